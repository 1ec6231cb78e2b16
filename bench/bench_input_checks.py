"""Wrong but plausible input, end to end: does ``gnssacc run`` catch it, and what do the checks cost?

For each simulated scenario (``car`` 120 s, ``ugv-slow`` 240 s: parked 36 s, slow, reversing)
and IMU grade (consumer, industrial, tactical; ``--all-grades`` adds the ``-basic`` grades), a
clean run stamped in UNIX seconds (2024, as loggers and bags stamp them) is written as a CSV run
directory, then copies of it with one corruption each (the cases of issue 9: a logger clock on
UTC beside fixes on GPS time, clock offsets of 0.1 s and 1 s (the logger's clock stamps the
IMU, the truth and the odometry alike: docs/formats.md), lat/lon swapped, lat/lon in radians
with a correct init.json, gyro in deg/s, accelerometer in g, IMU stamps in ms with a correct
init.json, IMU upside down, IMU turned 90 deg in yaw). Each is run in-process through
``gnssacc.cli.main`` (``--methods ekf --tune none``) with three configurations:

* ``default``: a correction the estimator proves is applied and stated (issue 32). The case is
  ``repaired`` when the run ends with exit 0, the correction in ``metrics.json``'s
  ``input_corrections``, the EKF's PRMSE within 10 % of the clean run's (both against the
  simulated truth, on the GNSS clock: a truth on the IMU's clock would carry the applied
  offset's error) and a clock offset within 20 ms or 3 of its sigmas; ``caught`` when it ends
  with exit 2 and one ``gnssacc: error:`` line holding the case's key words (what the data
  cannot tell from another: swapped or sign-lost coordinates); ``unprovable`` when nothing is
  applied and the run says that an offset of that size could go unseen; else ``MISSED`` or
  ``WRONG``;
* ``strict`` (``--strict``): today's refusal: ``caught`` or ``MISSED``;
* ``auto`` (``imu_time_offset_s`` and ``imu_to_body_rpy_deg = "auto"``): as ``default``, where
  every measured offset is proposed.

On the clean run nothing may be applied, refused or warned of in any configuration (else a
``FALSE`` alarm). Then the clean KITTI sequence and the shared real recordings
(``../shared/data``) through the checks alone (no false alarm), clock offsets with RTK-grade
fixes, and the time the checks add to a 10-minute run (median of 3).

GNSS velocities (issue 31): the same scenarios simulated with Doppler velocities, written with
one error each (ENU as NED, the vertical as up, time tags 1 s late and 1 s early: each velocity
beside the next or the previous fix, as a CSV run holds one per fix; the estimator
must prove and apply the correction, PRMSE within 10 % of the clean run's and a time tag within
50 ms; an east velocity biased by 0.5 m/s and a north velocity zeroed: a warning naming that
axis alone, the run not refused), each in the default configuration and with ``--strict``
(``caught``: exit 2 and one error line). ``--velocity-only`` runs those alone.

    python bench/bench_input_checks.py [--seeds 0] [--all-grades] [--quick] [--velocity-only]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
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
#: 2024-03-01 12:00 UTC: the first IMU sample of every run [UNIX s].
T0_UNIX = 1709294400.0
CONFIGS = {
    "default": None,
    "strict": '[checks]\non_proof = "refuse"\n',
    "auto": '[mounting]\nimu_time_offset_s = "auto"\nimu_to_body_rpy_deg = "auto"\n',
}
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


def _late(run, offset_s: float):
    """A logger clock that needs ``offset_s`` added to reach the GNSS clock: its IMU, truth and
    odometry stamps alike."""
    out = _imu(run, t=run.imu.t - offset_s)
    out = replace(out, truth=replace(run.truth, t=run.truth.t - offset_s))
    return out if run.odometry is None else replace(out, odometry=run.odometry.shifted(-offset_s))


def _gnss(run, lat, lon):
    g = run.gnss
    return replace(run, gnss=GnssFixes(g.t, lat, lon, g.h, g.sigma_ned))


def _rotated(run, R):
    return _imu(run, f=run.imu.f_b @ R.T, w=run.imu.omega_ib_b @ R.T)


@dataclass(frozen=True)
class Case:
    """One corruption: what it does to the run, the check that must answer it, the words a
    refusal must hold and, for a clock offset, the offset [s] a correction must apply."""

    name: str
    corrupt: object
    check: str
    words: tuple
    offset_s: float | None = None
    needs_init: bool = False
    ambiguous: bool = False


CASES = (
    Case("gps-vs-utc-18s", lambda r: _late(r, 18.0), "time_offset", ("imu_time_offset_s",), 18.0),
    Case("offset-1s", lambda r: _late(r, -1.0), "time_offset", ("imu_time_offset_s",), -1.0),
    Case("offset-0.1s", lambda r: _late(r, 0.1), "time_offset", ("imu_time_offset_s",), 0.1),
    # Swapped and sign-lost coordinates look alike (a mirror image): refused, naming both.
    Case(
        "latlon-swapped",
        lambda r: _gnss(r, r.gnss.lon, r.gnss.lat),
        "latlon",
        ("gnss.csv", "swapped", "lost sign"),
        ambiguous=True,
    ),
    Case(
        "latlon-radians",
        lambda r: _gnss(r, np.radians(r.gnss.lat), np.radians(r.gnss.lon)),
        "latlon",
        ("gnss.csv", "radians"),
        needs_init=True,
    ),
    Case(
        "gyro-deg-s",
        lambda r: _imu(r, w=np.degrees(r.imu.omega_ib_b)),
        "gyro_units",
        ("imu.csv", "deg/s"),
    ),
    Case("accel-g", lambda r: _imu(r, f=r.imu.f_b / 9.80665), "accel_units", ("imu.csv", "in g")),
    Case(
        "imu-ms",
        lambda r: _imu(r, t=r.imu.t * 1000.0),
        "time_units",
        ("imu.csv", "milliseconds"),
        needs_init=True,
    ),
    Case(
        "upside-down",
        lambda r: _rotated(r, np.diag([1.0, -1.0, -1.0])),
        "mounting",
        ("imu.csv", "imu_to_body_rpy_deg"),
    ),
    Case(
        "yawed-90",
        lambda r: _rotated(r, np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])),
        "mounting",
        ("imu.csv", "imu_to_body_rpy_deg"),
    ),
)


def _vel_reading(M):
    from gnssacc.checks.velcheck import transformed

    return lambda r: replace(r, gnss_vel=transformed(r.gnss_vel, np.asarray(M, float)))


def _vel_tags(d):
    return lambda r: replace(r, gnss_vel=replace(r.gnss_vel, t=r.gnss_vel.t + d))


def _vel_axis(i, how):
    def corrupt(r):
        v = r.gnss_vel.v_ned.copy()
        v[:, i] = how(v[:, i])
        return replace(r, gnss_vel=replace(r.gnss_vel, v_ned=v))

    return corrupt


@dataclass(frozen=True)
class VelCase:
    """A velocity corruption: the check that must correct it (and the time-tag error it must
    find [s]), or the axis a warning must name."""

    name: str
    corrupt: object
    check: str | None = None
    lag_s: float | None = None
    axis: str | None = None


VEL_CASES = (
    VelCase("vel-enu-as-ned", _vel_reading([[0, 1, 0], [1, 0, 0], [0, 0, -1]]), "velocity_frame"),
    VelCase("vel-vertical-up", _vel_reading(np.diag([1, 1, -1])), "velocity_frame"),
    VelCase("vel-tags-1s-late", _vel_tags(1.0), "velocity_time", lag_s=1.0),
    # A CSV run holds one velocity per fix row: a time-tag error is whole epochs there (the
    # velocity written beside the next or the previous fix)
    VelCase("vel-tags-1s-early", _vel_tags(-1.0), "velocity_time", lag_s=-1.0),
    VelCase("vel-east-bias-0.5", _vel_axis(1, lambda v: v + 0.5), axis="east"),
    VelCase("vel-north-zeroed", _vel_axis(0, lambda v: 0.0 * v), axis="north"),
)
VEL_LAG_TOL_S = 0.05


def _vel_judge(case: VelCase, code, err, metrics, ratio) -> str:
    """The outcome of one velocity run (module notes)."""
    if "Traceback" in err:
        return "TRACEBACK"
    errors = [ln for ln in err.splitlines() if ln.startswith("gnssacc: error:")]
    if code == 2:
        return "caught" if len(errors) == 1 and "veloc" in errors[0] else f"WRONG {errors[:1]}"
    if code != 0:
        return f"FAILED exit {code}"
    applied = _applied(metrics, err)
    said = [ln for ln in err.splitlines() if "contradict the fixes on" in ln]
    if case.axis is not None:
        named = [a for a in ("north", "east", "down") if f"{a}: the fixes depart" in " ".join(said)]
        if applied:
            return f"WRONG applied {sorted(applied)}"
        return "warned" if named == [case.axis] else f"MISSED (named {named})"
    if case.check not in applied:
        return f"MISSED, PRMSE x{ratio:.3f}"
    text = f"PRMSE x{ratio:.3f}"
    off = False
    if case.lag_s is not None:
        lag = applied[case.check].get("lag_s", np.nan)
        off = not abs(lag - case.lag_s) <= VEL_LAG_TOL_S
        text += f", tags {lag:+.3f} s late"
    return ("WRONG " if off or abs(ratio - 1) > PRMSE_TOL else "repaired ") + text


def vel_sweep(scenario: str, grade: str, seed: int, tmp: Path, configs: dict, tally: dict) -> None:
    """Every velocity case on one simulated run with velocities, default and ``--strict``."""
    kw = dict(imu_grade=grade, noise="white", seed=seed, t_start_s=T0_UNIX, velocity=True)
    run = simulate(scenario, SCENARIOS[scenario], **kw)
    tag = f"{scenario}/{grade}/{seed}"
    ref = {}
    folder = write_csv_run(run, tmp / "vel-clean")
    for cname in ("default", "strict"):
        code, err, metrics = _run(folder, tmp / "out", configs[cname])
        ref[cname] = prmse_against(run.truth, tmp / "out") if code == 0 else np.nan
        verdict = _judge(None, code, err, metrics, 1.0)
        _report(tally, tag, f"vel-clean/{cname}", verdict, f"PRMSE {ref[cname]:.2f}")
    for case in VEL_CASES:
        folder = write_csv_run(case.corrupt(run), tmp / case.name)
        for cname in ("default", "strict"):
            code, err, metrics = _run(folder, tmp / "out", configs[cname])
            ratio = prmse_against(run.truth, tmp / "out") / ref[cname] if code == 0 else np.nan
            verdict = _vel_judge(case, code, err, metrics, ratio)
            if cname == "strict" and case.axis is None and verdict.startswith("MISSED"):
                verdict = "MISSED"
            _report(tally, tag, f"{case.name}/{cname}", verdict, "")


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


def prmse_against(truth, out: Path) -> float:
    """The EKF's PRMSE [m] against the simulated truth (the GNSS clock), from trajectory_ekf.csv."""
    from gnssacc.core.earth import LocalTangentFrame

    tab = np.genfromtxt(out / "trajectory_ekf.csv", delimiter=",", names=True)
    frame = LocalTangentFrame(truth.lat[0], truth.lon[0], truth.h[0])
    p = frame.to_ned(np.radians(tab["lat_deg"]), np.radians(tab["lon_deg"]), tab["h_m"])
    q = frame.to_ned(truth.lat, truth.lon, truth.h)
    inside = (tab["t"] >= truth.t[0]) & (tab["t"] <= truth.t[-1])
    ref = np.column_stack([np.interp(tab["t"][inside], truth.t, q[:, i]) for i in range(3)])
    return float(np.sqrt(np.mean(np.sum((p[inside] - ref) ** 2, axis=1))))


def _applied(metrics: dict, err: str) -> dict:
    """``{check: details}`` of the corrections a run applied (``metrics.json``; IMU stamps
    rescaled when the run was loaded: said in a warning)."""
    applied = {
        c["check"]: c.get("details", {})
        for c in metrics.get("input_checks", [])
        if c.get("action") in ("applied", "repaired")
    }
    if "divided the IMU time stamps by" in err:
        applied["time_units"] = {}
    return applied


def _unseen_s(metrics: dict) -> float | None:
    clock = (metrics.get("input_corrections") or {}).get("clock") or {}
    return clock.get("unseen_s")


def _offset_ok(d: dict, truth: float) -> bool:
    """Within 20 ms, or within 3 sigma where the fixes cannot tell better (3 m fixes at 1 Hz)."""
    total = d.get("configured_s", 0.0) + d.get("offset_s", 0.0)
    return abs(total - truth) <= max(OFFSET_TOL_S, 3.0 * (d.get("sigma_s") or 0.0))


def _judge(case, code, err, metrics, ratio) -> str:
    """The outcome of one run (module notes)."""
    errors = [ln for ln in err.splitlines() if ln.startswith("gnssacc: error:")]
    if "Traceback" in err:
        return "TRACEBACK"
    if code == 2:
        ok = case is not None and len(errors) == 1 and all(w in errors[0] for w in case.words)
        return "caught" if ok else f"WRONG error: {errors[:1]}"
    if code != 0:
        return f"FAILED exit {code}: {errors[:1]}"
    applied = _applied(metrics, err)
    # What the input checks warn of (a method's own consistency warnings are not theirs).
    warned = [
        ln
        for ln in err.splitlines()
        if ln.startswith("gnssacc: warning:") and not ln.startswith("gnssacc: warning: ekf")
    ]
    if case is None:
        return f"FALSE: applied {sorted(applied)}, {warned[:1]}" if applied or warned else "ok"
    if case.check not in applied:
        unseen = _unseen_s(metrics)
        if case.offset_s is not None and unseen is not None and abs(case.offset_s) <= unseen:
            return f"unprovable (said: below {unseen:.2f} s unseen), PRMSE x{ratio:.3f}"
        return f"MISSED, PRMSE x{ratio:.3f}"
    off = case.offset_s is not None and not _offset_ok(applied[case.check], case.offset_s)
    text = f"PRMSE x{ratio:.3f}"
    if case.offset_s is not None:
        d = applied[case.check]
        total = d.get("configured_s", 0.0) + d.get("offset_s", 0.0)
        text += f", offset {total:+.3f} s +- {d.get('sigma_s') or 0.0:.3f}"
    return ("WRONG " if off or abs(ratio - 1) > PRMSE_TOL else "repaired ") + text


def sweep(scenario: str, grade: str, seed: int, tmp: Path, configs: dict, tally: dict) -> None:
    """Every case on one simulated run, in every configuration."""
    kw = dict(imu_grade=grade, noise="white", seed=seed, t_start_s=T0_UNIX)
    base = simulate(scenario, SCENARIOS[scenario], **kw)
    with_init = simulate(scenario, SCENARIOS[scenario], give_init=True, **kw)
    tag = f"{scenario}/{grade}/{seed}"
    clean = {}
    for run, name in ((base, "clean"), (with_init, "clean-init")):
        folder = write_csv_run(run, tmp / name)
        for cname, config in configs.items():
            code, err, metrics = _run(folder, tmp / "out", config)
            clean[(name, cname)] = prmse_against(run.truth, tmp / "out") if code == 0 else np.nan
            if name == "clean":
                verdict = _judge(None, code, err, metrics, 1.0)
                _report(tally, tag, f"clean/{cname}", verdict, f"PRMSE {clean[(name, cname)]:.2f}")
    for case in CASES:
        run = with_init if case.needs_init else base
        folder = write_csv_run(case.corrupt(run), tmp / case.name)
        for cname, config in configs.items():
            code, err, metrics = _run(folder, tmp / "out", config)
            ref = clean[("clean-init" if case.needs_init else "clean", cname)]
            ratio = prmse_against(run.truth, tmp / "out") / ref if code == 0 else np.nan
            verdict = _judge(case, code, err, metrics, ratio)
            if cname == "strict" and verdict.startswith(("MISSED", "unprovable")):
                verdict = "MISSED " + verdict.split(" ", 1)[-1]
            _report(tally, tag, f"{case.name}/{cname}", verdict, "")


def _report(tally: dict, tag: str, case: str, verdict: str, extra: str) -> None:
    word = verdict.split()[0].rstrip(":,")
    tally.setdefault(case, {}).setdefault(word, 0)
    tally[case][word] += 1
    print(f"{tag:28s} {case:28s} {verdict} {extra}".rstrip(), flush=True)


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


def velocity_check_time(duration_s: float = 600.0, rounds: int = 3) -> None:
    """What the velocity checks add to the input checks on a clean run with velocities (median of
    ``rounds``): the same run with and without its velocities; and on KITTI (none)."""
    from gnssacc.pipeline import load_source

    run = simulate(
        "car-city", duration_s, imu_grade="consumer", noise="white", seed=0, velocity=True
    )
    cfg = load_config()
    warnings.simplefilter("ignore")
    check_input(run, cfg)  # compile
    with_vel = _median_time(lambda: check_input(run, cfg), rounds)
    without = _median_time(lambda: check_input(replace(run, gnss_vel=None), cfg), rounds)
    print(
        f"input checks of a {duration_s:.0f} s car-city run (consumer IMU), median of {rounds}: "
        f"with velocities {with_vel[0]:.2f} s (min {with_vel[1]:.2f}, max {with_vel[2]:.2f}), "
        f"without {without[0]:.2f} s (min {without[1]:.2f}, max {without[2]:.2f})"
    )
    kitti = load_source("kitti", load_config("kitti"), noise="white", seed=0)
    kcfg = load_config("kitti")
    med = _median_time(lambda: check_input(kitti, kcfg), rounds)
    print(
        f"input checks of KITTI (no velocities): {med[0]:.2f} s (min {med[1]:.2f}, max {med[2]:.2f})"
    )


def check_time(duration_s: float = 600.0, rounds: int = 3) -> None:
    """Time of the checks on a clean run (median of ``rounds``), with the default configuration
    and with the measured offset and mounting applied ("auto": EKF passes for the offset), against
    a whole default run."""
    run = simulate("car-city", duration_s, imu_grade="consumer", noise="white", seed=0)
    plain = load_config()
    auto = load_config(
        overrides={"mounting": {"imu_time_offset_s": "auto", "imu_to_body_rpy_deg": "auto"}}
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
    ap.add_argument("--velocity-only", action="store_true", help="only the velocity cases")
    a = ap.parse_args()
    grades = ("industrial",) if a.quick else GRADES + (BASIC if a.all_grades else ())
    tally: dict = {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        configs = {}
        for name, text in CONFIGS.items():
            if text is not None:
                (Path(tmp) / f"{name}.toml").write_text(text)
            configs[name] = None if text is None else Path(tmp) / f"{name}.toml"
        for seed in (int(s) for s in a.seeds.split(",")):
            for scenario in SCENARIOS:
                for grade in grades:
                    if not a.velocity_only:
                        sweep(scenario, grade, seed, Path(tmp), configs, tally)
                    vel_sweep(scenario, grade, seed, Path(tmp), configs, tally)
    print(
        f"\n{sum(sum(v.values()) for v in tally.values())} runs in {time.perf_counter() - t0:.0f} s; outcomes:"
    )
    for case, words in tally.items():
        print(f"  {case:28s} " + ", ".join(f"{w} {n}" for w, n in sorted(words.items())))
    print()
    if a.velocity_only:
        if not a.quick:
            velocity_check_time()
        return
    real_recordings(load_config())
    offsets_rtk(grades)
    if not a.quick:
        check_time()
        velocity_check_time()


if __name__ == "__main__":
    main()
