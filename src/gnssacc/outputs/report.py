"""Outputs a user can plot or feed to other tools: comparison table, metrics.json,
per-method trajectory CSV, and the error / trajectory figures."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..analysis.metrics import BASELINES, Score, improvement_pct, truth_at
from ..core.display import DISPLAY_SCALE, TRAJECTORY_COLUMNS, text_table
from ..core.recording import RecordedRun
from ..core.solution import NavSolution

#: Columns of ``trajectory_<id>.csv`` (display units, :mod:`gnssacc.core.display`).
TRAJECTORY_COLUMNS = list(TRAJECTORY_COLUMNS)


def trajectory_table(sol: NavSolution) -> np.ndarray:
    """The rows of ``trajectory_<id>.csv`` (see :data:`TRAJECTORY_COLUMNS`), in display units."""
    return np.column_stack([sol.t, np.degrees(sol.lat), np.degrees(sol.lon), sol.h, sol.v_n, np.degrees(sol.rpy),
                            sol.b_a * DISPLAY_SCALE[9:12], sol.b_g * DISPLAY_SCALE[12:15], sol.sigma * DISPLAY_SCALE])


def write_trajectory_csv(sol: NavSolution, path: Path) -> None:
    """Write one solution as CSV with a header row (units in the column names)."""
    # 1e-9 deg ~ 0.1 mm; velocities to 1e-4 m/s; angles to 1e-5 deg; biases and sigmas 6 significant digits.
    fmt = (["%.6f", "%.9f", "%.9f", "%.4f"] + ["%.4f"] * 3 + ["%.5f"] * 3
           + ["%.6g"] * (len(TRAJECTORY_COLUMNS) - 10))
    np.savetxt(path, trajectory_table(sol), delimiter=",", header=",".join(TRAJECTORY_COLUMNS), comments="",
               fmt=fmt)


#: The facts about a run that ``metrics.json`` keeps (under ``"run"``), from ``run.meta``: only
#: these, each small (per-sample arrays such as a simulation's true biases stay out).
RUN_FIELDS = {
    "source": "kind of source: kitti, csv, bag, simulator",
    "noise": "GNSS noise profile drawn from the truth (white, gm, none), if any",
    "seed": "its seed",
    "outages": "GNSS outage spans [s from the start]",
    "gnss_from_truth_hz": "rate of the fixes made from a bag's truth [Hz]",
    "imu_frame": "axes of a CSV run's imu.csv (frd, flu)",
    "bag_format": "ros1 or ros2",
    "topics": "the bag topics read: imu, gnss, truth, odometry",
    "truth_checks": "a bag's truth candidates against the fixes: frame, fixes compared, RMS [m], ratio [fix sigmas], ok",
    "odometry_frame": "where the wheel odometry came from",
    "gnss_file": "the GNSS file the fixes came from (gnss.pos, gnss.nmea, --gnss)",
    "gnss_format": "its format: csv, rtklib-pos, nmea",
    "gnss_time_system": "its time system (GPST, UTC, JST)",
    "gnss_clock": "the IMU clock its absolute times were put on: unix or gps",
    "gnss_qualities": "fixes per stated quality (fix, float, sbas, dgps, single, ppp, estimated, unknown)",
    "gnss_quality_dropped": "fixes dropped by [gnss] quality, per quality",
    "gnss_quality_inflated": "fixes whose sigmas [gnss] quality multiplied, per quality",
    "gnss_sigma_from": "NMEA fixes whose sigmas came from GST, HDOP x UERE (an assumption) or the default",
    "imu_mounting": "where a bag's IMU mounting came from, and its roll/pitch/yaw [deg]",
    "truth_origin": "how a bag's truth pose frame was placed",
    "damaged": "what a damaged bag lost",
    "time_fixes": "repairs of a bag's time stamps",
    "gaps": "IMU and GNSS gaps of a bag",
    "scenario": "simulator scenario",
    "imu_grade": "simulated IMU grade",
    "imu_rate_hz": "simulated IMU rate [Hz]",
    "gnss_rate_hz": "simulated GNSS rate [Hz]",
    "gnss_seed": "simulator seed of the fixes' noise",
    "origin_llh_deg": "tangent-plane origin [deg, deg, m]",
}


def run_facts(run: RecordedRun) -> dict:
    """The :data:`RUN_FIELDS` the run has (``outages`` from :attr:`RecordedRun.outages`)."""
    facts = {k: run.meta[k] for k in RUN_FIELDS if k in run.meta}
    if run.outages:
        facts["outages"] = [list(s) for s in run.outages]
    return facts


def metrics_dict(run: RecordedRun, sols: dict[str, NavSolution], scores: dict[str, Score], gnss: Score,
                 extra: dict, failed: dict[str, str] | None = None) -> dict:
    """The content of ``metrics.json``.

    Each entry of ``methods`` has ``status``: ``"ok"`` with the scores and statistics of a
    solution, or ``"failed"`` with ``error``, the one-line reason, for each of ``failed``
    (``{method: reason}``), listed after the solutions.
    """
    methods = {}
    for mid, sol in sols.items():
        sc = scores[mid]
        base = BASELINES.get(mid)
        methods[mid] = {
            "status": "ok",
            "prmse_m": sc.prmse_m, "hrmse_m": sc.hrmse_m, "prmse_outage_m": sc.prmse_outage_m,
            "rpy_rmse_deg": sc.rpy_rmse_deg, "n_epochs": sc.n_epochs, **sc.truth,
            "improvement_pct": improvement_pct(scores[base].prmse_m, sc.prmse_m) if base in scores else None,
            "runtime_s": sol.runtime_s,
            "realtime_factor": run.duration_s / sol.runtime_s if sol.runtime_s > 0 else None,
            "stats": sol.stats,
        }
    for mid, reason in (failed or {}).items():
        methods[mid] = {"status": "failed", "error": reason}
    return {"source": run.name, "where": run.where, "duration_s": run.duration_s, "t_start": run.t_start,
            "gnss_prmse_m": gnss.prmse_m, "gnss_hrmse_m": gnss.hrmse_m, "gnss_n_epochs": gnss.n_epochs,
            "n_fixes": len(run.gnss),
            "run": run_facts(run), "methods": methods, **extra}


def ok_methods(metrics: dict) -> dict:
    """The entries of ``metrics["methods"]`` that hold a solution (``status`` not ``"failed"``)."""
    return {mid: m for mid, m in metrics["methods"].items() if m.get("status", "ok") != "failed"}


def failed_methods(metrics: dict) -> dict[str, str]:
    """``{method: one-line reason}`` of the methods that failed."""
    return {mid: m.get("error", "") for mid, m in metrics["methods"].items() if m.get("status") == "failed"}


def write_json(data: dict, path: Path) -> None:
    path.write_text(json.dumps(data, indent=2, default=_json_default) + "\n")


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def _fmt(x, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def _nis_cell(metrics: dict, mid: str) -> str:
    """Position NIS per dof (EKF) or normalised GNSS residual (smoother), '!' when warned about."""
    c = metrics.get("consistency", {}).get(mid)
    if not c:
        return "-"
    value = c["nis"].get("pos")
    return _fmt(value, ".2f") + (" !" if c["warnings"] else "")


def table_rows(metrics: dict) -> tuple[list[str], list[list[str]]]:
    """The comparison table's header and rows (text cells), the raw fixes last; the failed
    methods are :func:`failed_methods`."""
    ok = ok_methods(metrics)
    outage = any(m["prmse_outage_m"] is not None for m in ok.values())
    head = ["method", "PRMSE [m]", "HRMSE [m]"] + (["outage PRMSE [m]"] if outage else []) + \
        ["NIS", "acc gain [%]", "wall [s]", "real-time x"]
    rows = []
    for mid, m in ok.items():
        rows.append([mid, _fmt(m["prmse_m"], ".2f"), _fmt(m["hrmse_m"], ".2f")] +
                    ([_fmt(m["prmse_outage_m"], ".2f")] if outage else []) +
                    [_nis_cell(metrics, mid), _fmt(m["improvement_pct"], "+.1f"), f"{m['runtime_s']:.3f}",
                     _fmt(m["realtime_factor"], ".0f")])
    if metrics.get("gnss_prmse_m") is not None:
        rows.append(["gnss (raw fixes)", _fmt(metrics["gnss_prmse_m"], ".2f"), _fmt(metrics["gnss_hrmse_m"], ".2f")] +
                    (["-"] if outage else []) + ["-", "-", "-", "-"])
    return head, rows


def table_notes(metrics: dict) -> tuple[list[str], list[str]]:
    """The lines above the comparison table (the scored window) and below it (the NIS legend)."""
    return _window_lines(metrics), _legend(metrics)


def format_table(metrics: dict) -> str:
    """The comparison table printed by ``gnssacc run``, headed by the window it scores; a method
    that failed has a ``failed: <reason>`` row."""
    head, rows = table_rows(metrics)
    failed = failed_methods(metrics)
    lines = text_table(head, rows, max([0] + [len(mid) for mid in failed]))
    first = len(lines[1].split("  ")[0])
    # A failed row is not cut into columns: its reason runs on after the method id.
    failed_rows = [f"{mid.ljust(first)}  failed: {reason}" for mid, reason in failed.items()]
    return "\n".join(_window_lines(metrics) + lines + failed_rows + _legend(metrics))


def _window_lines(metrics: dict) -> list[str]:
    w = metrics.get("scored_window_s")
    if not w:
        return []
    t0 = metrics.get("t_start", 0.0)
    frac = (w[1] - w[0]) / metrics["duration_s"] if metrics["duration_s"] > 0 else 1.0
    n = {m["n_epochs"] for m in ok_methods(metrics).values()}
    return [f"scored over t = {w[0] - t0:.1f} .. {w[1] - t0:.1f} s from the start ({100 * frac:.0f} % of the run), "
            f"every row: {'/'.join(str(x) for x in sorted(n))} epochs per method, "
            f"{metrics.get('gnss_n_epochs', '-')} raw fixes"]


def _legend(metrics: dict) -> list[str]:
    if not metrics.get("consistency"):
        return []
    return ["NIS: mean normalised innovation (EKF) or GNSS residual (smoother) squared per dof; "
            "1 = consistent, '!' = see the warnings"]


def figure(figsize, nrows: int = 1, ncols: int = 1, **kw):
    """A matplotlib figure and axes for a file (the Agg backend: never needs a display)."""
    import matplotlib
    matplotlib.use("Agg")  # files only; never needs a display
    import matplotlib.pyplot as plt

    return plt.subplots(nrows, ncols, figsize=figsize, **kw)


def _finish(fig, ax, path: Path, xlabel: str, ylabel: str, title: str, legend: bool = True,
            title_ax=None) -> None:
    import matplotlib.pyplot as plt

    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    (title_ax or ax).set_title(title)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: Line styles cycled over the methods, so that two methods whose errors coincide stay distinct
#: (the later one dashed or dotted on top of the earlier, thinner).
_STYLES = (("-", 1.6), ("--", 1.2), (":", 1.4), ("-.", 1.0))


def plot_errors(run: RecordedRun, sols: dict[str, NavSolution], path: Path) -> None:
    """North, east and down position error per method against time, each with its +-3 sigma
    band (the method's own 1-sigma, drawn as thin edges in its colour and line style); GNSS
    outages shaded grey when there are any. Each axis spans the 98th percentile of the errors and
    bands (the widest 2 % of a band, deep in an outage, is cut off)."""
    fig, axes = figure((10, 7.5), nrows=3, sharex=True)
    outages = run.outages
    extent = np.zeros(3)   # per axis: the 98th percentile of |error| and 3 sigma over the methods
    for k, (mid, sol) in enumerate(sols.items()):
        p_true, valid = truth_at(run, sol.t)
        err = run.origin.to_ned(sol.lat, sol.lon, sol.h)[valid] - p_true[valid]
        t, sig = sol.t[valid] - run.t_start, sol.sigma[valid, 0:3]
        style, lw = _STYLES[k % len(_STYLES)]
        for i, ax in enumerate(axes):
            line, = ax.plot(t, err[:, i], style, lw=lw, label=mid, zorder=3)
            for sign in (-1, 1):   # the band as thin edges in the method's colour and style
                ax.plot(t, sign * 3 * sig[:, i], style, lw=0.7, color=line.get_color(), alpha=0.6, zorder=2)
        if len(t):
            extent = np.maximum(extent, np.percentile(np.maximum(np.abs(err), 3 * sig), 98, axis=0))
    for ax, axis, lim in zip(axes, ("north", "east", "down"), extent):
        if lim > 0:   # a band that opens in a long outage must not flatten every error line
            ax.set_ylim(-1.15 * lim, 1.15 * lim)
        for a, b in outages:
            ax.axvspan(a, b, color="0.85", zorder=0)
        ax.set_ylabel(f"{axis} error [m]")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=min(len(sols), 4), fontsize="small", loc="upper right")
    note = "; grey: GNSS outages" if outages else ""
    _finish(fig, axes[-1], path, "time since start [s]", "down error [m]",
            f"{run.name}: position error, estimate minus truth, with +-3 sigma bands{note}", legend=False,
            title_ax=axes[0])


def plot_trajectory(run: RecordedRun, sols: dict[str, NavSolution], path: Path) -> None:
    """North/east track of each method with the truth and the GNSS fixes."""
    fig, ax = figure((7.5, 7.5))
    fx = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h)
    ax.plot(fx[:, 1], fx[:, 0], ".", ms=2.5, color="0.6", label="GNSS fixes")
    if run.truth is not None:
        tr = run.origin.to_ned(run.truth.lat, run.truth.lon, run.truth.h)
        ax.plot(tr[:, 1], tr[:, 0], "k-", lw=1.5, label="truth")
    for mid, sol in sols.items():
        p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
        ax.plot(p[:, 1], p[:, 0], lw=1, label=mid)
    ax.set_aspect("equal", adjustable="datalim")
    _finish(fig, ax, path, "east [m]", "north [m]",
            f"{run.name}: track (origin {np.degrees(run.origin.lat0):.5f}, {np.degrees(run.origin.lon0):.5f} deg)")
