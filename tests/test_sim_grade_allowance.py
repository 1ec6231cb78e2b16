"""A ``sim:`` run's grade sets what the tuner cannot identify (the gyro turn-error allowance)."""

import tomllib
from dataclasses import replace
from importlib import resources

import pytest

from gnssacc.core.config import DEFAULTS, load_config
from gnssacc.sources.simspec import grade_allowance, known_noise_config, load_sim

KEY = "gyro_turn_error_ppm"


def _preset_value(name: str) -> float:
    """The value written in the packaged preset file (read as text, not through the code)."""
    text = (resources.files("gnssacc") / "presets" / f"{name}.toml").read_text()
    return float(tomllib.loads(text)["imu"][KEY])


@pytest.fixture(scope="module")
def runs():
    return {g: load_sim(f"sim:car,imu={g},duration=5", None, 0) for g in ("consumer", "tactical")}


@pytest.mark.parametrize("tune", [None, "auto", "none"])
@pytest.mark.parametrize("grade", ["consumer", "tactical"])
def test_the_grade_sets_the_allowance_in_every_tuning_mode(runs, grade, tune):
    cfg = known_noise_config(load_config(), runs[grade], tune)
    assert cfg["imu"][KEY] == _preset_value(grade) != DEFAULTS["imu"][KEY]
    assert ("imu", KEY) not in cfg.explicit  # not the user's
    assert any(f"grade {grade}" in s for s in cfg.sources)


def test_the_users_value_and_preset_win(runs):
    mine = load_config(overrides={"imu": {KEY: 123.0}})
    assert known_noise_config(mine, runs["consumer"], None)["imu"][KEY] == 123.0
    chosen = load_config(preset="tactical")
    assert known_noise_config(chosen, runs["consumer"], "none")["imu"][KEY] == _preset_value(
        "tactical"
    )


def test_a_grade_without_a_preset_or_a_run_not_from_a_spec_keeps_the_default():
    basic = load_sim("sim:car,imu=consumer-basic,duration=5", None, 0)
    assert grade_allowance(load_config(), basic)["imu"][KEY] == DEFAULTS["imu"][KEY]
    made = load_sim("sim:car,imu=consumer,duration=5", None, 0)
    plain = replace(made, meta={k: v for k, v in made.meta.items() if k != "source_spec"})
    assert grade_allowance(load_config(), plain)["imu"][KEY] == DEFAULTS["imu"][KEY]
