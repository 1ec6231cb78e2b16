"""How well each estimator knows its own error: a consistency table over KITTI, the simulated
scenarios and the shared real recordings, with default settings (``gnssacc.process``).

Per case and method (``ekf``, ``smoother``): PRMSE [m]; yaw RMSE [deg]; position NEES per dof;
attitude NEES per dof pooled and roll / pitch / yaw; the share of epochs whose wrapped yaw error
exceeds three stated sigma and the last epoch's yaw sigma [deg]; the NIS per dof of each update
kind. A ``!`` follows a NEES whose run raised a warning about it (outside its chi-square band). With
several seeds each figure is the median over them, and the NEES carry their range.

Cases:

* ``kitti``: the gtsam KITTI sequence (1 Hz RTK-grade truth with simulated fix noise of the seed;
  its truth has no attitude).
* ``sim:...``: the simulator (:mod:`gnssacc.sources.sim`) with scenario, IMU grade, fix noise
  (``white``, time-correlated ``gm``, or receiver-filtered at 10 Hz, ``filtered 10 Hz``), outages
  (``--outage-every 60:20``), the non-holonomic constraint off (``nhc off``) and wheel odometry
  (``odo``).
* ``rover 20 Hz no sigmas``: the slow consumer-IMU rover of ``bench_hard_traits.py`` (20 Hz
  receiver-filtered fixes that state no sigma).
* ``sideways``: the sideways-IMU ROS 1 bag of ``bench_hard_traits.py`` with automatic mounting
  (a consumer UGV, odometry; truth from the simulator).
* ``comma``: comma2k19 example 1 against comma's own post-processed pose (position only), which
  describes the camera: as a user would run it (no lever arm: the estimate is the antenna's, ~1.8
  m away), and with the antenna's lever arm measured from that pose (``comma lever arm``). The
  pose is comma's fusion of the same u-blox fixes, not an independent truth.
* ``vn310-lckf`` / ``vn310-tckf``: the static VN-310E logs; no position truth, attitude against the
  unit's own dual-antenna solution (a reference, not a truth: its own sigma is not accounted for).

``--quick`` runs every case with one seed (5-10 min on two loaded cores); the default runs
``--seeds`` seeds of each simulated case (default 3, the median shown; ~25 min; KITTI always
seeds 0-4).

``--kitti-seeds N`` runs KITTI over the fix-noise seeds ``0 .. N-1`` (default 5); with five or more
seeds of a case, a line per method says on how many seeds its NEES leaves the acceptance range
[0.5, 1.5], how many a consistent estimator would leave at each run's effective count, and the
NEES pooled over the seeds.

``--set SECTION.KEY=VALUE`` (repeatable) sets a configuration value for every case (e.g.
``--set imu.gyro_turn_error_ppm=1000``, the turn allowance before ``"auto"``).

    python bench/bench_consistency.py [--quick] [--seeds 3] [--only car-city] [--json out.json]
        [--set imu.gyro_turn_error_ppm=1000]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
import tomllib
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

import gnssacc
from gnssacc.analysis.errorstats import AXES_RPY, nees
from gnssacc.analysis.observability import state_errors
from gnssacc.core.rotations import wrap_angle

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_recordings import DATA, ned_rotation, comma, vn310  # noqa: E402

METHODS = ["ekf", "smoother"]
KINDS = ("pos", "acc", "zupt", "zaru", "nhc", "odo")
GRADES = ("consumer", "industrial", "tactical")
SCENARIOS = ("car", "car-city", "ugv", "ugv-slow", "static")


@dataclass
class Case:
    """One row group: a source made per seed and the options of ``gnssacc.process``."""

    name: str
    source: object  # a str (``kitti``, ``sim:...``) or a callable seed -> (RecordedRun, extra)
    seeds: tuple = (0,)
    options: dict = field(default_factory=dict)


def sim_case(scenario, grade, noise="white", outages=False, nhc=True, odo=False, seeds=(0,)):
    """A simulated case (300 s; odometry at 10 Hz; outages 20 s every 60 s; receiver-filtered
    fixes, ``noise="filtered"``, at 10 Hz)."""
    spec = f"sim:{scenario},imu={grade},duration=300" + (",odom_hz=10" if odo else "")
    spec += ",gnss_hz=10" if noise == "filtered" else ""
    name = f"{scenario} {grade}" + {"gm": " gm", "filtered": " filtered 10 Hz"}.get(noise, "")
    name += (" outages" if outages else "") + ("" if nhc else " nhc-off") + (" odo" if odo else "")
    options = {"noise": noise}
    if outages:
        options["outage_every"] = "60:20"
    if not nhc:
        options["config"] = {"nhc": {"enabled": False}}
    return Case(name, spec, seeds, options)


def sideways_bag(seed: int, folder: Path):
    """The sideways-IMU bag of ``bench_hard_traits.py`` with ``imu_to_body_rpy_deg = "auto"``."""
    from bench_hard_traits import write_sideways_bag

    run, bag = write_sideways_bag(folder, seed)
    auto = {"mounting": {"imu_to_body_rpy_deg": "auto"}}
    loaded = gnssacc.load(str(bag), config=auto)
    return replace(loaded, truth=run.truth), {"config": auto}, None


def rover_fixes(seed: int, folder: Path):
    """The slow consumer-IMU rover of ``bench_hard_traits.py``: 20 Hz receiver-filtered fixes
    (Gauss-Markov 0.6 / 1.0 m, 30 s) that state no sigma, 367 s."""
    from bench_hard_traits import rover_run

    return rover_run(seed), {}, None


def vn310_case(log: str):
    """A VN-310E static log with the unit's own attitude as the reference (``t`` [s], rpy [rad]),
    where the log has it (``lckf``; ``tckf`` has no attitude)."""

    def make(seed: int, folder: Path):
        root = DATA / "vn310_static"
        run = vn310(root, log)
        gnss = _csv_columns(root / f"{log}_vn310-gnss.csv")
        keys = [f"Att::YawPitchRoll::{a} [deg]" for a in "RPY"]
        if not all(k in gnss for k in keys):
            return run, {}, None
        imu = _csv_columns(root / f"{log}_vn310-imu.csv")
        t = gnss["GNSS1::Tow [ns]"] * 1e-9 - imu["GpsTow [s]"][0]
        return run, {}, (t, np.radians(np.column_stack([gnss[k] for k in keys])))

    return make


def comma_case(lever_arm: bool):
    """comma2k19 example 1; with ``lever_arm`` the antenna's offset from the reference point (the
    camera, which comma's pose describes) is configured, as measured from that pose: the mean of
    ``R_nb^T (fix - pose)`` over the fixes (std 0.1-0.4 m per axis)."""

    def make(seed: int, folder: Path):
        root = DATA / "comma2k19_example1"
        run = comma(root)
        if not lever_arm:
            return run, {}, None
        from scipy.spatial.transform import Rotation

        q = np.load(root / "global_pose/frame_orientations")  # w, x, y, z: ECEF <- camera
        t_pose = np.load(root / "global_pose/frame_times")
        tr = run.truth
        R_nb = np.einsum(
            "kij,kjl->kil",
            ned_rotation(tr.lat, tr.lon),
            Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix(),
        )
        g = run.gnss
        p_pose = run.origin.to_ned(tr.lat, tr.lon, tr.h)
        at = np.column_stack([np.interp(g.t, t_pose, p_pose[:, i]) for i in range(3)])
        k = np.clip(np.searchsorted(t_pose, g.t), 0, len(t_pose) - 1)
        offset = np.einsum("kji,kj->ki", R_nb[k], run.origin.to_ned(g.lat, g.lon, g.h) - at)
        return run, {"config": {"gnss": {"lever_arm_b_m": offset.mean(axis=0).tolist()}}}, None

    return make


def _csv_columns(path: Path) -> dict:
    head = path.open().readline().strip().split(",")
    data = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=range(len(head)))
    return {name.strip(): data[:, i] for i, name in enumerate(head)}


def cases(quick: bool, n_seeds: int, kitti_seeds: int = 5) -> list[Case]:
    """Every case: KITTI seeds ``0 .. kitti_seeds - 1``; the simulated grid with one seed
    (``quick``) or ``n_seeds``; the real recordings."""
    s = (0,) if quick else tuple(range(n_seeds))
    out = [Case("kitti", "kitti", tuple(range(kitti_seeds)))]
    out += [sim_case(sc, g, seeds=s) for sc in SCENARIOS for g in GRADES]
    for sc in ("car-city", "ugv"):
        for g in GRADES:
            out += [
                sim_case(sc, g, "gm", seeds=s),
                sim_case(sc, g, outages=True, seeds=s),
                sim_case(sc, g, nhc=False, seeds=s),
                sim_case(sc, g, outages=True, nhc=False, seeds=s),
                sim_case(sc, g, outages=True, odo=True, seeds=s),
            ]
    out += [
        sim_case("car", "consumer", "gm", outages=True, seeds=s),
        sim_case("ugv-slow", "consumer", "gm", seeds=s),
        sim_case("ugv-slow", "consumer", odo=True, seeds=s),
        sim_case("ugv-slow", "consumer", "filtered", seeds=s),
        Case("sideways bag auto", sideways_bag, s),
        Case("rover 20 Hz no sigmas", rover_fixes, s),
    ]
    if DATA.is_dir():
        out += [
            Case("comma", comma_case(False)),
            Case("comma lever arm", comma_case(True)),
            Case("vn310-lckf", vn310_case("lckf")),
            Case("vn310-tckf", vn310_case("tckf")),
        ]
    return out


def _outside(n: dict | None) -> bool:
    """Whether an :func:`~gnssacc.analysis.errorstats.nees` (pooled or an axis) is out of band."""
    return bool(n and (n["pooled_outside"] or n["outside"]))


def method_row(res, mid: str, ref) -> dict:
    """The figures of one method of one finished run (attitude against ``ref`` when given)."""
    m = res.metrics["methods"][mid]
    cons = res.metrics["consistency"].get(mid, {})
    sol = res.solutions[mid]
    e = m.get("errors") or {}
    sig = np.asarray(sol.sigma)[:, 6:9]
    if ref is not None:
        t, rpy = ref
        inside = (sol.t >= t[0]) & (sol.t <= t[-1])
        r = np.column_stack([np.interp(sol.t[inside], t, np.unwrap(rpy[:, i])) for i in range(3)])
        err, sig = wrap_angle(sol.rpy[inside] - r), sig[inside]
        att = nees(err, sig, AXES_RPY)
    elif res.run.truth is not None and res.run.truth.rpy is not None:
        err, att = state_errors(res.run, sol)[:, 6:9], e.get("nees_attitude")
    else:
        err, att = None, None
    yaw = {"yaw_rmse": None, "yaw_out3": None, "yaw_sigma_end": None}
    if err is not None:
        ok = np.isfinite(err[:, 2]) & (sig[:, 2] > 0)
        yaw = {
            "yaw_rmse": math.degrees(float(np.sqrt(np.mean(err[ok, 2] ** 2)))),
            "yaw_out3": float(np.mean(np.abs(err[ok, 2]) > 3.0 * sig[ok, 2])),
            "yaw_sigma_end": math.degrees(float(sig[ok, 2][-1])),
        }
    pos = e.get("nees_position")
    return {
        "prmse": m.get("prmse_m"),
        **yaw,
        "nees_pos": pos["value"] if pos else None,
        "nees_pos_warn": _outside(pos),
        "nees_pos_neff": pos["n_eff"] if pos else None,
        "nees_att": att["value"] if att else None,
        "nees_att_warn": _outside(att),
        "nees_att_neff": att["n_eff"] if att else None,
        **{f"nees_{a}": (att["per_axis"][a]["value"] if att else None) for a in AXES_RPY},
        **{f"nis_{k}": (cons.get("nis") or {}).get(k) for k in KINDS},
    }


def run_case(case: Case, seed: int) -> dict:
    """``{method: figures}`` of one seed of a case (or ``{"error": text}``)."""
    with tempfile.TemporaryDirectory() as tmp:
        try:  # a refusal is a result of the bench, not its end
            ref = None
            if callable(case.source):
                source, options, ref = case.source(seed, Path(tmp))
                config = merged(case.options.get("config", {}), options.get("config", {}))
                options = {**case.options, **options, **({"config": config} if config else {})}
            else:
                source, options = case.source, {**case.options, "seed": seed}
            res = gnssacc.process(source, methods=METHODS, **options)
        except Exception as exc:
            return {"error": f"{type(exc).__name__}: {str(exc)[:150]}"}
    out = {mid: method_row(res, mid, ref) for mid in METHODS if mid in res.solutions}
    start = res.metrics.get("start") or {}
    out["yaw_determined"] = start.get("yaw_determined", True)
    return out


def settings(items: list) -> dict:
    """``{section: {key: value}}`` of ``--set SECTION.KEY=VALUE`` items (the value read as TOML:
    ``false``, ``1000``, ``[0.0, 0.5, 0.0]``; else the text)."""
    out: dict = {}
    for item in items:
        name, _, text = item.partition("=")
        section, _, key = name.partition(".")
        try:
            value: object = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text
        out.setdefault(section, {})[key] = value
    return out


def merged(base: dict, over: dict) -> dict:
    """Configuration ``{section: {key: value}}`` ``base`` with ``over``'s values on top, section
    by section (new dicts; neither argument changes)."""
    out = {s: dict(v) for s, v in base.items()}
    for section, values in over.items():
        out.setdefault(section, {}).update(values)
    return out


def with_settings(case: Case, extra: dict) -> Case:
    """``case`` with ``extra`` merged into its configuration (a case's own settings win)."""
    if not extra:
        return case
    config = merged(extra, case.options.get("config", {}))
    return replace(case, options={**case.options, "config": config})


def _median(values):
    v = [x for x in values if x is not None and np.isfinite(x)]
    return float(np.median(v)) if v else None


def _f(x, spec=".2f"):
    return "-" if x is None else format(x, spec)


def _nees_cell(rows, key: str) -> str:
    """Median NEES, '!' when a seed warned about it, and the range over seeds."""
    v = [r[key] for r in rows if r.get(key) is not None]
    if not v:
        return "-"
    cell = _f(float(np.median(v)), ".2f" if np.median(v) < 100 else ".0f")
    cell += " !" if any(r.get(key + "_warn") for r in rows) else ""
    if len(v) > 1:
        cell += f" ({min(v):.2g}-{max(v):.2g})"
    return cell


COLUMNS = (
    ("PRMSE", lambda rs: _f(_median(r["prmse"] for r in rs))),
    ("yaw RMSE", lambda rs: _f(_median(r["yaw_rmse"] for r in rs))),
    ("NEES pos", lambda rs: _nees_cell(rs, "nees_pos")),
    ("NEES att", lambda rs: _nees_cell(rs, "nees_att")),
    (
        "roll/pitch/yaw",
        lambda rs: "/".join(_f(_median(r[f"nees_{a}"] for r in rs), ".1f") for a in AXES_RPY),
    ),
    ("yaw>3s", lambda rs: _f(_median(r["yaw_out3"] for r in rs), ".0%")),
    ("yaw sig", lambda rs: _f(_median(r["yaw_sigma_end"] for r in rs), ".2g")),
    (
        "NIS pos/acc/zupt/zaru/nhc/odo",
        lambda rs: "/".join(_f(_median(r[f"nis_{k}"] for r in rs)) for k in KINDS),
    ),
)


#: The acceptance range of a run's mean NEES per dof (issue 33).
ACCEPT = (0.5, 1.5)


def _nees_dof(rows: list, key: str) -> tuple[np.ndarray, np.ndarray]:
    """A NEES of method rows (``key``: ``nees_pos`` or ``nees_att``) and each run's effective
    chi-square dof (its effective count times 3 axes), over the rows that have both."""
    have = [r for r in rows if r.get(key) is not None and r.get(key + "_neff") is not None]
    return np.array([r[key] for r in have]), 3.0 * np.array([r[key + "_neff"] for r in have])


def spread_lines(results: dict, min_seeds: int = 5) -> list[str]:
    """Per case with at least ``min_seeds`` seeds and per method and NEES: how many seeds fall
    outside :data:`ACCEPT`, the NEES pooled over the seeds (weighted by each run's effective
    count of independent epochs times dof), and how many a consistent estimator would leave
    outside (the sum over seeds of the chi-square tail probability at each run's effective dof)."""
    from scipy.stats import chi2

    out = []
    for name, per_seed in results.items():
        ok = [r for r in per_seed if "error" not in r]
        for mid in METHODS:
            for key in ("nees_pos", "nees_att"):
                rows = [r[mid] for r in ok if (r.get(mid) or {}).get(key) is not None]
                v, k = _nees_dof(rows, key)
                if len(rows) < min_seeds or len(v) < len(rows):
                    continue
                chance = 1.0 - (chi2.cdf(ACCEPT[1] * k, k) - chi2.cdf(ACCEPT[0] * k, k))
                out.append(
                    f"{name} {mid} {key}: outside [{ACCEPT[0]}, {ACCEPT[1]}] on "
                    f"{int(np.sum((v < ACCEPT[0]) | (v > ACCEPT[1])))} of {len(v)} seeds "
                    f"(a consistent estimator: {chance.sum():.1f}); median {np.median(v):.2f}, "
                    f"pooled {np.sum(v * k) / np.sum(k):.2f} over {k.sum():.0f} effective dof"
                )
    return out


#: Cases left out of :func:`population_lines`: references that are no independent truth.
NOT_TRUTH = ("comma", "vn310")


def population_lines(results: dict) -> list[str]:
    """Over every run with a truth (``NOT_TRUTH`` left out) and both methods, per NEES: the runs
    above and below :data:`ACCEPT` against the number consistent estimators would leave there at
    each run's effective count (the chi-square tail at ``effective_count`` times 3 dof; where the
    bench's NEES scatter less than their chi-square, as its position NEES do, fewer)."""
    from scipy.stats import chi2

    out = []
    rows = [
        r.get(mid) or {}
        for name, per_seed in results.items()
        if not name.startswith(NOT_TRUTH)
        for r in per_seed
        for mid in METHODS
    ]
    for key in ("nees_pos", "nees_att"):
        va, ka = _nees_dof(rows, key)
        if not len(va):
            continue
        out.append(
            f"all runs, {key}: above {ACCEPT[1]} {int(np.sum(va > ACCEPT[1]))} of {len(va)} "
            f"(consistent: about {np.sum(chi2.sf(ACCEPT[1] * ka, ka)):.1f}), below {ACCEPT[0]} "
            f"{int(np.sum(va < ACCEPT[0]))} (about {np.sum(chi2.cdf(ACCEPT[0] * ka, ka)):.1f})"
        )
    return out


def table(results: dict) -> str:
    """The printed table: one row per case and method."""
    head = ["case", "method", "seeds"] + [h for h, _ in COLUMNS]
    rows = []
    for name, per_seed in results.items():
        ok = [r for r in per_seed if "error" not in r]
        if not ok:
            rows.append([name, "-", "0", per_seed[0]["error"]] + [""] * (len(COLUMNS) - 1))
            continue
        for mid in METHODS:
            rs = [r[mid] for r in ok if mid in r]
            if rs:
                rows.append([name, mid, str(len(rs))] + [f(rs) for _, f in COLUMNS])
    width = [max(len(str(r[i])) for r in rows + [head]) for i in range(len(head))]

    def line(r):
        return "  ".join(str(c).ljust(w) for c, w in zip(r, width, strict=True)).rstrip()

    return "\n".join([line(head), line(["-" * w for w in width])] + [line(r) for r in rows])


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="one seed per simulated case")
    p.add_argument("--seeds", type=int, default=3, help="seeds per simulated case (full mode)")
    p.add_argument("--kitti-seeds", type=int, default=5, help="KITTI's fix-noise seeds 0..N-1")
    p.add_argument("--only", default="", help="run only the cases whose name contains this")
    p.add_argument("--json", help="also write every seed's figures to this file")
    p.add_argument("--table", help="print the table of a file --json wrote, and run nothing")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="a configuration value for every case (e.g. imu.gyro_turn_error_ppm=10000)",
    )
    a = p.parse_args(argv)
    extra = settings(a.set)
    warnings.simplefilter("ignore")  # the table carries the warnings as '!'
    if a.table and not Path(a.table).is_file():
        p.error(f"--table {a.table}: no such file (it reads what --json wrote)")
    results = json.loads(Path(a.table).read_text()) if a.table else {}
    t0 = time.perf_counter()
    for case in cases(a.quick, a.seeds, a.kitti_seeds):
        if a.table or (a.only and a.only not in case.name):
            continue
        results[case.name] = []
        for seed in case.seeds:
            t = time.perf_counter()
            results[case.name].append(run_case(with_settings(case, extra), seed))
            print(f"{case.name} seed {seed}: {time.perf_counter() - t:.0f} s", flush=True)
        if a.json:  # every case as it ends: a long run that stops keeps what it measured
            Path(a.json).write_text(json.dumps(results, indent=1) + "\n")
    print(f"\n{len(results)} cases in {time.perf_counter() - t0:.0f} s\n")
    print(table(results))
    print("\n".join(spread_lines(results) + population_lines(results)))
    print(
        "\nNEES: mean (error / stated sigma)^2 per dof, 1 = consistent; '!' = outside its "
        "chi-square band (a run's warning); (a-b) = range over seeds. yaw>3s: share of epochs with "
        "|yaw error| > 3 stated sigma; yaw sig: stated yaw sigma at the end [deg]. vn310: attitude "
        "against the unit's own solution."
    )


if __name__ == "__main__":
    main()
