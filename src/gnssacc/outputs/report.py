"""Outputs a user can plot or feed to other tools: comparison table, metrics.json,
per-method trajectory CSV, and the error / trajectory figures."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..analysis.metrics import BASELINES, Score, improvement_pct
from ..core.display import DISPLAY_SCALE, TRAJECTORY_COLUMNS, text_table
from ..core.recording import RecordedRun
from ..core.solution import NavSolution
from ..core.states import BA, BG, YAW

#: Columns of ``trajectory_<id>.csv`` (display units, :mod:`gnssacc.core.display`).
TRAJECTORY_COLUMNS = list(TRAJECTORY_COLUMNS)


def trajectory_table(sol: NavSolution) -> np.ndarray:
    """The rows of ``trajectory_<id>.csv`` (see :data:`TRAJECTORY_COLUMNS`), in display units."""
    return np.column_stack(
        [
            sol.t,
            np.degrees(sol.lat),
            np.degrees(sol.lon),
            sol.h,
            sol.v_n,
            np.degrees(sol.rpy),
            sol.b_a * DISPLAY_SCALE[BA],
            sol.b_g * DISPLAY_SCALE[BG],
            sol.sigma * DISPLAY_SCALE,
        ]
    )


#: A stated yaw 1-sigma above this says the data never told the yaw [deg]: the table says "yaw
#: undetermined" for every method whose trajectory has it (a third of a half turn: a heading
#: either side of the truth by more than a right angle is then within three sigma).
YAW_UNDETERMINED_SIGMA_DEG = 30.0


def yaw_sigma_summary(sol: NavSolution) -> dict:
    """The stated yaw 1-sigma of a solution: at the end and its largest [deg], and the share of
    epochs where it exceeds :data:`YAW_UNDETERMINED_SIGMA_DEG` (``metrics.json`` per method)."""
    sig = np.degrees(sol.sigma[:, YAW][:, 0]) if len(sol) else np.zeros(0)
    if not len(sig):
        return {"end_deg": None, "max_deg": None, "undetermined_share": 0.0}
    return {
        "end_deg": float(sig[-1]),
        "max_deg": float(np.max(sig)),
        "undetermined_share": float(np.mean(sig > YAW_UNDETERMINED_SIGMA_DEG)),
    }


def write_trajectory_csv(sol: NavSolution, path: Path) -> None:
    """Write one solution as CSV with a header row (units in the column names)."""
    # 1e-9 deg ~ 0.1 mm; velocities to 1e-4 m/s; angles to 1e-5 deg; biases and sigmas 6 significant digits.
    fmt = (
        ["%.6f", "%.9f", "%.9f", "%.4f"]
        + ["%.4f"] * 3
        + ["%.5f"] * 3
        + ["%.6g"] * (len(TRAJECTORY_COLUMNS) - 10)
    )
    np.savetxt(
        path,
        trajectory_table(sol),
        delimiter=",",
        header=",".join(TRAJECTORY_COLUMNS),
        comments="",
        fmt=fmt,
    )


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


def metrics_dict(
    run: RecordedRun,
    sols: dict[str, NavSolution],
    scores: dict[str, Score],
    gnss: Score,
    extra: dict,
    failed: dict[str, str] | None = None,
) -> dict:
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
            "prmse_m": sc.prmse_m,
            "hrmse_m": sc.hrmse_m,
            "prmse_outage_m": sc.prmse_outage_m,
            "rpy_rmse_deg": sc.rpy_rmse_deg,
            "n_epochs": sc.n_epochs,
            "yaw_sigma": yaw_sigma_summary(sol),
            **sc.truth,
            "errors": sc.errors,
            "improvement_pct": improvement_pct(scores[base].prmse_m, sc.prmse_m)
            if base in scores
            else None,
            "runtime_s": sol.runtime_s,
            "realtime_factor": run.duration_s / sol.runtime_s if sol.runtime_s > 0 else None,
            "stats": {
                k: v for k, v in sol.stats.items() if not isinstance(v, np.ndarray)
            },  # not per-update series
        }
    for mid, reason in (failed or {}).items():
        methods[mid] = {"status": "failed", "error": reason}
    return {
        "source": run.name,
        "where": run.where,
        "duration_s": run.duration_s,
        "t_start": run.t_start,
        "gnss_prmse_m": gnss.prmse_m,
        "gnss_hrmse_m": gnss.hrmse_m,
        "gnss_n_epochs": gnss.n_epochs,
        "gnss_errors": gnss.errors,
        "n_fixes": len(run.gnss),
        "run": run_facts(run),
        "methods": methods,
        **extra,
    }


def ok_methods(metrics: dict) -> dict:
    """The entries of ``metrics["methods"]`` that hold a solution (``status`` not ``"failed"``)."""
    return {mid: m for mid, m in metrics["methods"].items() if m.get("status", "ok") != "failed"}


def failed_methods(metrics: dict) -> dict[str, str]:
    """``{method: one-line reason}`` of the methods that failed."""
    return {
        mid: m.get("error", "")
        for mid, m in metrics["methods"].items()
        if m.get("status") == "failed"
    }


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


def _get(d: dict | None, *keys):
    """``d[k0][k1]...`` or ``None`` where a level is missing."""
    for k in keys:
        if not isinstance(d, dict) or d.get(k) is None:
            return None
        d = d[k]
    return d


def _flagged(metrics: dict, mid: str, column: str) -> bool:
    """Whether a warning about ``mid`` concerns table column ``column`` (:data:`COLUMNS` of
    :mod:`gnssacc.analysis.consistency`)."""
    c = metrics.get("consistency", {}).get(mid) or {}
    flags = c.get("flags")
    if flags is None:  # metrics.json of an older version: every warning was shown on the NIS
        return column == "nis" and bool(c.get("warnings"))
    return column in flags


def _cell(value, spec: str, warned: bool = False) -> str:
    return _fmt(value, spec) + (" !" if warned and value is not None else "")


def _columns(metrics: dict) -> list[tuple[str, object]]:
    """The table's columns: ``(header, cell(mid, m) -> str)``, those the run has figures for."""
    ok = ok_methods(metrics)
    truth = any(m.get("prmse_m") is not None for m in ok.values())
    cons = lambda mid, k: _get(metrics, "consistency", mid, "nis", k)
    cols = [("method", None)]
    if truth:
        cols += [
            ("PRMSE [m]", lambda mid, m: _fmt(m.get("prmse_m"), ".2f")),
            ("HRMSE [m]", lambda mid, m: _fmt(m.get("hrmse_m"), ".2f")),
            ("CEP95 [m]", lambda mid, m: _fmt(_get(m, "errors", "horizontal", "cep95"), ".2f")),
            (
                "PRMSE at fixes [m]",
                lambda mid, m: _cell(
                    _get(m, "errors", "at_fixes", "prmse_m"), ".2f", _flagged(metrics, mid, "fixes")
                ),
            ),
        ]
        if any(m.get("prmse_outage_m") is not None for m in ok.values()):
            cols.append(("outage PRMSE [m]", lambda mid, m: _fmt(m.get("prmse_outage_m"), ".2f")))
        if any(_get(m, "errors", "attitude_axes") for m in ok.values()):
            cols.append(
                (
                    "yaw RMSE [deg]",
                    lambda mid, m: _fmt(_get(m, "errors", "attitude_axes", "yaw", "rmse"), ".2f"),
                )
            )
        cols.append(
            (
                "NEES pos",
                lambda mid, m: _cell(
                    _get(m, "errors", "nees_position", "value"),
                    ".2f",
                    _flagged(metrics, mid, "nees"),
                ),
            )
        )
        if any(_get(m, "errors", "nees_attitude") for m in ok.values()):
            cols.append(
                (
                    "NEES att",
                    lambda mid, m: _cell(
                        _get(m, "errors", "nees_attitude", "value"),
                        ".2f",
                        _flagged(metrics, mid, "nees_att"),
                    ),
                )
            )
    else:
        cols.append(
            (
                "fix residual [m]",
                lambda mid, m: _cell(
                    _get(m, "errors", "fix_residual", "rmse"),
                    ".2f",
                    _flagged(metrics, mid, "fixes"),
                ),
            )
        )
    cols.append(
        ("NIS", lambda mid, m: _cell(cons(mid, "pos"), ".2f", _flagged(metrics, mid, "nis")))
    )
    if any(cons(mid, "vel") is not None for mid in ok):  # a run with GNSS velocities
        if truth:
            cols.append(
                (
                    "vel RMSE [m/s]",
                    lambda mid, m: _fmt(_get(m, "errors", "velocity", "rmse"), ".3f"),
                )
            )
        cols.append(
            (
                "NIS vel",
                lambda mid, m: _cell(cons(mid, "vel"), ".2f", _flagged(metrics, mid, "vel")),
            )
        )
    cols += [
        ("acc gain [%]", lambda mid, m: _fmt(m.get("improvement_pct"), "+.1f")),
        ("wall [s]", lambda mid, m: f"{m['runtime_s']:.3f}"),
        ("real-time x", lambda mid, m: _fmt(m.get("realtime_factor"), ".0f")),
    ]
    return cols


def _fix_cells(metrics: dict, head: list[str]) -> list[str]:
    """The raw fixes' row: their own figures at their epochs (the like-for-like reference)."""
    g = metrics.get("gnss_errors") or {}
    own = {
        "PRMSE [m]": _fmt(metrics.get("gnss_prmse_m"), ".2f"),
        "HRMSE [m]": _fmt(metrics.get("gnss_hrmse_m"), ".2f"),
        "CEP95 [m]": _fmt(_get(g, "horizontal", "cep95"), ".2f"),
        "PRMSE at fixes [m]": _fmt(metrics.get("gnss_prmse_m"), ".2f"),
    }
    return ["gnss (raw fixes)"] + [own.get(h, "-") for h in head[1:]]


#: Relative PRMSE difference [-] under which two methods are named together as the best.
TIE = 0.01


def _accuracy(m: dict) -> float | None:
    """A method's like-for-like accuracy: its PRMSE at the raw fixes' epochs, else its PRMSE."""
    at_fixes = _get(m, "errors", "at_fixes", "prmse_m")
    return at_fixes if at_fixes is not None else m.get("prmse_m")


def _trust(metrics: dict, mid: str) -> str:
    """How far a method's stated sigma is to be trusted, in a few words: its position NEES (or
    NIS without truth), and its attitude NEES when that is outside its band."""
    text = _position_trust(metrics, mid)
    att = _get(metrics["methods"][mid], "errors", "nees_attitude")
    if att and att.get("band") and not att["band"][0] <= att["value"] <= att["band"][1]:
        size = "small" if att["value"] > att["band"][1] else "large"
        text += f"; its attitude sigma is too {size} (attitude NEES {att['value']:.3g})"
    return text


def _position_trust(metrics: dict, mid: str) -> str:
    m = metrics["methods"][mid]
    nees = _get(m, "errors", "nees_position")
    if nees and nees.get("band"):
        lo, hi = nees["band"]
        if nees["value"] > hi:
            return (
                f"stated position sigma is too small (NEES {nees['value']:.1f}, "
                f"band up to {hi:.1f})"
            )
        if nees["value"] < lo:
            return f"stated position sigma is too large (NEES {nees['value']:.2f})"
        return f"stated position sigma holds (NEES {nees['value']:.2f})"
    nis = _get(metrics, "consistency", mid, "nis", "pos")
    return (
        f"position NIS {nis:.2f} (1 = consistent)" if nis is not None else "no consistency figure"
    )


def verdict_line(metrics: dict) -> str | None:
    """The first-screen answer: which method, how good (against the raw fixes), how sure; or
    that no method beats the fixes. Methods within :data:`TIE` of the best are named with it.
    Without truth: accuracy cannot be scored; the method whose NIS is nearest 1 among those no
    NIS warning flags is named (with a caveat when every method is flagged)."""
    ok = ok_methods(metrics)
    if not ok:
        return None
    scored = {mid: _accuracy(m) for mid, m in ok.items() if _accuracy(m) is not None}
    fixes = metrics.get("gnss_prmse_m")
    if scored and fixes is not None:
        best = min(scored, key=scored.get)
        ties = [mid for mid, v in scored.items() if v <= scored[best] * (1 + TIE)]
        names = " and ".join([best] + [m for m in ties if m != best])
        equal = " (equal within 1 %)" if len(ties) > 1 else ""
        if scored[best] >= fixes:
            return (
                f"verdict: no method beats the raw fixes (best {names}: {scored[best]:.2f} m PRMSE "
                f"at the fixes' epochs, the fixes {fixes:.2f} m)"
            )
        return (
            f"verdict: {names}{equal} {'are' if equal else 'is'} most accurate: "
            f"{scored[best]:.2f} m PRMSE at the fixes' epochs, {fixes / scored[best]:.1f}x "
            f"better than the raw fixes ({fixes:.2f} m); "
            f"{best}'s {_trust(metrics, best)}"
        )
    nis = {
        mid: v
        for mid in ok
        if (v := _get(metrics, "consistency", mid, "nis", "pos")) is not None and v > 0
    }
    if not nis:
        return "verdict: no truth and no NIS: neither accuracy nor consistency can be told"
    # A mean NIS near 1 says little when a warning flags the innovations (correlated, out of band
    # most of the run): such a method is named only when every method is flagged, and then so said.
    flagged = {mid for mid in nis if "nis" in (_get(metrics, "consistency", mid, "flags") or [])}
    best = min(
        [mid for mid in nis if mid not in flagged] or list(nis),
        key=lambda mid: abs(math.log(nis[mid])),
    )
    caveat = "; but every method's NIS is flagged (see the warnings)" if best in flagged else ""
    return (
        f"verdict (no truth: accuracy cannot be scored): {best} is the most consistent "
        f"(position NIS {nis[best]:.2f}, 1 = consistent){caveat}"
    )


def _drop_empty(head: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """Without the columns (after the first) whose every cell is ``-``."""
    keep = [0] + [i for i in range(1, len(head)) if any(r[i] != "-" for r in rows)]
    return [head[i] for i in keep], [[r[i] for i in keep] for r in rows]


def table_rows(metrics: dict) -> tuple[list[str], list[list[str]]]:
    """The comparison table's header and rows (text cells), the raw fixes last; the failed
    methods are :func:`failed_methods`. A warned figure carries ``!`` in its own column: the NIS
    (innovations, noise model), ``PRMSE at fixes`` / ``fix residual`` (no better than the fixes),
    ``NEES pos`` / ``NEES att`` (position / attitude errors against the truth beyond the stated
    sigma; the attitude column where the truth has attitude)."""
    cols = _columns(metrics)
    head = [h for h, _ in cols]
    rows = [[mid] + [f(mid, m) for _, f in cols[1:]] for mid, m in ok_methods(metrics).items()]
    if metrics.get("gnss_prmse_m") is not None:
        rows.append(_fix_cells(metrics, head))
    return _drop_empty(head, rows) if rows else (head, rows)


def table_notes(metrics: dict) -> tuple[list[str], list[str]]:
    """The lines above the comparison table (the scored window) and below it (whose axes the
    attitude is of, when the vehicle's; the truth's gaps; the legend)."""
    return _window_lines(metrics), _axes_lines(metrics) + _truth_lines(metrics) + _legend(metrics)


def format_table(metrics: dict) -> str:
    """The comparison table printed by ``gnssacc run``, headed by the window it scores; a method
    that failed has a ``failed: <reason>`` row."""
    head, rows = table_rows(metrics)
    failed = failed_methods(metrics)
    lines = text_table(head, rows, max([0] + [len(mid) for mid in failed]))
    first = len(lines[1].split("  ")[0])
    # A failed row is not cut into columns: its reason runs on after the method id.
    failed_rows = [f"{mid.ljust(first)}  failed: {reason}" for mid, reason in failed.items()]
    verdict = verdict_line(metrics) if metrics.get("consistency") else None
    return "\n".join(
        ([verdict] if verdict else [])
        + _window_lines(metrics)
        + lines
        + failed_rows
        + _start_lines(metrics)
        + _axes_lines(metrics)
        + _truth_lines(metrics)
        + _legend(metrics)
    )


def _axes_lines(metrics: dict) -> list[str]:
    """Whose axes the attitude columns are of, and the least sigma of each angle, what no
    measurement tells of them (``metrics.json`` ``attitude_axes``:
    :func:`gnssacc.prepare.attitude_axes.attitude_axes`)."""
    axes = metrics.get("attitude_axes") or {}
    floor = axes.get("sigma_floor_deg") or {}
    resolved = axes.get("resolution_deg") or {}
    least = [f"{a} {v:.2f}" for a, v in floor.items() if v > 0.0 and a not in resolved]
    level = axes.get("level_deg")
    tilt = (
        "; roll and pitch: the tilt a vehicle that never showed its yaw cannot tell from its "
        f"horizontal accelerometer biases, {level['bias_mg'][1]:.3g} / {level['bias_mg'][0]:.3g} "
        "mg 1-sigma"
        if level
        else ""
    )
    unknown = (
        f"; unmeasured, each sigma at least {', '.join(least)} deg (the accelerometer triad's "
        f"turn against the IMU's case: {axes['misalignment_ppm']:.0f} ppm cross-axis, from "
        f"{axes['misalignment_from']}{tilt})"
        if least
        else ""
    )
    known = (
        "; the constraint's axes known to "
        + ", ".join(f"{a} {v:.2f}" for a, v in resolved.items())
        + " deg (the tuner's likelihood), each sigma at least that"
        if resolved
        else ""
    )
    if axes.get("axes") == "vehicle":
        return [
            f"attitude: of the vehicle's axes, the body's turned by pitch "
            f"{axes['pitch_offset_deg']:+.2f} deg, yaw {axes['yaw_offset_deg']:+.2f} deg "
            f"({', '.join(axes['set_by'])}: the constraint's axes){known}{unknown}; the biases "
            "stay in the body's"
        ]
    return [f"attitude: of the body's axes{known}{unknown}"] if known or unknown else []


def _truth_lines(metrics: dict) -> list[str]:
    """Why a recording's truth is not scored, when the input checks set it aside; and the gaps
    the scores interpolate it across, when it has any."""
    why = (metrics.get("input_corrections") or {}).get("truth_not_scored")
    if why:
        return [f"truth not scored: {why}"]
    cov = metrics.get("truth_coverage") or {}
    gaps = cov.get("gaps") or {}
    if not gaps.get("n") or metrics.get("gnss_prmse_m") is None:
        return []
    return [
        f"truth: sampled every {cov['interval_s']:.3g} s; {gaps['n']} gap(s) up to "
        f"{gaps['longest_s']:.1f} s, across which the scores interpolate it linearly"
    ]


def _start_lines(metrics: dict) -> list[str]:
    """What the estimates' yaw rests on, when nothing does: said in the table, not only in a log
    (the start's, and each method's along the run: :data:`YAW_UNDETERMINED_SIGMA_DEG`)."""
    start = metrics.get("start") or {}
    out = []
    if not start.get("yaw_determined", True):
        out.append(
            f"yaw undetermined (sigma {start['yaw_sigma_deg']:.0f} deg): "
            f"{start.get('why', 'the motion never told it')}; heading and attitude figures of "
            "every method rest on that guess"
        )
    return out + _trajectory_yaw_lines(metrics)


def _trajectory_yaw_lines(metrics: dict) -> list[str]:
    """The methods whose stated yaw sigma exceeds :data:`YAW_UNDETERMINED_SIGMA_DEG` somewhere."""
    parts = []
    for mid, m in ok_methods(metrics).items():
        ys = m.get("yaw_sigma") or {}
        if ys.get("undetermined_share", 0.0) > 0.0:
            parts.append(
                f"{mid} {100 * ys['undetermined_share']:.0f} % of epochs "
                f"(sigma {ys['end_deg']:.0f} deg at the end)"
            )
    if not parts:
        return []
    return [
        f"yaw undetermined (stated sigma > {YAW_UNDETERMINED_SIGMA_DEG:.0f} deg): "
        + ", ".join(parts)
        + "; their heading is a guess there"
    ]


def _window_lines(metrics: dict) -> list[str]:
    w = metrics.get("scored_window_s")
    if not w:
        return []
    t0 = metrics.get("t_start", 0.0)
    frac = (w[1] - w[0]) / metrics["duration_s"] if metrics["duration_s"] > 0 else 1.0
    n = {m["n_epochs"] for m in ok_methods(metrics).values()}
    what = "scored" if metrics.get("gnss_prmse_m") is not None else "compared (no truth)"
    return [
        f"{what} over t = {w[0] - t0:.1f} .. {w[1] - t0:.1f} s from the start ({100 * frac:.0f} % of the run), "
        f"every row: {'/'.join(str(x) for x in sorted(n))} epochs per method, "
        f"{metrics.get('gnss_n_epochs', '-')} raw fixes"
    ]


def _legend(metrics: dict) -> list[str]:
    if not metrics.get("consistency"):  # a table made by hand, not by a run
        return []
    head = table_rows(metrics)[0]
    out = []
    if "PRMSE at fixes [m]" in head:
        out.append(
            "PRMSE at fixes: each method at the raw fixes' epochs, like for like with the fixes' own row"
            + (
                " (fixes exist outside outages only: this is the no-outage figure)"
                if "outage PRMSE [m]" in head
                else ""
            )
            + "; CEP95: 95 % of the horizontal errors are below it"
        )
        out.append(
            "NEES pos"
            + (" / att" if "NEES att" in head else "")
            + ": mean (error / stated sigma)^2 per axis against the truth; 1 = consistent"
        )
    elif "fix residual [m]" in head:
        out.append(
            "no truth: accuracy cannot be scored; fix residual = RMS distance to the raw fixes (agreement "
            "with them, not accuracy), and the NIS"
        )
    out.append(
        "NIS: mean normalised innovation (EKF) or GNSS residual (smoother) squared per dof; "
        "1 = consistent; '!' = the figure a warning is about"
    )
    return out


def group_warnings(items: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """``(method, text)`` warnings folded into fewer lines: warnings that differ only in their
    numbers become one ``("m1, m2", text)`` whose differing numbers name their methods,
    ``"a (m1) / b (m2)"``.

    Returns
    -------
    list of (str, str)
        ``(methods, text)`` in the order each group first appeared.
    """
    import re

    num = re.compile(r"-?\d+(?:\.\d+)?")
    groups: dict[str, list[tuple[str, str]]] = {}
    for mid, text in items:
        groups.setdefault(num.sub("#", text), []).append((mid, text))
    out = []
    for key, members in groups.items():
        values = [num.findall(text) for _, text in members]
        mids = [m for m, _ in members]
        slots = iter([_whose([v[i] for v in values], mids) for i in range(len(values[0]))])
        parts = key.split("#")
        text = "".join(p + (next(slots) if i < len(parts) - 1 else "") for i, p in enumerate(parts))
        out.append((", ".join(dict.fromkeys(m for m, _ in members)), text))
    return out


def _whose(values: list[str], mids: list[str]) -> str:
    """One number of a grouped warning: itself when every method has it, else each value with
    the methods it is of, ``"3.10 (ekf) / 3.40 (ekf-acc)"``."""
    by: dict[str, list[str]] = {}
    for v, m in zip(values, mids, strict=True):
        by.setdefault(v, []).append(m)
    if len(by) == 1:
        return values[0]
    return " / ".join(f"{v} ({', '.join(dict.fromkeys(ms))})" for v, ms in by.items())


#: Actions of an input-check finding (:class:`gnssacc.checks.findings.Finding`) that changed
#: the run.
APPLIED = ("applied", "repaired")
#: ... and those that left the data as given after the estimator's verdict.
NOT_APPLIED = ("refuted", "not confirmed")


def _gain_text(finding: dict) -> str:
    """The estimator's evidence in a few words, e.g. "log-likelihood +18606 over 963 fixes"."""
    v = (finding.get("details") or {}).get("verdict") or {}
    gain = v.get("loglik_gain")
    if isinstance(gain, str) or gain is None:  # "inf": as given nothing could be estimated
        return "the data as given cannot be estimated"
    return f"log-likelihood {gain:+.0f} over {v.get('n_fixes', 0)} fixes"


def applied_corrections(checks: list[dict]) -> list[str]:
    """One short text per correction the input checks applied (``metrics.json``'s ``input_checks``
    entries), with the estimator's evidence."""
    return [
        f"{c.get('correction') or c['check']} ({_gain_text(c)})"
        for c in checks
        if c.get("action") in APPLIED
    ]


def header_line(header: str | None, checks: list[dict]) -> str | None:
    """The run's header line (``header``: what the run is) with the corrections the estimator
    proved and the input checks applied; ``None`` when there is neither."""
    applied = applied_corrections(checks)
    tail = "corrected, as the estimator proves: " + "; ".join(applied) if applied else ""
    if header is None:
        return tail or None
    return f"{header}; {tail}" if tail else header


def corrections_summary(checks: list[dict], on_proof: str) -> dict:
    """``metrics.json``'s ``input_corrections``: the policy, the corrections applied and the
    proposals tested and left (refuted, or not decided), each with its evidence."""

    def entry(c: dict) -> dict:
        d = c.get("details") or {}
        return {
            "check": c["check"],
            "proposal": c["problem"],
            "correction": c.get("correction", ""),
            "verdict": c["action"],
            "evidence": d.get("evidence", ""),
        }

    return {
        "on_proof": on_proof,
        "applied": [entry(c) for c in checks if c.get("action") in APPLIED],
        "not_applied": [entry(c) for c in checks if c.get("action") in NOT_APPLIED],
        "truth_not_scored": next(
            (c["problem"] for c in checks if c.get("action") == "not scored"), None
        ),
        "clock": next(
            ({"text": c["problem"], **c["details"]} for c in checks if c.get("action") == "bound"),
            None,
        ),
    }


def clock_line(checks: list[dict]) -> str | None:
    """What the run says about its IMU-to-GNSS clock offset (how large one could go unseen)."""
    bound = next((c for c in checks if c.get("action") == "bound"), None)
    return f"clock: {bound['problem']}" if bound else None


def quality_line(quality: dict) -> str:
    """One line of the IMU data-quality findings (a :class:`gnssacc.checks.quality.QualityReport`
    as a dict: its suspect ``spans`` by kind, with their total length)."""
    spans = quality.get("spans", [])
    if not spans:
        return "IMU data quality: no suspect spans"
    kinds: dict[str, list] = {}
    for s in spans:
        kinds.setdefault(s["kind"], []).append(s)
    parts = [
        f"{len(v)} {k} ({sum(s['t_end'] - s['t_start'] for s in v):.1f} s)"
        for k, v in kinds.items()
    ]
    return "IMU data quality: " + ", ".join(parts) + " - process noise inflated over these spans"
