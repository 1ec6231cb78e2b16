"""Wrong but plausible input, end to end: does ``gnssacc run`` catch it, and what do the checks cost?

For each simulated scenario (``car`` 120 s, ``ugv-slow`` 240 s: parked 36 s, slow, reversing)
and IMU grade (consumer, industrial, tactical; ``--all-grades`` adds the ``-basic`` grades), a
clean run is written as a CSV run directory, then copies of it with one corruption each (the
cases of issue 9: IMU on UTC beside GNSS on GPS time, clock offsets of 0.1 s and 1 s, lat/lon
swapped, lat/lon in radians with a correct init.json, gyro in deg/s, accelerometer in g, IMU
stamps in ms with a correct init.json, IMU upside down, IMU turned 90 deg in yaw). Each is run
twice in-process through ``gnssacc.cli.main`` (``--methods ekf --tune none``):

* with the default configuration: the case must end with exit 2 and one ``gnssacc: error:`` line
  holding the case's key words; the clean run must end with exit 0 (no false alarm);
* with the repair configuration (``[checks] repair = "auto"``, ``imu_time_offset_s = "auto"``,
  ``imu_to_body_rpy_deg = "auto"``): the case must end with exit 0 and PRMSE within 10 % of the
  clean run's (judged against the unmodified truth); time offsets must be recovered within
  20 ms; on the clean run nothing may be repaired or applied (no offset beyond 20 ms, no mounting).

Then the clean KITTI sequence and the shared real recordings (``../shared/data``) through the
checks alone (no false alarm), and the time the checks add to a 10-minute run (median of 3).

    python bench/bench_input_checks.py [--seeds 0] [--all-grades] [--quick]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import statistics
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from gnssacc import cli
from gnssacc.core.config import load_config
from gnssacc.core.recording import GnssFixes, ImuData
from gnssacc.pipeline import check_input
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate

SCENARIOS = {"car": 120.0, "ugv-slow": 240.0}
GRADES = ("consumer", "industrial", "tactical")
BASIC = ("consumer-basic", "industrial-basic", "tactical-basic")
AUTO = '[checks]\nrepair = "auto"\n[mounting]\nimu_time_offset_s = "auto"\nimu_to_body_rpy_deg = "auto"\n'
OFFSET_TOL_S = 0.02
PRMSE_TOL = 0.10


def _imu(run, t=None, f=None, w=None):
    i = run.imu
    return replace(
        run,
        imu=ImuData(
            i.t if t is None else t, i.f_b if f is None else f, i.omega_ib_b if w is None else w
        ),
    )


def _gnss(run, lat, lon):
    g = run.gnss
    return replace(run, gnss=GnssFixes(g.t, lat, lon, g.h, g.sigma_ned))


def _rotated(run, R):
    return _imu(run, f=run.imu.f_b @ R.T, w=run.imu.omega_ib_b @ R.T)


@dataclass(frozen=True)
class Case:
    """One corruption: what it does to the run, the words its error must hold, and, when the
    checks can measure it, the offset [s] the repair configuration must apply."""

    name: str
    corrupt: object
    words: tuple
    offset_s: float | None = None
    needs_init: bool = False
    default_must_fail: bool = True
    repairable: bool = True


CASES = (
    Case(
        "gps-vs-utc-18s",
        lambda r: _imu(r, t=r.imu.t - 18.0),
        ("imu.csv", "imu_time_offset_s"),
        18.0,
    ),
    Case("offset-1s", lambda r: _imu(r, t=r.imu.t + 1.0), ("imu.csv", "imu_time_offset_s"), -1.0),
    Case("offset-0.1s", lambda r: _imu(r, t=r.imu.t - 0.1), (), 0.1, default_must_fail=False),
    # Swapped and sign-lost coordinates look alike (a mirror image): never repaired, always an error.
    Case(
        "latlon-swapped",
        lambda r: _gnss(r, r.gnss.lon, r.gnss.lat),
        ("gnss.csv", "swapped"),
        repairable=False,
    ),
    Case(
        "latlon-radians",
        lambda r: _gnss(r, np.radians(r.gnss.lat), np.radians(r.gnss.lon)),
        ("gnss.csv", "radians"),
        needs_init=True,
    ),
    Case("gyro-deg-s", lambda r: _imu(r, w=np.degrees(r.imu.omega_ib_b)), ("imu.csv", "deg/s")),
    Case("accel-g", lambda r: _imu(r, f=r.imu.f_b / 9.80665), ("imu.csv", "in g")),
    Case(
        "imu-ms",
        lambda r: _imu(r, t=r.imu.t * 1000.0),
        ("imu.csv", "milliseconds"),
        needs_init=True,
    ),
    Case(
        "upside-down",
        lambda r: _rotated(r, np.diag([1.0, -1.0, -1.0])),
        ("imu.csv", "imu_to_body_rpy_deg"),
    ),
    Case(
        "yawed-90",
        lambda r: _rotated(r, np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])),
        ("imu.csv", "imu_to_body_rpy_deg"),
    ),
)


def _cli(args: list) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli.main([str(a) for a in args])
    return code, err.getvalue()


def _run(folder: Path, out: Path, config: Path | None) -> tuple[int, str, dict | None]:
    args = [
        "run",
        folder,
        "--out",
        out,
        "--methods",
        "ekf",
        "--tune",
        "none",
        "--no-plots",
        "--overwrite",
    ]
    code, err = _cli(args + (["--config", config] if config else []))
    metrics = json.loads((out / "metrics.json").read_text()) if code == 0 else None
    return code, err, metrics


def _applied(err: str) -> tuple[float | None, float | None, bool]:
    """The offset the checks applied and its 1-sigma [s] (from the warning), and whether a mounting
    was applied."""
    m = re.search(
        r'imu_time_offset_s = "auto": measured ([-+0-9.]+) s \+- ([0-9.]+) s \([^)]*\)[,;] added',
        err,
    )
    off, sig = (float(m.group(1)), float(m.group(2))) if m else (None, None)
    return off, sig, "applied imu_to_body_rpy_deg" in err


def _judge_default(case: Case | None, code: int, err: str) -> str:
    errors = [ln for ln in err.splitlines() if ln.startswith("gnssacc: error:")]
    if "Traceback" in err:
        return "TRACEBACK"
    if case is None:
        return "ok" if code == 0 else f"FALSE ALARM: {errors[:1]}"
    if code == 2 and len(errors) == 1 and all(w in errors[0] for w in case.words):
        return "caught"
    if code == 0 and not case.default_must_fail:
        return "passed (harmless)"
    return f"MISSED exit {code}: {errors[:1]}"


def _offset_ok(off: float | None, sig: float | None, truth: float) -> bool:
    """Within 20 ms, or within 3 sigma where the fixes cannot tell better (3 m fixes at 1 Hz)."""
    return off is not None and abs(off - truth) <= max(OFFSET_TOL_S, 3.0 * sig)


def _judge_auto(case: Case | None, code: int, err: str, metrics, clean_prmse: float) -> str:
    if case is not None and not case.repairable:
        return _judge_default(case, code, err).replace("caught", "caught (not repairable)")
    if code != 0:
        return f"FAILED exit {code}: {[ln for ln in err.splitlines() if 'error' in ln][:1]}"
    off, sig, mounted = _applied(err)
    ratio = metrics["methods"]["ekf"]["prmse_m"] / clean_prmse
    text = f"PRMSE x{ratio:.3f}" + (
        f", offset {off:+.3f} s +- {sig:.3f}" if off is not None else ""
    )
    if case is None:
        bad = mounted or (off is not None and not _offset_ok(off, sig, 0.0)) or "repair" in err
        return ("FALSE ALARM " if bad else "ok ") + text
    wrong = case.offset_s is not None and not _offset_ok(off, sig, case.offset_s)
    return ("WRONG " if wrong or abs(ratio - 1) > PRMSE_TOL else "repaired ") + text


def sweep(scenario: str, grade: str, seed: int, tmp: Path, auto: Path, tally: dict) -> None:
    """Every case on one simulated run, default and repair configurations."""
    base = simulate(scenario, SCENARIOS[scenario], imu_grade=grade, noise="white", seed=seed)
    with_init = simulate(
        scenario, SCENARIOS[scenario], imu_grade=grade, noise="white", seed=seed, give_init=True
    )
    tag = f"{scenario}/{grade}/{seed}"
    code, err, metrics = _run(write_csv_run(base, tmp / "clean"), tmp / "out", None)
    clean = metrics["methods"]["ekf"]["prmse_m"] if metrics else float("nan")
    _report(tally, tag, "clean", _judge_default(None, code, err), f"PRMSE {clean:.2f} m")
    code, err, metrics = _run(tmp / "clean", tmp / "out", auto)
    _report(tally, tag, "clean+auto", _judge_auto(None, code, err, metrics, clean), "")
    _, _, m_init = _run(write_csv_run(with_init, tmp / "clean-init"), tmp / "out", None)
    clean_init = (
        m_init["methods"]["ekf"]["prmse_m"] if m_init else float("nan")
    )  # the same run started from init.json
    for case in CASES:
        folder = write_csv_run(
            case.corrupt(with_init if case.needs_init else base), tmp / case.name
        )
        code, err, _ = _run(folder, tmp / "out", None)
        _report(tally, tag, case.name, _judge_default(case, code, err), "")
        code, err, metrics = _run(folder, tmp / "out", auto)
        ref = clean_init if case.needs_init else clean
        _report(tally, tag, case.name + "+auto", _judge_auto(case, code, err, metrics, ref), "")


def _report(tally: dict, tag: str, case: str, verdict: str, extra: str) -> None:
    word = verdict.split()[0]
    tally.setdefault(case, {}).setdefault(word, 0)
    tally[case][word] += 1
    print(f"{tag:28s} {case:22s} {verdict} {extra}".rstrip(), flush=True)


def real_recordings(cfg) -> None:
    """KITTI and the shared recordings through the checks alone: findings or errors are false alarms."""
    from gnssacc.pipeline import load_source

    runs = [("kitti", load_source("kitti", load_config("kitti"), noise="white", seed=0))]
    data = Path(__file__).resolve().parents[2] / "shared" / "data"
    if data.is_dir():
        sys.path.insert(0, str(Path(__file__).parent))
        import bench_real_recordings as real

        runs += [("comma2k19", real.comma(data / "comma2k19_example1"))]
        runs += [
            (f"vn310-{log}", real.vn310(data / "vn310_static", log)) for log in ("lckf", "tckf")
        ]
    for name, run in runs:
        try:
            _, _, findings = check_input(run, cfg)
            seen = [
                f for f in findings if f.action != "refuted"
            ]  # refuted proposals are only recorded
            print(
                f"{name:12s} {'ok' if not seen else 'FALSE ALARM ' + str([(f.check, f.action) for f in seen])}"
            )
        except Exception as exc:  # noqa: BLE001 - a bench reports every outcome
            print(f"{name:12s} FALSE ALARM {exc}")


def rtk(run, sigma_m: float = 0.03, seed: int = 0):
    """The run with RTK-grade fixes: truth at the fix epochs plus ``sigma_m`` white noise."""
    g, rng = run.gnss, np.random.default_rng(seed)
    n = rng.normal(0.0, sigma_m, (len(g.t), 3))
    r_e = 6378137.0
    lat, lon = g.lat + n[:, 0] / r_e, g.lon + n[:, 1] / (r_e * np.cos(g.lat))
    return replace(
        run, gnss=GnssFixes(g.t, lat, lon, g.h - n[:, 2], np.full((len(g.t), 3), sigma_m))
    )


def offsets_rtk(grades) -> None:
    """Clock offsets of 0.1, 1 and 18 s with 3 cm fixes (noise-free simulation + RTK noise): the
    measured offset must be within 20 ms."""
    cfg = load_config(overrides={"mounting": {"imu_time_offset_s": "auto"}})
    worst = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for scenario, duration in SCENARIOS.items():
            for grade in grades:
                base = rtk(simulate(scenario, duration, imu_grade=grade, noise="none", seed=1))
                for offset in (0.1, 1.0, 18.0):
                    run, cfg_out, _ = check_input(_imu(base, t=base.imu.t - offset), cfg)
                    got = float(cfg_out["mounting"]["imu_time_offset_s"])
                    worst = max(worst, abs(got - offset))
                    print(
                        f"rtk {scenario:9s} {grade:11s} offset {offset:5.1f} s: measured {got:+.4f} s, "
                        f"error {1000 * (got - offset):+.1f} ms",
                        flush=True,
                    )
    print(
        f"worst offset error with 3 cm fixes: {1000 * worst:.1f} ms ({'within' if worst <= OFFSET_TOL_S else 'OVER'} "
        f"{1000 * OFFSET_TOL_S:.0f} ms)"
    )


def _median_time(fn, rounds: int) -> tuple[float, float, float]:
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times), max(times)


def check_time(duration_s: float = 600.0, rounds: int = 3) -> None:
    """Time of the checks on a clean run (median of ``rounds``), with the default configuration
    and with the measured offset and mounting applied ("auto": EKF passes for the offset), against
    a whole default run."""
    run = simulate("car-city", duration_s, imu_grade="consumer", noise="white", seed=0)
    plain = load_config()
    auto = load_config(
        overrides={
            "mounting": {"imu_time_offset_s": "auto", "imu_to_body_rpy_deg": "auto"},
            "checks": {"repair": "auto"},
        }
    )
    warnings.simplefilter("ignore")  # the "auto" offset's warning, printed once per round otherwise
    check_input(run, auto)  # compile
    figures = {
        name: _median_time(lambda c=cfg: check_input(run, c), rounds)
        for name, cfg in (("default", plain), ("auto", auto))
    }
    with tempfile.TemporaryDirectory() as tmp:
        folder = write_csv_run(run, Path(tmp) / "ten")
        t0 = time.perf_counter()
        code, _ = _cli(["run", folder, "--out", Path(tmp) / "o", "--no-plots"])
        whole = time.perf_counter() - t0
    print(
        f"a whole default gnssacc run of a {duration_s:.0f} s car-city run (consumer IMU; all methods, tuning): "
        f"{whole:.1f} s (exit {code}); the checks, median of {rounds}:"
    )
    for name, (med, lo, hi) in figures.items():
        print(
            f"  {name:8s} config: {med:.2f} s (min {lo:.2f}, max {hi:.2f}) = {100 * med / whole:.1f} % of the run"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="0", help="comma-separated noise seeds (default 0)")
    ap.add_argument("--all-grades", action="store_true", help="also the -basic IMU grades")
    ap.add_argument("--quick", action="store_true", help="industrial grade only, no timing")
    a = ap.parse_args()
    grades = ("industrial",) if a.quick else GRADES + (BASIC if a.all_grades else ())
    tally: dict = {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        auto = Path(tmp) / "auto.toml"
        auto.write_text(AUTO)
        for seed in (int(s) for s in a.seeds.split(",")):
            for scenario in SCENARIOS:
                for grade in grades:
                    sweep(scenario, grade, seed, Path(tmp), auto, tally)
    print(
        f"\n{sum(sum(v.values()) for v in tally.values())} runs in {time.perf_counter() - t0:.0f} s; outcomes:"
    )
    for case, words in tally.items():
        print(f"  {case:22s} " + ", ".join(f"{w} {n}" for w, n in sorted(words.items())))
    print()
    real_recordings(load_config())
    offsets_rtk(grades)
    if not a.quick:
        check_time()


if __name__ == "__main__":
    main()
