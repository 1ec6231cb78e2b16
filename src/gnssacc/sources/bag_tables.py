"""Decoded bag rows as gnssacc's objects (fixes, truth, wheel odometry), and which of the candidate
topics is the truth and which the wheel odometry.

The rule (:func:`choose`): a truth candidate (a pose topic, or a fix topic beside the GNSS) is the
truth only when its frame is not a local odometry frame and its positions, as given, agree with
the fixes (:mod:`gnssacc.sources.truth_check`); a rejected one is named in one warning line with
the measured disagreement. ``--truth-topic`` forces a choice: it is checked the same way and warned
about, never refused. The wheel odometry is the Odometry / TwistStamped topic left once the truth
is decided (or the one ``--odom-topic`` names).

Frames: pose positions are ENU about the pose frame's origin (``truth_origin_llh_deg``, else the
first GNSS fix: an assumption the agreement check then tests); twists are in the body's FLU axes
(REP-103): the forward speed is ``linear.x`` and the yaw rate about the body's down axis is
``-angular.z``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.config import DEG
from ..core.earth import LocalTangentFrame
from ..core.errors import InputError, warn_data
from ..core.recording import GnssFixes, Truth, WheelOdometry, drop_nonfinite
from .bag_decode import ODOMETRY_TYPE, POSE_COLS, Collector
from .bag_times import sorted_unique
from .common import check_degrees
from .truth_check import agreement, is_local_frame


def clean_rows(
    col: Collector, n_needed: int, where: str, what: str, max_bad: float, meta: dict, key: str
) -> np.ndarray:
    """The rows of ``col`` whose first ``n_needed`` columns are finite (the others dropped with a
    warning, or an error above ``max_bad``), sorted by time without repeated stamps."""
    tab = col.table()
    if len(tab) == 0:
        raise InputError(where, f"{what}: no messages")
    keep = np.all(np.isfinite(tab[:, :n_needed]), axis=1)
    if not keep.all():
        drop_nonfinite(tab[:, :n_needed], where, what, max_bad)  # warns with the count, or raises
        tab = tab[keep]
    return sorted_unique(tab, where, what, meta, key)


def fix_table(
    col: Collector, where: str, what: str, max_bad: float, meta: dict, key: str
) -> np.ndarray:
    """Fix rows (t [s], lat [deg], lon [deg], h [m], sigma NED [m]): counted, checked, sorted."""
    label = f"{what} topic {col.topic}"
    tab = col.table()
    if col.skipped_no_fix:
        if len(tab) == 0:
            raise InputError(
                where,
                f"{label}: all {col.skipped_no_fix} messages are NO_FIX (status -1); no usable fix",
            )
        warn_data(where, f"{label}: skipped {col.skipped_no_fix} NO_FIX message(s)")
    if col.zero_cov:
        warn_data(
            where,
            f"{label}: {col.zero_cov} message(s) with an all-zero covariance; "
            f"used gnss.default_sigma_m instead",
        )
    meta.setdefault("fix_counts", {})[key] = {
        "messages": col.total,
        "no_fix": col.skipped_no_fix,
        "zero_covariance": col.zero_cov,
    }
    if len(tab) == 0:
        raise InputError(where, f"{label}: no messages")
    tab = drop_nonfinite(tab, where, label, max_bad)
    if len(tab) == 0:
        raise InputError(where, f"{label}: no usable fix")
    tab = sorted_unique(tab, where, label, meta, key)
    check_degrees(tab[:, 1], tab[:, 2], tab[:, 0], where, label)
    return tab


def fixes_of(tab: np.ndarray) -> GnssFixes:
    """Fix rows -> :class:`GnssFixes` (radians)."""
    return GnssFixes(tab[:, 0], tab[:, 1] * DEG, tab[:, 2] * DEG, tab[:, 3], tab[:, 4:7])


def pose_origin(origin: LocalTangentFrame, truth_origin_llh_deg) -> tuple[LocalTangentFrame, str]:
    """The origin of pose frames: ``truth_origin_llh_deg`` [deg, deg, m], else ``origin``; and how it was decided."""
    if truth_origin_llh_deg is None:
        return origin, "assumed: the pose frame is ENU with origin at the first GNSS fix"
    lat0, lon0, h0 = (float(v) for v in truth_origin_llh_deg)
    return LocalTangentFrame(lat0 * DEG, lon0 * DEG, h0), f"given: {lat0}, {lon0} deg, {h0} m"


def pose_truth(
    col: Collector, porigin: LocalTangentFrame, where: str, max_bad: float, meta: dict
) -> Truth:
    """Truth from pose rows (NED about the pose frame's origin ``porigin``)."""
    ptab = clean_rows(col, 4, where, f"truth topic {col.topic}", max_bad, meta, "truth")
    lat, lon, h = porigin.to_llh(ptab[:, 1:4])
    v_n = ptab[:, 4:7] if np.all(np.isfinite(ptab[:, 4:7])) else None
    rpy = ptab[:, 7:10] if np.all(np.isfinite(ptab[:, 7:10])) else None
    return Truth(ptab[:, 0], lat, lon, h, v_n, rpy)


def odometry_of(
    col: Collector, msgtype: str, where: str, max_bad: float, meta: dict
) -> WheelOdometry | None:
    """Wheel odometry from Odometry or TwistStamped rows (forward speed ``linear.x``, yaw rate
    ``-angular.z``, sigmas from the twist covariance when every message states one); None when the
    twist never moves (a pose-only topic)."""
    first = POSE_COLS if msgtype == ODOMETRY_TYPE else 1
    tab = col.table()
    if len(tab) == 0:
        return None
    twist = np.column_stack([tab[:, 0], tab[:, first : first + 6]])
    twist = clean_rows_of(twist, col.topic, where, max_bad, meta)
    v, w = twist[:, 1], -twist[:, 4]
    if len(v) < 2 or not (np.any(v != 0) or np.any(w != 0)):
        return None
    var_v, var_w = twist[:, 5], twist[:, 6]
    sig_v = np.sqrt(var_v) if np.all(np.isfinite(var_v)) else None
    sig_w = np.sqrt(var_w) if np.all(np.isfinite(var_w)) else None
    frame = col.child_frame_id or col.frame_id
    return WheelOdometry(
        twist[:, 0].copy(),
        v.copy(),
        w.copy(),
        sig_v,
        sig_w,
        frame=f"{col.topic} ({frame})" if frame else col.topic,
    )


def clean_rows_of(
    tab: np.ndarray, topic: str, where: str, max_bad: float, meta: dict
) -> np.ndarray:
    """Twist rows ``(t, v x, y, z, omega z, var v, var omega)`` with finite speeds, sorted."""
    keep = np.all(np.isfinite(tab[:, :5]), axis=1)
    if not keep.all():
        drop_nonfinite(tab[:, :5], where, f"odometry topic {topic}", max_bad)
        tab = tab[keep]
    return sorted_unique(tab, where, f"odometry topic {topic}", meta, "odometry")


@dataclass
class Chosen:
    """What :func:`choose` decided."""

    truth: Truth | None
    truth_topic: str | None
    odometry: WheelOdometry | None
    odometry_topic: str | None
    reasons: list = field(default_factory=list)
    checks: dict = field(default_factory=dict)  # topic -> {"n", "rms_m", "ratio", "ok", "frame"}


@dataclass
class Context:
    """What the choice needs besides the decoded topics."""

    where: str
    gnss: GnssFixes
    origin: LocalTangentFrame
    truth_origin_llh_deg: object
    lever_m: float
    max_bad: float
    meta: dict


def choose(sel, dec, ctx: Context, given_truth: Truth | None) -> Chosen:
    """The truth (checked candidates, or the given one checked and only warned about) and the wheel
    odometry of a bag (module notes). ``given_truth``: the truth already made from ``sel.truth``."""
    out = Chosen(given_truth, sel.truth.topic if sel.truth is not None else None, None, None)
    if sel.truth is not None and sel.gnss is not None:  # --truth-topic: checked, never refused
        verdict = _verdict(sel.truth, sel.truth_kind, dec, ctx, given_truth)
        out.checks[sel.truth.topic] = verdict
        if not verdict["ok"]:
            warn_data(
                ctx.where,
                f"--truth-topic {sel.truth.topic} used as truth although {verdict['why']}",
            )
    accepted = []
    for stat, kind in sel.truth_candidates:
        truth = _candidate_truth(stat, kind, dec, ctx)
        verdict = _verdict(stat, kind, dec, ctx, truth)
        out.checks[stat.topic] = verdict
        if verdict["ok"]:
            accepted.append((stat, truth, verdict))
        else:
            warn_data(ctx.where, f"{stat.topic} is not taken as truth: {verdict['why']}")
            out.reasons.append(f"not truth {stat.topic}: {verdict['why']}")
    if len(accepted) == 1:
        stat, out.truth, verdict = accepted[0]
        out.truth_topic = stat.topic
        out.reasons.append(
            f"truth {stat.topic}: geo-referenced and agrees with the fixes ({verdict['why']})"
        )
    elif len(accepted) > 1:
        names = ", ".join(a[0].topic for a in accepted)
        warn_data(
            ctx.where,
            f"no truth: several topics agree with the fixes ({names}); pick one with --truth-topic",
        )
        out.reasons.append(
            f"no truth: several topics agree with the fixes ({names}); pick one with --truth-topic"
        )
    elif sel.truth_candidates:
        out.reasons.append("no truth: no candidate is geo-referenced and agrees with the fixes")
    _choose_odometry(sel, dec, ctx, out)
    return out


def _candidate_truth(stat, kind: str, dec, ctx: Context) -> Truth | None:
    """A candidate as a :class:`Truth` (None for a pose in a local odometry frame: not looked at)."""
    col = dec.cols[stat.topic]
    if kind == "fix":
        rows = fix_table(col, ctx.where, "truth", ctx.max_bad, {}, "truth")
        return Truth(rows[:, 0], rows[:, 1] * DEG, rows[:, 2] * DEG, rows[:, 3])
    if is_local_frame(col.frame_id):
        return None
    return pose_truth(
        col, pose_origin(ctx.origin, ctx.truth_origin_llh_deg)[0], ctx.where, ctx.max_bad, {}
    )


def _verdict(stat, kind: str, dec, ctx: Context, truth: Truth | None) -> dict:
    """``{"ok", "why", "frame", "n", "rms_m", "ratio"}`` of one candidate."""
    frame = dec.cols[stat.topic].frame_id if kind == "pose" else "geodetic"
    if kind == "pose" and is_local_frame(frame):
        return {
            "ok": False,
            "frame": frame,
            "n": 0,
            "rms_m": None,
            "ratio": None,
            "why": f"its pose is in the local frame {frame!r} (REP-105 odometry: not geo-referenced)",
        }
    g, o = ctx.gnss, ctx.origin
    a = agreement(
        truth.t,
        o.to_ned(truth.lat, truth.lon, truth.h),
        g.t,
        o.to_ned(g.lat, g.lon, g.h),
        g.sigma_ned,
        ctx.lever_m,
    )
    where_from = (
        f"frame {frame!r} read as ENU about the {'given origin' if ctx.truth_origin_llh_deg else 'first fix'}"
        if kind == "pose"
        else "a fix topic"
    )
    why = f"{a.describe()}; {where_from}"
    if not a.ok and a.n >= 5:
        why = f"its positions disagree with the fixes: {why}"
    finite = {
        k: (float(v) if np.isfinite(v) else None)
        for k, v in (("rms_m", a.rms_m), ("ratio", a.ratio))
    }
    return {"ok": a.ok, "frame": frame, "n": a.n, **finite, "why": why}


def _choose_odometry(sel, dec, ctx: Context, out: Chosen) -> None:
    """The given odometry topic, or the only candidate (not the truth) whose twist moves."""
    types = {
        s.topic: s.msgtype for s in ([sel.odom] if sel.odom else []) + list(sel.odom_candidates)
    }
    if sel.odom is not None:
        names = [sel.odom.topic]
    else:
        names = [s.topic for s in sel.odom_candidates if s.topic != out.truth_topic]
    found = []
    for topic in names:
        odo = odometry_of(dec.cols[topic], types[topic], ctx.where, ctx.max_bad, ctx.meta)
        if odo is None:
            if sel.odom is not None:
                raise InputError(
                    ctx.where,
                    f"--odom-topic {topic}: its twist is zero throughout (no speed to use)",
                )
            out.reasons.append(f"not wheel odometry {topic}: its twist is zero throughout")
            continue
        found.append((topic, odo))
    if len(found) == 1:
        out.odometry_topic, out.odometry = found[0]
        if sel.odom is None:
            out.reasons.append(
                f"wheel odometry {found[0][0]}: the only Odometry/TwistStamped topic with a moving "
                f"twist that is not the truth"
            )
    elif len(found) > 1:
        out.reasons.append(
            "no wheel odometry: several topics ("
            + ", ".join(t for t, _ in found)
            + "); pick one with --odom-topic"
        )
