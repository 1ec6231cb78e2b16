"""ROS bags as a run source: ROS 1 ``.bag``, ROS 2 directories (sqlite3 or MCAP) and bare ``.mcap``.

Everything is read through :class:`rosbags.highlevel.AnyReader`, with the message definitions
taken from the bag itself, so custom message types decode without a ROS installation.

Topics
    IMU: ``sensor_msgs/msg/Imu``. GNSS: ``sensor_msgs/msg/NavSatFix`` or a custom fix type with
    a field mapping (:data:`FIX_MAPPINGS`, shipped for the ROOAD ``ubxtranslator/hpposllh``).
    Truth (optional): ``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseStamped``,
    ``geometry_msgs/msg/PoseWithCovarianceStamped`` or a second fix topic (e.g. an RTK receiver),
    taken only when geo-referenced and agreeing with the fixes (:mod:`.bag_tables`,
    :mod:`.truth_check`): a drive controller's Odometry in its ``odom`` frame is never the truth.
    Wheel odometry (optional): the ``nav_msgs/msg/Odometry`` or ``geometry_msgs/msg/TwistStamped``
    topic left after the truth (``linear.x`` forward, ``-angular.z`` the yaw rate about the body's
    down axis), as ``run.odometry``, on the IMU's clock.
    GNSS velocity (optional): a ``geometry_msgs/msg/TwistWithCovarianceStamped`` or
    ``TwistStamped`` topic in ENU beside the fixes, told apart from wheel odometry by its frame,
    its stamps at the fix epochs and its agreement with the fixes' differences
    (:mod:`.bag_velocity`), as ``run.gnss_vel`` on the fixes' clock.
    Topics are picked by type and rate when unambiguous (see :func:`select_topics`); otherwise
    an :class:`~gnssacc.core.errors.InputError` lists the candidates and the argument that picks one.

Frames (ROS REP-103 -> gnssacc)
    IMU samples are body Front-Left-Up and converted to Front-Right-Down ``(x, -y, -z)`` before
    the ``[mounting]`` rotation. Pose positions and orientations are in a local East-North-Up
    frame: ``(e, n, u) -> (n, e, -u)`` and ``R_nb = T_ned_enu @ R_enu_flu @ T_flu_frd``.
    ASSUMPTION for pose truth: the pose frame is ENU with its origin at the first GNSS fix,
    unless ``truth_origin_llh_deg`` says otherwise; the agreement check tests it.

Times
    Header stamps by default (the bag receive time for header-less types such as hpposllh);
    ``time_source="receive"`` uses the receive time of every message. Out-of-order messages are
    sorted (counted, warned), exact duplicates dropped (counted, warned), gaps listed in
    ``run.meta["gaps"]``.

Only the chosen connections are read (``reader.messages(connections=...)``): image and other
topics are skipped without being decoded, and memory is bounded by the IMU/GNSS data.

Modules
    This module composes the others into a :class:`~gnssacc.core.recording.RecordedRun` (frames, units,
    origin, initial state) and re-exports their public names: :mod:`.bag_files` (bag paths and
    opening), :mod:`.bag_salvage` (damaged ROS 1 bags), :mod:`.bag_topics` (survey and topic
    selection), :mod:`.bag_decode` (messages to rows, fix mappings, ``/tf_static``) and
    :mod:`.bag_times` (time-stamp repair and gaps).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.config import DEG, RunConfig
from ..core.earth import LocalTangentFrame
from ..core.errors import InputError, warn_data
from ..core.memory import release_free_memory
from ..core.recording import GnssFixes, ImuData, InitialState, RecordedRun, Truth
from ..core.rotations import FLU_FRD, dcm_to_euler, quaternion_to_dcm, ros_to_R_nb
from .bag_decode import (
    FIX_MAPPINGS,
    TIME_SOURCES,
    Collector,
    Decoded,
    RowDecoder,
    decode_topics,
    merge_fix_mappings,
    normalize_type,
    tf_mounting,
)
from .bag_files import MAGIC, STORAGE_SUFFIXES, check_bag_path, open_reader, storage_files
from .bag_tables import Context, choose, clean_rows, fix_table, fixes_of, pose_origin, pose_truth
from .bag_times import find_gaps, subsample
from .bag_topics import Selection, TopicStat, select_topics, survey
from .bag_velocity import VelocityChoice, choose_velocity
from .common import apply_mounting, configured_time_offset_s, one_line, with_noisy_fixes

# The bag source's public names, wherever they are defined.
__all__ = [
    "FIX_MAPPINGS",
    "MAGIC",
    "STORAGE_SUFFIXES",
    "Selection",
    "TopicStat",
    "check_bag_path",
    "enu_flu_to_ned_frd",
    "inspect_bag",
    "load_bag_run",
    "normalize_type",
    "select_topics",
    "storage_files",
]

#: Initial-state sigmas when the IMU orientation has no (valid) covariance.
INIT_SIGMA_ROLL_PITCH_DEG = 1.0
INIT_SIGMA_YAW_DEG = 5.0
INIT_VEL_FIT_S = 3.0

enu_flu_to_ned_frd = ros_to_R_nb  # name kept for callers of this module


def load_bag_run(
    path,
    cfg: RunConfig,
    *,
    imu_topic: str | None = None,
    gnss_topic: str | None = None,
    truth_topic: str | None = None,
    time_source: str = "header",
    gnss_from_truth_hz: float | None = None,
    noise: str | None = None,
    seed: int = 0,
    fix_mappings: dict | None = None,
    truth_origin_llh_deg=None,
    odom_topic: str | None = None,
) -> RecordedRun:
    """Load a ROS 1 / ROS 2 bag as a :class:`RecordedRun`.

    Parameters
    ----------
    path : str or Path
        A ``.bag`` file, a ROS 2 bag directory (sqlite3 or MCAP storage) or a bare ``.mcap``.
    cfg : RunConfig
        Uses ``[mounting]``, ``gnss.default_sigma_m``, ``data.max_bad_fraction`` and ``[bag] fix_mappings``.
    imu_topic, gnss_topic, truth_topic, odom_topic : str, optional
        Topic choices; by default picked by :func:`select_topics` (the truth and the wheel
        odometry then decided from the data: :func:`gnssacc.sources.bag_tables.choose`).
    time_source : {"header", "receive"}
        Header stamps (receive time for header-less types) or bag receive times.
    gnss_from_truth_hz : float, optional
        Make the estimators' GNSS from the truth fix topic, subsampled at this rate [Hz], with
        the noise profile ``noise`` (default ``white``) and ``seed``; the truth stays the truth.
    noise : str, optional
        With ``gnss_from_truth_hz`` only.
    seed : int
    fix_mappings : dict, optional
        Extra or replacement field mappings of custom fix types (see :data:`FIX_MAPPINGS`).
    truth_origin_llh_deg : (lat, lon, h), optional
        Origin of the ENU frame of pose/odometry truth [deg, deg, m]; default: the first GNSS fix.

    Returns
    -------
    RecordedRun
        Validated; ``name`` the file stem, ``where`` the path, ``origin`` at the first fix.
        IMU in body FRD [m/s^2, rad/s]; ``init`` is set when the IMU messages carry a valid
        orientation (REP-145).
    """
    path = Path(path)
    where = str(path)
    _check_options(where, time_source, noise, gnss_from_truth_hz)
    mappings = merge_fix_mappings(
        cfg["bag"]["fix_mappings"] if fix_mappings is None else fix_mappings
    )
    decoder = RowDecoder(mappings, time_source, cfg.default_sigma_ned, where)
    max_bad = float(cfg["data"]["max_bad_fraction"])
    meta: dict = {"source": "bag", "time_source": time_source}
    sel, dec, tf = _read(
        path,
        cfg,
        decoder,
        meta,
        imu_topic=imu_topic,
        gnss_topic=gnss_topic,
        truth_topic=truth_topic,
        gnss_from_truth=gnss_from_truth_hz is not None,
        odom_topic=odom_topic,
    )

    itab, imu, R_bi_total = _imu(dec.cols[sel.imu.topic], tf, cfg, where, max_bad, meta)
    gnss, origin, truth = _fixes_and_truth(
        sel, dec, imu, cfg, where, meta, gnss_from_truth_hz, noise, seed, truth_origin_llh_deg
    )
    vel, chosen = _velocity_and_choices(
        sel,
        dec,
        Context(
            where,
            gnss,
            origin,
            truth_origin_llh_deg,
            float(np.linalg.norm(cfg.lever_arm_b)),
            max_bad,
            meta,
        ),
        truth,
        cfg.default_velocity_sigma,
    )
    odometry = (
        None if chosen.odometry is None else chosen.odometry.shifted(configured_time_offset_s(cfg))
    )
    good_q = np.isfinite(itab[:, 7:11]).all(axis=1)
    init = (
        _initial_state(itab, good_q, imu, gnss, R_bi_total, sel.imu.topic) if good_q.any() else None
    )
    run = RecordedRun(
        name=path.stem if path.is_file() else path.name,
        where=where,
        imu=imu,
        gnss=gnss,
        origin=origin,
        truth=chosen.truth,
        init=init,
        meta=meta,
        odometry=odometry,
        gnss_vel=vel.velocity,
    )
    release_free_memory()  # the decoded message columns
    return run.validate()


def _fixes_and_truth(
    sel: Selection,
    dec: Decoded,
    imu: ImuData,
    cfg: RunConfig,
    where: str,
    meta: dict,
    gnss_from_truth_hz,
    noise: str | None,
    seed: int,
    truth_origin_llh_deg,
):
    """(fixes, origin at the first fix, truth or None) of the selected topics: the GNSS fix topic,
    or fixes made from a fix-type truth with ``noise`` at ``gnss_from_truth_hz`` [Hz]; a pose
    truth in the ENU frame at ``truth_origin_llh_deg`` (default: the first fix)."""
    max_bad = float(cfg["data"]["max_bad_fraction"])
    truth = None
    if sel.truth is not None and sel.truth_kind == "fix":
        rows = fix_table(dec.cols[sel.truth.topic], where, "truth", max_bad, meta, "truth")
        truth = Truth(rows[:, 0], rows[:, 1] * DEG, rows[:, 2] * DEG, rows[:, 3])
    if sel.gnss is not None:
        gnss = fixes_of(fix_table(dec.cols[sel.gnss.topic], where, "GNSS", max_bad, meta, "gnss"))
        origin = LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0])
    else:
        gnss, origin = _gnss_from_truth(
            truth, imu, where, float(gnss_from_truth_hz), noise or "white", seed, meta
        )
    meta["gaps"]["gnss"] = find_gaps(gnss.t, float(cfg["quality"]["gap_factor"]))
    if sel.truth is not None and sel.truth_kind == "pose":
        porigin, meta["truth_origin"] = pose_origin(origin, truth_origin_llh_deg)
        truth = pose_truth(dec.cols[sel.truth.topic], porigin, where, max_bad, meta)
    return gnss, origin, truth


def _velocity_and_choices(
    sel: Selection, dec: Decoded, ctx: Context, truth, velocity_sigma
) -> tuple[VelocityChoice, object]:
    """The receiver's velocity topic (only with the bag's own fixes) and the truth and odometry
    decided from the data (:func:`gnssacc.sources.bag_tables.choose`), recorded into the
    context's ``meta``: ``(velocity, chosen)``."""
    vel = VelocityChoice()
    if sel.gnss is not None:  # a receiver's velocity belongs with its own fixes only
        vel = choose_velocity(
            sel.vel_candidates, dec, ctx.gnss, ctx.origin, ctx.where, velocity_sigma
        )
        sel = replace(sel, odom_candidates=[s for s in sel.odom_candidates if s.topic != vel.topic])
    chosen = choose(sel, dec, ctx, truth)
    _record_choice(chosen, sel, ctx.meta, ctx.truth_origin_llh_deg, ctx.origin)
    if vel.topic:
        ctx.meta["topics"]["gnss_velocity"] = vel.topic
    ctx.meta["selection"] += vel.reasons
    return vel, chosen


def _record_choice(chosen, sel: Selection, meta: dict, truth_origin_llh_deg, origin) -> None:
    """The truth and odometry decided, their reasons and checks, into ``meta``."""
    meta["topics"].update(truth=chosen.truth_topic, odometry=chosen.odometry_topic)
    meta["selection"] = list(sel.reasons) + list(chosen.reasons)
    if chosen.checks:
        meta["truth_checks"] = chosen.checks
    if (
        chosen.truth_topic is not None
        and sel.truth_kind != "fix"
        and "truth_origin" not in meta
        and any(s.topic == chosen.truth_topic and k == "pose" for s, k in sel.truth_candidates)
    ):
        meta["truth_origin"] = pose_origin(origin, truth_origin_llh_deg)[1]
    if chosen.odometry is not None:
        meta["odometry_frame"] = chosen.odometry.frame


def _check_options(where: str, time_source: str, noise: str | None, gnss_from_truth_hz) -> None:
    """:class:`InputError` for a time source, noise or ``--gnss-from-truth`` rate [Hz] that cannot be used."""
    if time_source not in TIME_SOURCES:
        raise InputError(
            where, f"time_source must be one of {', '.join(TIME_SOURCES)}, got {time_source!r}"
        )
    if noise is not None and gnss_from_truth_hz is None:
        raise InputError(
            where,
            "--noise on a bag needs --gnss-from-truth RATE_HZ (without it the bag's own "
            "fixes are used as they are)",
        )
    if gnss_from_truth_hz is not None and not float(gnss_from_truth_hz) > 0:
        raise InputError(
            where, f"--gnss-from-truth must be a positive rate in Hz, got {gnss_from_truth_hz}"
        )


def _read(path: Path, cfg: RunConfig, decoder: RowDecoder, meta: dict, **choices) -> tuple:
    """Open the bag, pick the topics (``choices``: see :func:`select_topics`), decode them and
    look for the IMU mounting on ``/tf_static``: (Selection, Decoded, (R_bi, what) or None)."""
    where = decoder.where
    reader = open_reader(path)
    try:
        meta["bag_format"] = "ros2" if reader.is2 else "ros1"
        if getattr(reader, "damaged", None):
            meta["damaged"] = (
                f"{reader.damaged}; salvaged {reader.good_bytes} of {reader.file_bytes} bytes"
            )
        sel = select_topics(survey(reader), where, mappings=decoder.mappings, **choices)
        meta["topics"] = {
            "imu": sel.imu.topic,
            "gnss": sel.gnss.topic if sel.gnss else None,
            "truth": sel.truth.topic if sel.truth else None,
        }
        meta["selection"] = sel.reasons
        dec = decode_topics(reader, chosen_topics(sel), decoder)
        _check_damage(dec, where, meta)
        tf = None
        if not np.any(cfg.imu_to_body_rpy_deg):  # a configured mounting wins over /tf_static
            try:
                tf = tf_mounting(reader, dec.imu_frame_id)
            except Exception as err:
                warn_data(
                    where,
                    f"/tf_static could not be read ({one_line(err)}); IMU mounting from the config",
                )
    finally:
        reader.close()
    return sel, dec, tf


def chosen_topics(sel: Selection, with_imu: bool = True) -> dict[str, str]:
    """Topic -> type of every topic the selection needs decoded (the IMU, the GNSS, the truth and
    its candidates, the odometry and its candidates)."""
    stats = [sel.imu if with_imu else None, sel.gnss, sel.truth, sel.odom]
    stats += [s for s, _ in sel.truth_candidates] + list(sel.odom_candidates)
    stats += list(sel.vel_candidates)
    return {s.topic: s.msgtype for s in stats if s is not None}


def _check_damage(dec: Decoded, where: str, meta: dict) -> None:
    """A bag that broke off while reading: the messages before the damage, with a warning."""
    if dec.damaged is None:
        return
    n = sum(len(c) for c in dec.cols.values())
    if not n:
        raise InputError(where, f"cannot read the bag (truncated or corrupt?): {dec.damaged}")
    warn_data(
        where, f"the bag is damaged ({dec.damaged}); using the {n} messages read before the damage"
    )
    meta["damaged"] = dec.damaged


def _imu(col: Collector, tf, cfg: RunConfig, where: str, max_bad: float, meta: dict):
    """IMU rows -> (sorted rows, ImuData in body FRD, R_bi of the IMU axes incl. /tf_static).

    The FLU samples are turned FRD, rotated by the ``/tf_static`` mounting if there is one, then
    by ``[mounting]`` (:func:`~gnssacc.sources.common.apply_mounting`).
    """
    what = f"IMU topic {col.topic}"
    itab = clean_rows(col, 7, where, what, max_bad, meta, "imu")
    if len(itab) < 2:
        raise InputError(where, f"{what}: {len(itab)} usable message(s), need at least two")
    f_imu = itab[:, 1:4] @ FLU_FRD  # FLU -> FRD (diagonal: same as T @ x per row)
    w_imu = itab[:, 4:7] @ FLU_FRD
    if tf is not None:
        R_bi_tf, what_tf = tf
        f_imu, w_imu = f_imu @ R_bi_tf.T, w_imu @ R_bi_tf.T
        meta["imu_mounting"] = {
            "from": what_tf,
            "imu_to_body_rpy_deg": [float(np.degrees(a)) for a in dcm_to_euler(R_bi_tf)],
        }
        R_bi_total = cfg.R_bi @ R_bi_tf
    else:
        meta["imu_mounting"] = {
            "from": "config [mounting] imu_to_body_rpy_deg",
            "imu_to_body_rpy_deg": [float(v) for v in cfg.imu_to_body_rpy_deg],
        }
        R_bi_total = cfg.R_bi
    imu = apply_mounting(ImuData(itab[:, 0].copy(), f_imu, w_imu), cfg)
    meta["gaps"] = {"imu": find_gaps(imu.t, float(cfg["quality"]["gap_factor"]))}
    return itab, imu, R_bi_total


def _gnss_from_truth(
    truth: Truth, imu: ImuData, where: str, rate_hz: float, noise: str, seed: int, meta: dict
):
    """(fixes, origin): the truth subsampled at ``rate_hz`` [Hz] plus ``noise``; origin at the first truth point."""
    origin = LocalTangentFrame(truth.lat[0], truth.lon[0], truth.h[0])
    sub = subsample(truth.t, rate_hz)
    sub_truth = Truth(truth.t[sub], truth.lat[sub], truth.lon[sub], truth.h[sub])
    holder = RecordedRun(
        "tmp", where, imu, GnssFixes(*(np.empty(0),) * 4, np.empty((0, 3))), origin
    )
    gnss = with_noisy_fixes(holder, sub_truth, noise, seed).gnss
    meta.update(gnss_from_truth_hz=rate_hz, noise=noise, seed=seed)
    return gnss, origin


def _initial_state(
    itab: np.ndarray,
    good_q: np.ndarray,
    imu: ImuData,
    gnss: GnssFixes,
    R_bi: np.ndarray,
    topic: str,
) -> InitialState | None:
    """Initial state from the IMU orientation (ENU <- IMU FLU, rows of ``itab`` where ``good_q``)
    nearest the first fix inside the IMU span, and a line fitted to the fixes of the next
    :data:`INIT_VEL_FIT_S` seconds; None without a fix inside the IMU span. ``R_bi``: IMU FRD
    axes to body FRD axes."""
    inside = np.flatnonzero((gnss.t >= imu.t[0]) & (gnss.t <= imu.t[-1]))
    if inside.size == 0:
        return None
    k0 = int(inside[0])
    t0 = float(gnss.t[k0])
    qi = np.flatnonzero(good_q)
    j = int(qi[np.argmin(np.abs(imu.t[qi] - t0))])
    q = itab[j, 7:11]
    R_n_imu = enu_flu_to_ned_frd(quaternion_to_dcm(*q))
    R_nb = R_n_imu @ R_bi.T
    rpy = np.array(dcm_to_euler(R_nb))
    cov = itab[j, 11:14]  # roll, pitch, yaw variances of the IMU orientation (FLU axes)
    sig_att = (
        np.array([INIT_SIGMA_ROLL_PITCH_DEG, INIT_SIGMA_ROLL_PITCH_DEG, INIT_SIGMA_YAW_DEG]) * DEG
    )
    if np.all(np.isfinite(cov)) and np.all(cov > 0):
        sig_att = np.sqrt(cov)
    # velocity: straight-line fit over the fixes in [t0, t0 + 3 s]
    origin = LocalTangentFrame(gnss.lat[k0], gnss.lon[k0], gnss.h[k0])
    win = np.flatnonzero((gnss.t >= t0) & (gnss.t <= t0 + INIT_VEL_FIT_S))
    sig_p = gnss.sigma_ned[k0].copy()
    if win.size >= 2:
        p = origin.to_ned(gnss.lat[win], gnss.lon[win], gnss.h[win])
        dt = gnss.t[win] - t0
        A = np.column_stack([np.ones_like(dt), dt])
        coef, *_ = np.linalg.lstsq(A, p, rcond=None)
        v_n = coef[1]
        span = max(float(dt[-1]), 1e-3)
        # slope sigma of a line fit (~sigma_p * sqrt(12 / n) / span) plus 0.3 m/s for acceleration in the window
        sig_v = np.sqrt(
            (gnss.sigma_ned[win].mean(axis=0) * np.sqrt(12.0 / win.size) / span) ** 2 + 0.3**2
        )
        how_v = f"velocity fitted to {win.size} fixes over {span:.1f} s"
    else:
        v_n = np.zeros(3)
        sig_v = np.full(3, 5.0)
        how_v = "velocity unknown (one fix): 0 +- 5 m/s"
    return InitialState(
        t=t0,
        lat=float(gnss.lat[k0]),
        lon=float(gnss.lon[k0]),
        h=float(gnss.h[k0]),
        v_n=v_n,
        rpy=rpy,
        sigma_pos_m=sig_p,
        sigma_vel_mps=sig_v,
        sigma_att_rad=sig_att,
        how=f"attitude from the orientation on {topic}, position from the first fix, {how_v}",
        yaw_evidence="orientation",
    )


def inspect_bag(
    path, *, imu_topic=None, gnss_topic=None, truth_topic=None, odom_topic=None, fix_mappings=None
) -> str:
    """A text summary of a bag: topics, types, counts, rates, time span, the topics gnssacc would
    use and why (the truth and wheel-odometry candidates decoded and decided as when loading)."""
    path = Path(path)
    where = str(path)
    reader = open_reader(path)
    try:
        stats = survey(reader)
        span = (reader.end_time - reader.start_time) * 1e-9 if reader.message_count else 0.0
        start = reader.start_time * 1e-9 if reader.message_count else 0.0
        kind = "ROS 2" if reader.is2 else "ROS 1"
    finally:
        reader.close()
    lines = [
        f"{where}: {kind} bag, {sum(s.count for s in stats)} messages, {span:.2f} s "
        f"(from {start:.3f} s receive time)",
        "",
    ]
    w = max([len(s.topic) for s in stats] + [5])
    wt = max([len(s.msgtype) for s in stats] + [4])
    lines.append(f"  {'topic':<{w}}  {'type':<{wt}}  {'count':>8}  {'~rate Hz':>9}")
    for s in stats:
        lines.append(f"  {s.topic:<{w}}  {s.msgtype:<{wt}}  {s.count:>8}  {s.rate_hz:>9.2f}")
    lines.append("")
    mappings = merge_fix_mappings(fix_mappings)
    try:
        sel = select_topics(
            stats,
            where,
            imu_topic=imu_topic,
            gnss_topic=gnss_topic,
            truth_topic=truth_topic,
            mappings=mappings,
            odom_topic=odom_topic,
        )
        lines.append("gnssacc would use:")
        lines += [f"  {r}" for r in sel.reasons]
    except InputError as err:
        lines.append(f"gnssacc cannot pick the topics: {err.problem}")
        return "\n".join(lines)
    try:
        lines += [f"  {r}" for r in _decide_candidates(path, sel, mappings)]
    except InputError as err:
        lines.append(f"  cannot decide the truth and odometry candidates: {err.problem}")
    return "\n".join(lines)


def _decide_candidates(path: Path, sel: Selection, mappings: dict) -> list[str]:
    """The truth / odometry decision of a selection (default configuration), as reason lines."""
    import warnings

    from ..core.config import load_config

    if sel.gnss is None or not (
        sel.truth_candidates or sel.odom_candidates or sel.odom or sel.truth or sel.vel_candidates
    ):
        return []
    cfg = load_config(None)
    where = str(path)
    decoder = RowDecoder(mappings, "header", cfg.default_sigma_ned, where)
    reader = open_reader(path)
    try:
        dec = decode_topics(reader, chosen_topics(sel, with_imu=False), decoder)
    finally:
        reader.close()
    max_bad = float(cfg["data"]["max_bad_fraction"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the decisions are listed as lines here
        gnss = fixes_of(fix_table(dec.cols[sel.gnss.topic], where, "GNSS", max_bad, {}, "gnss"))
        origin = LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0])
        given = None
        if sel.truth is not None:
            col = dec.cols[sel.truth.topic]
            if sel.truth_kind == "fix":
                rows = fix_table(col, where, "truth", max_bad, {}, "truth")
                given = Truth(rows[:, 0], rows[:, 1] * DEG, rows[:, 2] * DEG, rows[:, 3])
            else:
                given = pose_truth(col, origin, where, max_bad, {})
        vel = choose_velocity(
            sel.vel_candidates, dec, gnss, origin, where, cfg.default_velocity_sigma
        )
        sel = replace(sel, odom_candidates=[s for s in sel.odom_candidates if s.topic != vel.topic])
        chosen = choose(sel, dec, Context(where, gnss, origin, None, 0.0, max_bad, {}), given)
    out = list(chosen.reasons) + list(vel.reasons)
    for topic, v in chosen.checks.items():
        if sel.truth is not None and topic == sel.truth.topic and not v["ok"]:
            out.append(f"truth {topic} (given) disagrees: {v['why']}")
    if chosen.odometry is None and not any("wheel odometry" in r for r in out):
        out.append("no wheel odometry topic")
    return out
