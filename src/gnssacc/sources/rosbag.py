"""ROS bags as a run source: ROS 1 ``.bag``, ROS 2 directories (sqlite3 or MCAP) and bare ``.mcap``.

Everything is read through :class:`rosbags.highlevel.AnyReader`, with the message definitions
taken from the bag itself, so custom message types decode without a ROS installation.

Topics
    IMU: ``sensor_msgs/msg/Imu``. GNSS: ``sensor_msgs/msg/NavSatFix`` or a custom fix type with
    a field mapping (:data:`FIX_MAPPINGS`, shipped for the ROOAD ``ubxtranslator/hpposllh``).
    Truth (optional): ``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseStamped``,
    ``geometry_msgs/msg/PoseWithCovarianceStamped`` or a second fix topic (e.g. an RTK receiver).
    Topics are picked by type and rate when unambiguous (see :func:`select_topics`); otherwise
    an :class:`~gnssacc.core.errors.InputError` lists the candidates and the argument that picks one.

Frames (ROS REP-103 -> gnssacc)
    IMU samples are body Front-Left-Up and converted to Front-Right-Down ``(x, -y, -z)`` before
    the ``[mounting]`` rotation. Pose positions and orientations are in a local East-North-Up
    frame: ``(e, n, u) -> (n, e, -u)`` and ``R_nb = T_ned_enu @ R_enu_flu @ T_flu_frd``.
    ASSUMPTION for pose truth: the pose frame is ENU with its origin at the first GNSS fix,
    unless ``truth_origin_llh_deg`` says otherwise.

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

from pathlib import Path

import numpy as np

from ..core.config import DEG, RunConfig
from ..core.earth import LocalTangentFrame
from ..core.errors import InputError, warn_data
from ..core.memory import release_free_memory
from ..core.recording import GnssFixes, ImuData, InitialState, RecordedRun, Truth, drop_nonfinite
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
from .bag_times import find_gaps, sorted_unique, subsample
from .bag_topics import Selection, TopicStat, select_topics, survey
from .common import apply_mounting, check_degrees, one_line, with_noisy_fixes

# The bag source's public names, wherever they are defined.
__all__ = ["FIX_MAPPINGS", "MAGIC", "STORAGE_SUFFIXES", "Selection", "TopicStat", "check_bag_path",
           "enu_flu_to_ned_frd", "inspect_bag", "load_bag_run", "normalize_type", "select_topics", "storage_files"]

#: Initial-state sigmas when the IMU orientation has no (valid) covariance.
INIT_SIGMA_ROLL_PITCH_DEG = 1.0
INIT_SIGMA_YAW_DEG = 5.0
INIT_VEL_FIT_S = 3.0

enu_flu_to_ned_frd = ros_to_R_nb  # name kept for callers of this module


def load_bag_run(path, cfg: RunConfig, *, imu_topic: str | None = None, gnss_topic: str | None = None,
                 truth_topic: str | None = None, time_source: str = "header",
                 gnss_from_truth_hz: float | None = None, noise: str | None = None, seed: int = 0,
                 fix_mappings: dict | None = None, truth_origin_llh_deg=None) -> RecordedRun:
    """Load a ROS 1 / ROS 2 bag as a :class:`RecordedRun`.

    Parameters
    ----------
    path : str or Path
        A ``.bag`` file, a ROS 2 bag directory (sqlite3 or MCAP storage) or a bare ``.mcap``.
    cfg : RunConfig
        Uses ``[mounting]``, ``gnss.default_sigma_m``, ``data.max_bad_fraction`` and ``[bag] fix_mappings``.
    imu_topic, gnss_topic, truth_topic : str, optional
        Topic choices; by default picked by :func:`select_topics`.
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
    mappings = merge_fix_mappings(cfg["bag"]["fix_mappings"] if fix_mappings is None else fix_mappings)
    decoder = RowDecoder(mappings, time_source, cfg.default_sigma_ned,
                         where)
    max_bad = float(cfg["data"]["max_bad_fraction"])
    meta: dict = {"source": "bag", "time_source": time_source}
    sel, dec, tf = _read(path, cfg, decoder, meta, imu_topic=imu_topic, gnss_topic=gnss_topic,
                         truth_topic=truth_topic, gnss_from_truth=gnss_from_truth_hz is not None)

    itab, imu, R_bi_total = _imu(dec.cols[sel.imu.topic], tf, cfg, where, max_bad, meta)
    truth = None
    if sel.truth is not None and sel.truth_kind == "fix":
        rows = _fix_table(dec.cols[sel.truth.topic], where, "truth", max_bad, meta, "truth")
        truth = Truth(rows[:, 0], rows[:, 1] * DEG, rows[:, 2] * DEG, rows[:, 3])
    if sel.gnss is not None:
        g = _fix_table(dec.cols[sel.gnss.topic], where, "GNSS", max_bad, meta, "gnss")
        gnss = GnssFixes(g[:, 0], g[:, 1] * DEG, g[:, 2] * DEG, g[:, 3], g[:, 4:7])
        origin = LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0])
    else:
        gnss, origin = _gnss_from_truth(truth, imu, where, float(gnss_from_truth_hz), noise or "white", seed, meta)
    meta["gaps"]["gnss"] = find_gaps(gnss.t, float(cfg["quality"]["gap_factor"]))
    if sel.truth is not None and sel.truth_kind == "pose":
        truth = _pose_truth(dec.cols[sel.truth.topic], origin, truth_origin_llh_deg, where, max_bad, meta)
    good_q = np.isfinite(itab[:, 7:11]).all(axis=1)
    init = _initial_state(itab, good_q, imu, gnss, R_bi_total, sel.imu.topic) if good_q.any() else None
    run = RecordedRun(name=path.stem if path.is_file() else path.name, where=where, imu=imu, gnss=gnss,
                      origin=origin, truth=truth, init=init, meta=meta)
    release_free_memory()   # the decoded message columns
    return run.validate()


def _check_options(where: str, time_source: str, noise: str | None, gnss_from_truth_hz) -> None:
    """:class:`InputError` for a time source, noise or ``--gnss-from-truth`` rate [Hz] that cannot be used."""
    if time_source not in TIME_SOURCES:
        raise InputError(where, f"time_source must be one of {', '.join(TIME_SOURCES)}, got {time_source!r}")
    if noise is not None and gnss_from_truth_hz is None:
        raise InputError(where, "--noise on a bag needs --gnss-from-truth RATE_HZ (without it the bag's own "
                                "fixes are used as they are)")
    if gnss_from_truth_hz is not None and not float(gnss_from_truth_hz) > 0:
        raise InputError(where, f"--gnss-from-truth must be a positive rate in Hz, got {gnss_from_truth_hz}")


def _read(path: Path, cfg: RunConfig, decoder: RowDecoder, meta: dict, **choices) -> tuple:
    """Open the bag, pick the topics (``choices``: see :func:`select_topics`), decode them and
    look for the IMU mounting on ``/tf_static``: (Selection, Decoded, (R_bi, what) or None)."""
    where = decoder.where
    reader = open_reader(path)
    try:
        meta["bag_format"] = "ros2" if reader.is2 else "ros1"
        if getattr(reader, "damaged", None):
            meta["damaged"] = f"{reader.damaged}; salvaged {reader.good_bytes} of {reader.file_bytes} bytes"
        sel = select_topics(survey(reader), where, mappings=decoder.mappings, **choices)
        meta["topics"] = {"imu": sel.imu.topic, "gnss": sel.gnss.topic if sel.gnss else None,
                          "truth": sel.truth.topic if sel.truth else None}
        meta["selection"] = sel.reasons
        dec = decode_topics(reader, {s.topic: s.msgtype for s in (sel.imu, sel.gnss, sel.truth) if s is not None},
                            decoder)
        _check_damage(dec, where, meta)
        tf = None
        if not np.any(cfg.imu_to_body_rpy_deg):      # a configured mounting wins over /tf_static
            try:
                tf = tf_mounting(reader, dec.imu_frame_id)
            except Exception as err:
                warn_data(where, f"/tf_static could not be read ({one_line(err)}); IMU mounting from the config")
    finally:
        reader.close()
    return sel, dec, tf


def _check_damage(dec: Decoded, where: str, meta: dict) -> None:
    """A bag that broke off while reading: the messages before the damage, with a warning."""
    if dec.damaged is None:
        return
    n = sum(len(c) for c in dec.cols.values())
    if not n:
        raise InputError(where, f"cannot read the bag (truncated or corrupt?): {dec.damaged}")
    warn_data(where, f"the bag is damaged ({dec.damaged}); using the {n} messages read before the damage")
    meta["damaged"] = dec.damaged


def _clean_rows(col: Collector, n_needed: int, where: str, what: str, max_bad: float, meta: dict,
                key: str) -> np.ndarray:
    """The rows of ``col`` whose first ``n_needed`` columns are finite (the others dropped with a
    warning, or an error above ``max_bad``), sorted by time without repeated stamps."""
    tab = col.table()
    if len(tab) == 0:
        raise InputError(where, f"{what}: no messages")
    keep = np.all(np.isfinite(tab[:, :n_needed]), axis=1)
    if not keep.all():
        drop_nonfinite(tab[:, :n_needed], where, what, max_bad)      # warns with the count, or raises
        tab = tab[keep]
    return sorted_unique(tab, where, what, meta, key)


def _imu(col: Collector, tf, cfg: RunConfig, where: str, max_bad: float, meta: dict):
    """IMU rows -> (sorted rows, ImuData in body FRD, R_bi of the IMU axes incl. /tf_static).

    The FLU samples are turned FRD, rotated by the ``/tf_static`` mounting if there is one, then
    by ``[mounting]`` (:func:`~gnssacc.sources.common.apply_mounting`).
    """
    what = f"IMU topic {col.topic}"
    itab = _clean_rows(col, 7, where, what, max_bad, meta, "imu")
    if len(itab) < 2:
        raise InputError(where, f"{what}: {len(itab)} usable message(s), need at least two")
    f_imu = itab[:, 1:4] @ FLU_FRD          # FLU -> FRD (diagonal: same as T @ x per row)
    w_imu = itab[:, 4:7] @ FLU_FRD
    if tf is not None:
        R_bi_tf, what_tf = tf
        f_imu, w_imu = f_imu @ R_bi_tf.T, w_imu @ R_bi_tf.T
        meta["imu_mounting"] = {"from": what_tf, "imu_to_body_rpy_deg": [float(np.degrees(a))
                                                                        for a in dcm_to_euler(R_bi_tf)]}
        R_bi_total = cfg.R_bi @ R_bi_tf
    else:
        meta["imu_mounting"] = {"from": "config [mounting] imu_to_body_rpy_deg",
                                "imu_to_body_rpy_deg": [float(v) for v in cfg.imu_to_body_rpy_deg]}
        R_bi_total = cfg.R_bi
    imu = apply_mounting(ImuData(itab[:, 0].copy(), f_imu, w_imu), cfg)
    meta["gaps"] = {"imu": find_gaps(imu.t, float(cfg["quality"]["gap_factor"]))}
    return itab, imu, R_bi_total


def _fix_table(col: Collector, where: str, what: str, max_bad: float, meta: dict, key: str) -> np.ndarray:
    """Fix rows (t [s], lat [deg], lon [deg], h [m], sigma NED [m]): counted, checked, sorted."""
    label = f"{what} topic {col.topic}"
    tab = col.table()
    if col.skipped_no_fix:
        if len(tab) == 0:
            raise InputError(where, f"{label}: all {col.skipped_no_fix} messages are NO_FIX (status -1); no usable fix")
        warn_data(where, f"{label}: skipped {col.skipped_no_fix} NO_FIX message(s)")
    if col.zero_cov:
        warn_data(where, f"{label}: {col.zero_cov} message(s) with an all-zero covariance; "
                         f"used gnss.default_sigma_m instead")
    meta.setdefault("fix_counts", {})[key] = {"messages": col.total, "no_fix": col.skipped_no_fix,
                                              "zero_covariance": col.zero_cov}
    if len(tab) == 0:
        raise InputError(where, f"{label}: no messages")
    tab = drop_nonfinite(tab, where, label, max_bad)
    if len(tab) == 0:
        raise InputError(where, f"{label}: no usable fix")
    tab = sorted_unique(tab, where, label, meta, key)
    check_degrees(tab[:, 1], tab[:, 2], tab[:, 0], where, label)
    return tab


def _gnss_from_truth(truth: Truth, imu: ImuData, where: str, rate_hz: float, noise: str, seed: int, meta: dict):
    """(fixes, origin): the truth subsampled at ``rate_hz`` [Hz] plus ``noise``; origin at the first truth point."""
    origin = LocalTangentFrame(truth.lat[0], truth.lon[0], truth.h[0])
    sub = subsample(truth.t, rate_hz)
    sub_truth = Truth(truth.t[sub], truth.lat[sub], truth.lon[sub], truth.h[sub])
    holder = RecordedRun("tmp", where, imu, GnssFixes(*(np.empty(0),) * 4, np.empty((0, 3))), origin)
    gnss = with_noisy_fixes(holder, sub_truth, noise, seed).gnss
    meta.update(gnss_from_truth_hz=rate_hz, noise=noise, seed=seed)
    return gnss, origin


def _pose_truth(col: Collector, origin: LocalTangentFrame, truth_origin_llh_deg, where: str, max_bad: float,
                meta: dict) -> Truth:
    """Truth from pose rows (NED about the pose frame's origin: ``truth_origin_llh_deg`` or ``origin``)."""
    ptab = _clean_rows(col, 4, where, f"truth topic {col.topic}", max_bad, meta, "truth")
    if truth_origin_llh_deg is not None:
        lat0, lon0, h0 = (float(v) for v in truth_origin_llh_deg)
        porigin = LocalTangentFrame(lat0 * DEG, lon0 * DEG, h0)
        meta["truth_origin"] = f"given: {lat0}, {lon0} deg, {h0} m"
    else:
        porigin = origin
        meta["truth_origin"] = "assumed: the pose frame is ENU with origin at the first GNSS fix"
    lat, lon, h = porigin.to_llh(ptab[:, 1:4])
    v_n = ptab[:, 4:7] if np.all(np.isfinite(ptab[:, 4:7])) else None
    rpy = ptab[:, 7:10] if np.all(np.isfinite(ptab[:, 7:10])) else None
    return Truth(ptab[:, 0], lat, lon, h, v_n, rpy)


def _initial_state(itab: np.ndarray, good_q: np.ndarray, imu: ImuData, gnss: GnssFixes, R_bi: np.ndarray,
                   topic: str) -> InitialState | None:
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
    cov = itab[j, 11:14]       # roll, pitch, yaw variances of the IMU orientation (FLU axes)
    sig_att = np.array([INIT_SIGMA_ROLL_PITCH_DEG, INIT_SIGMA_ROLL_PITCH_DEG, INIT_SIGMA_YAW_DEG]) * DEG
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
        sig_v = np.sqrt((gnss.sigma_ned[win].mean(axis=0) * np.sqrt(12.0 / win.size) / span) ** 2 + 0.3 ** 2)
        how_v = f"velocity fitted to {win.size} fixes over {span:.1f} s"
    else:
        v_n = np.zeros(3)
        sig_v = np.full(3, 5.0)
        how_v = "velocity unknown (one fix): 0 +- 5 m/s"
    return InitialState(t=t0, lat=float(gnss.lat[k0]), lon=float(gnss.lon[k0]), h=float(gnss.h[k0]), v_n=v_n,
                        rpy=rpy, sigma_pos_m=sig_p, sigma_vel_mps=sig_v, sigma_att_rad=sig_att,
                        how=f"attitude from the orientation on {topic}, position from the first fix, {how_v}")



def inspect_bag(path, *, imu_topic=None, gnss_topic=None, truth_topic=None, fix_mappings=None) -> str:
    """A text summary of a bag: topics, types, counts, rates, time span, and the topics gnssacc would use."""
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
    lines = [f"{where}: {kind} bag, {sum(s.count for s in stats)} messages, {span:.2f} s "
             f"(from {start:.3f} s receive time)", ""]
    w = max([len(s.topic) for s in stats] + [5])
    wt = max([len(s.msgtype) for s in stats] + [4])
    lines.append(f"  {'topic':<{w}}  {'type':<{wt}}  {'count':>8}  {'~rate Hz':>9}")
    for s in stats:
        lines.append(f"  {s.topic:<{w}}  {s.msgtype:<{wt}}  {s.count:>8}  {s.rate_hz:>9.2f}")
    lines.append("")
    try:
        sel = select_topics(stats, where, imu_topic=imu_topic, gnss_topic=gnss_topic, truth_topic=truth_topic,
                            mappings=merge_fix_mappings(fix_mappings))
        lines.append("gnssacc would use:")
        lines += [f"  {r}" for r in sel.reasons]
    except InputError as err:
        lines.append(f"gnssacc cannot pick the topics: {err.problem}")
    return "\n".join(lines)
