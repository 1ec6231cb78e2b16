"""Simulated recordings as sources: ``sim:SCENARIO[,key=value...]``.

A source spec such as ``sim:ugv-slow,imu=consumer,gnss_hz=5,duration=300`` names a run of the
simulator (:func:`gnssacc.sources.sim.simulate`) instead of a file, wherever a source is accepted
(``gnssacc run``, ``gnssacc batch``, ``gnssacc bench``, :func:`gnssacc.process`). The task's seed
draws both the IMU errors and the GNSS noise, and the GNSS noise profile is the run's (or the
campaign's) ``--noise`` (default ``white``), so every seed of a campaign is an independent run.
The run has the receiver's Doppler velocities at the fix times (``velocity=True`` of
:func:`gnssacc.sources.sim.simulate`).

Keys (each at most once):

``imu``
    IMU grade (``consumer``, ``industrial``, ``tactical``, ... default ``industrial``).
``gnss_hz``, ``imu_hz``
    Fix and IMU rates [Hz] (default 1 and 100).
``duration``
    Run length [s] (default 300).
``lever_arm``
    Antenna position from the IMU, body FRD [m], three numbers separated by ``:``
    (default ``0:0:0``).
``odom_hz``
    Also simulate wheel odometry at this rate [Hz] (default: none;
    :mod:`gnssacc.sources.sim_odometry`: scale-factor error, noise, slip; skid steer for the UGV
    scenarios).

With ``--tune none`` such a run is estimated with the simulator's own filter-visible IMU
parameters (:attr:`gnssacc.core.recording.SimTruth.imu_params`) for every ``[imu]`` key the
configuration does not set explicitly (:func:`known_noise_config`): the IMU noise is then known,
not guessed from the defaults. With ``--tune auto`` the tuner identifies them as for any recording.
"""

from __future__ import annotations

from ..core.config import RunConfig
from ..core.config_check import Bound, number_problem
from ..core.errors import InputError

#: Limits of a simulated run (``sim:`` specs and ``gnssacc sim``).
SIM_DURATION_S = Bound(1.0, 86_400.0)


SIM_IMU_RATE_HZ = Bound(1.0, 4000.0)


SIM_MAX_GNSS_RATE_HZ = 100.0


#: Most IMU samples ``gnssacc sim`` makes (about 0.75 kB of memory each while simulating).
SIM_MAX_SAMPLES = 2_000_000

#: What starts a simulated source spec.
PREFIX = "sim:"
#: Defaults of the spec's keys (``simulate`` keyword, value).
DEFAULTS = {
    "imu": ("imu_grade", "industrial"),
    "gnss_hz": ("gnss_rate_hz", 1.0),
    "imu_hz": ("imu_rate_hz", 100.0),
    "duration": ("duration_s", 300.0),
    "lever_arm": ("lever_arm_b", (0.0, 0.0, 0.0)),
    "odom_hz": ("odom_hz", None),
}
_LEVER_ARM_M = Bound(-100.0, 100.0)


def is_sim_spec(source) -> bool:
    """Whether ``source`` is a ``sim:`` spec (a string starting with :data:`PREFIX`)."""
    return isinstance(source, str) and source.startswith(PREFIX)


def parse_sim_spec(spec: str) -> dict:
    """The :func:`gnssacc.sources.sim.simulate` keywords of a spec (without ``noise`` and ``seed``).

    Raises
    ------
    InputError
        Naming the spec: unknown scenario, grade or key, a key given twice, a value that is not a
        number or is out of range, or a run with fewer than two fixes or too many IMU samples.
    """
    from .sim_imu_errors import IMU_GRADES
    from .sim_scenarios import SCENARIOS

    scenario, *pairs = spec[len(PREFIX) :].split(",")
    if scenario not in SCENARIOS:
        raise InputError(spec, f"unknown scenario {scenario!r} (known: {', '.join(SCENARIOS)})")
    given: dict = {}
    for pair in pairs:
        key, eq, text = pair.partition("=")
        if key not in DEFAULTS or not eq:
            raise InputError(spec, f"{pair!r} is not key=value with a key of {', '.join(DEFAULTS)}")
        if key in given:
            raise InputError(spec, f"{key} given twice")
        given[key] = text
    out = {"scenario": scenario, **{kw: value for kw, value in DEFAULTS.values()}}
    for key, text in given.items():
        out[DEFAULTS[key][0]] = _value(spec, key, text, IMU_GRADES)
    _check_size(spec, out)
    return out


def _value(spec: str, key: str, text: str, grades):
    """One key's value, checked (see :func:`parse_sim_spec`)."""
    if key == "imu":
        if text not in grades:
            raise InputError(spec, f"unknown IMU grade {text!r} (known: {', '.join(grades)})")
        return text
    parts = text.split(":") if key == "lever_arm" else [text]
    if len(parts) != (3 if key == "lever_arm" else 1):
        raise InputError(
            spec,
            f"lever_arm={text}: expected three numbers X:Y:Z (body FRD) in metres, e.g. 0.5:0:-1",
        )
    bound = {
        "gnss_hz": Bound(0.0, SIM_MAX_GNSS_RATE_HZ, lo_open=True),
        "imu_hz": SIM_IMU_RATE_HZ,
        "duration": SIM_DURATION_S,
        "lever_arm": _LEVER_ARM_M,
        "odom_hz": Bound(0.0, SIM_IMU_RATE_HZ.hi, lo_open=True),
    }[key]
    values = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise InputError(spec, f"{key}={text}: {p!r} is not a number") from None
        problem = number_problem(v, False, bound)
        if problem:
            raise InputError(spec, f"{key}={text}: {problem} (expected a number {bound})")
        values.append(v)
    return tuple(values) if key == "lever_arm" else values[0]


def _check_size(spec: str, kw: dict) -> None:
    if kw["gnss_rate_hz"] > kw["imu_rate_hz"]:
        raise InputError(
            spec, f"gnss_hz={kw['gnss_rate_hz']:g} is above imu_hz={kw['imu_rate_hz']:g}"
        )
    if kw["odom_hz"] is not None and kw["odom_hz"] > kw["imu_rate_hz"]:
        raise InputError(spec, f"odom_hz={kw['odom_hz']:g} is above imu_hz={kw['imu_rate_hz']:g}")
    if kw["duration_s"] * kw["gnss_rate_hz"] < 1.0:
        raise InputError(
            spec,
            f"duration={kw['duration_s']:g} s at gnss_hz={kw['gnss_rate_hz']:g} gives fewer than "
            f"two GNSS fixes",
        )
    if kw["duration_s"] * kw["imu_rate_hz"] > SIM_MAX_SAMPLES:
        raise InputError(
            spec,
            f"duration={kw['duration_s']:g} s at imu_hz={kw['imu_rate_hz']:g} makes more than "
            f"{SIM_MAX_SAMPLES} IMU samples",
        )


def load_sim(spec: str, noise: str | None, seed: int):
    """The run a spec names, for a seed and a GNSS noise profile (``None``: ``white``).

    Returns
    -------
    RecordedRun
        Named ``sim-<scenario>``, with ``meta["source_spec"] = spec``; its truth at the IMU rate
        (:func:`gnssacc.sources.sim.dense_truth_rate`).
    """
    from dataclasses import replace

    from .sim import dense_truth_rate, simulate

    args = parse_sim_spec(spec)
    rate = dense_truth_rate(args.get("imu_rate_hz", DEFAULTS["imu_hz"][1]))
    run = simulate(**args, noise=noise or "white", seed=seed, velocity=True, truth_rate_hz=rate)
    return replace(run, meta={**run.meta, "source_spec": spec})


def folder_name(spec: str) -> str:
    """A folder name for a spec: ``sim:ugv-slow,imu=consumer`` -> ``sim-ugv-slow-imu_consumer``."""
    return (
        spec.replace(":", "-", 1)
        .replace(",", "-")
        .replace("=", "_")
        .replace(":", "_")
        .replace("/", "_")
    )


def known_noise_config(cfg: RunConfig, run, tune: str | None) -> RunConfig:
    """``cfg`` with the simulator's filter-visible IMU parameters under the keys the user did not
    set, when ``run`` came from a ``sim:`` spec (:func:`load_sim`) and the noise is not tuned
    (``tune`` or ``[tune] mode`` is ``none``); otherwise ``cfg`` itself.

    The user's own keys stay as they are (and explicit); the simulator's are recorded as set by
    ``simulator`` in the configuration's sources.
    """
    if run.sim is None or "source_spec" not in run.meta or (tune or cfg["tune"]["mode"]) != "none":
        return cfg
    imu = {k: v for k, v in run.sim.imu_params.items() if ("imu", k) not in cfg.explicit}
    return cfg.with_values({"imu": imu}, "simulator") if imu else cfg
