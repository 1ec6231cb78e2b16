"""``gnssacc config --show`` documents every key and round-trips; ``--template`` is a commented
starting file whose uncommented lines are exactly what the user sets."""

import tomllib

from gnssacc.cli import main
from gnssacc.core.config import DEFAULTS, load_config
from gnssacc.core.config_docs import key_comments


def test_every_key_is_documented_by_its_own_comment_or_its_group():
    docs = key_comments()
    for section, keys in DEFAULTS.items():
        names = list(keys)
        assert (section, names[0]) in docs, f"[{section}] {names[0]} has no documentation"
    assert any("[s]" in line for line in docs[("mounting", "imu_time_offset_s")])
    assert "deg/sqrt(h)" in " ".join(docs[("imu", "gyro_arw_deg_rth")])


def test_show_round_trips_and_says_what_set_each_value(capsys, tmp_path):
    user = tmp_path / "u.toml"
    user.write_text("[gnss]\nsigma_scale = 1.5\n")
    assert main(["config", "--show", "--preset", "kitti", "--config", str(user)]) == 0
    text = capsys.readouterr().out
    assert tomllib.loads(text) == load_config("kitti", user).values
    assert f"sigma_scale = 1.5   # set by {user}" in text
    assert "# set by preset kitti" in text
    assert "# Antenna position relative to the IMU, body frame FRD [m]." in text


def test_template_sets_nothing_until_a_line_is_uncommented(capsys, tmp_path):
    assert main(["config", "--template"]) == 0
    text = capsys.readouterr().out
    path = tmp_path / "t.toml"
    path.write_text(text)
    assert (
        load_config(None, path).explicit == frozenset()
        and load_config(None, path).values == DEFAULTS
    )
    path.write_text(
        text.replace("# default_sigma_m = [3.0, 3.0, 5.0]", "default_sigma_m = [1.0, 1.0, 2.0]")
    )
    cfg = load_config(None, path)
    assert cfg.explicit == {("gnss", "default_sigma_m")} and cfg["gnss"]["default_sigma_m"] == [
        1.0,
        1.0,
        2.0,
    ]
