"""Which twist topic of a bag is the GNSS receiver's velocity, told apart from wheel odometry.

ROS GNSS drivers (``ublox_gps``'s ``fix_velocity``, ``nmea_navsat_driver``'s ``vel``, ...)
publish the receiver's Doppler velocity beside ``NavSatFix`` as a
``geometry_msgs/TwistWithCovarianceStamped`` or ``TwistStamped`` in ENU axes; a drive controller
publishes its twist in the body's FLU axes (``linear.x`` the forward speed). A candidate (every
such topic but a given ``--odom-topic``) is the GNSS velocity only when all three hold:

frame
    Its ``frame_id`` is not a body frame (``base_link``, ``base_footprint``) nor a local
    odometry frame (``odom``, REP-105).
pairing
    One message per fix (counts within 25 %), and at least :data:`MIN_PAIRED` of its stamps at
    the same offset from the nearest fix stamp, to :data:`PAIR_FRACTION` of the fixes' median
    interval: the receiver tags both with one epoch (a driver that stamps each sentence as it
    arrives keeps a steady offset).
agreement
    Read as ENU, it agrees with the fixes' central differences: the mean over the horizontal
    axes of the squared residual over its variance (the differences' from the fixes' sigmas
    plus the velocity's own) is below ``max(4, chi2_motion / 4)``, ``chi2_motion`` the same
    mean of the differences themselves (a body-frame forward speed read as ENU misses by the
    speed in every direction but east). When the fixes' differences do not show motion beyond
    their noise (``chi2_motion`` < 4) the agreement is undecided and does not refuse.

One candidate passing is the GNSS velocity (and no longer a wheel-odometry candidate); several
is none, named. Each decision is a reason line (``gnssacc inspect``, ``run.meta["selection"]``).
The velocity keeps the header stamps (the fixes' clock); its covariance's linear block (ENU) is
rotated into NED; without a covariance (``TwistStamped``, or all zero) the documented default
sigma stands in (:data:`gnssacc.sources.gnss_vel.DEFAULT_VELOCITY_SIGMA_MPS`, not stated).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.earth import LocalTangentFrame
from ..core.recording import GnssFixes, GnssVelocity
from ..core.rotations import ENU_NED
from .bag_decode import BASE_FRAMES
from .gnss_vel import DEFAULT_VELOCITY_SIGMA_MPS, velocity_from_covariance
from .truth_check import is_local_frame

#: Fraction of a candidate's stamps that must lie at a fix epoch.
MIN_PAIRED = 0.8
#: A stamp within this fraction of the fixes' median interval of the median offset from the
#: fixes' stamps is at its fix's epoch.
PAIR_FRACTION = 0.1
#: Messages per fix beyond which (or below whose inverse) a topic is not one velocity per fix.
MAX_COUNT_RATIO = 1.25
#: The normalised agreement bound's floor (mean of two chi-square(1) terms: 4 is far out).
CHI2_FLOOR = 4.0


@dataclass
class VelocityChoice:
    """What :func:`choose_velocity` decided."""

    velocity: GnssVelocity | None = None
    topic: str | None = None
    reasons: list = field(default_factory=list)
    checks: dict = field(default_factory=dict)  # topic -> {"frame", "paired", "chi2", ...}


def choose_velocity(
    candidates: list,
    dec,
    gnss: GnssFixes,
    origin: LocalTangentFrame,
    where: str,
    default_sigma_ned: np.ndarray = DEFAULT_VELOCITY_SIGMA_MPS,
) -> VelocityChoice:
    """The GNSS velocity among the twist topics ``candidates`` (module rules).

    Parameters
    ----------
    candidates : list of TopicStat
        ``Selection.vel_candidates``.
    dec : Decoded
        The decoded topics (twist rows: ``t, v x, y, z, omega z, var v, var omega`` and the
        linear covariance ``xx, yy, zz, xy, xz, yz``).
    gnss : GnssFixes
    origin : LocalTangentFrame
    where : str
    default_sigma_ned : ndarray, shape (3,)
        Sigmas [m/s] of a topic that states none (``[velocity] default_sigma_mps``).
    """
    out = VelocityChoice()
    passed = []
    for stat in candidates:
        col = dec.cols[stat.topic]
        tab = col.table()
        tab = tab[np.all(np.isfinite(tab[:, :4]), axis=1)]
        if len(tab) < 2:
            out.reasons.append(f"not GNSS velocity {stat.topic}: fewer than two messages")
            continue
        tab = tab[np.argsort(tab[:, 0], kind="stable")]
        check = _check(tab, col.frame_id, gnss, origin)
        out.checks[stat.topic] = check
        if check["ok"]:
            passed.append((stat.topic, tab, col.frame_id, check))
        else:
            out.reasons.append(f"not GNSS velocity {stat.topic}: {check['why']}")
    if len(passed) == 1:
        topic, tab, frame, check = passed[0]
        out.topic, out.velocity = topic, velocity_of(tab, where, default_sigma_ned)
        out.reasons.append(f"GNSS velocity {topic} (frame {frame!r}): {check['why']}")
    elif len(passed) > 1:
        out.reasons.append(
            "no GNSS velocity: several topics qualify (" + ", ".join(p[0] for p in passed) + ")"
        )
    return out


def _check(tab: np.ndarray, frame: str, gnss: GnssFixes, origin: LocalTangentFrame) -> dict:
    """``{"ok", "why", "frame", "paired", "chi2", "chi2_motion"}`` of one candidate."""
    f = frame.strip().lstrip("/").lower()
    paired = _paired_fraction(tab[:, 0], gnss.t)
    chi2, chi2_motion = _agreement(tab, gnss, origin)
    out = {"frame": frame, "paired": paired, "chi2": chi2, "chi2_motion": chi2_motion}
    if f in BASE_FRAMES or is_local_frame(f):
        return {**out, "ok": False, "why": f"its frame {frame!r} is a body or odometry frame"}
    ratio = len(tab) / max(len(gnss), 1)
    if not 1.0 / MAX_COUNT_RATIO <= ratio <= MAX_COUNT_RATIO:
        why = f"{len(tab)} messages for {len(gnss)} fixes: not one per fix epoch"
        return {**out, "ok": False, "why": why}
    if paired < MIN_PAIRED:
        return {
            **out,
            "ok": False,
            "why": f"only {100 * paired:.0f} % of its stamps are at fix epochs",
        }
    moving = np.isfinite(chi2_motion) and chi2_motion >= CHI2_FLOOR
    bound = max(CHI2_FLOOR, chi2_motion / 4.0) if moving else np.inf
    if moving and not chi2 < bound:
        return {
            **out,
            "ok": False,
            "why": f"read as ENU it disagrees with the fixes' differences (normalised "
            f"{chi2:.1f}, bound {bound:.1f}; the motion itself {chi2_motion:.1f})",
        }
    how = (
        f"agrees as ENU with the fixes' differences (normalised {chi2:.1f}, the motion "
        f"{chi2_motion:.1f})"
        if moving
        else "the fixes show too little motion to compare (decided by frame and stamps)"
    )
    return {**out, "ok": True, "why": f"{100 * paired:.0f} % stamped at fix epochs; {how}"}


def _paired_fraction(t: np.ndarray, t_fix: np.ndarray) -> float:
    """Fraction of the stamps ``t`` at a fix epoch: one stamp per fix (their counts within
    :data:`MAX_COUNT_RATIO` of each other, else 0) whose offset from the nearest fix lies within
    :data:`PAIR_FRACTION` of the fixes' median interval of the median offset (a driver that
    stamps the velocity sentence a little after the position one keeps a steady offset)."""
    if len(t_fix) < 2 or len(t) < 2:
        return 0.0
    ratio = len(t) / len(t_fix)
    if not 1.0 / MAX_COUNT_RATIO <= ratio <= MAX_COUNT_RATIO:
        return 0.0
    dt = float(np.median(np.diff(t_fix)))
    j = np.clip(np.searchsorted(t_fix, t), 1, len(t_fix) - 1)
    before, after = t - t_fix[j - 1], t - t_fix[j]
    offset = np.where(np.abs(before) <= np.abs(after), before, after)
    return float(np.mean(np.abs(offset - np.median(offset)) <= PAIR_FRACTION * dt))


def _agreement(tab: np.ndarray, gnss: GnssFixes, origin: LocalTangentFrame):
    """(mean normalised squared horizontal residual, the same of the differences themselves)
    of the candidate read as ENU against the fixes' central differences (NaN without any)."""
    if len(gnss) < 3:
        return np.nan, np.nan
    p = origin.to_ned(gnss.lat, gnss.lon, gnss.h)
    dt = gnss.t[2:] - gnss.t[:-2]
    v_d = (p[2:, :2] - p[:-2, :2]) / dt[:, None]
    var_d = (gnss.sigma_ned[2:, :2] ** 2 + gnss.sigma_ned[:-2, :2] ** 2) / dt[:, None] ** 2
    tm = gnss.t[1:-1]
    inside = (tm >= tab[0, 0]) & (tm <= tab[-1, 0])
    if not inside.any():
        return np.nan, np.nan
    v_ned = tab[:, 1:4] @ ENU_NED.T
    v = np.column_stack([np.interp(tm[inside], tab[:, 0], v_ned[:, i]) for i in range(2)])
    var_v = float(np.max(DEFAULT_VELOCITY_SIGMA_MPS[:2])) ** 2
    r = v_d[inside] - v
    chi2 = float(np.mean(r**2 / (var_d[inside] + var_v)))
    chi2_motion = float(np.mean(v_d[inside] ** 2 / var_d[inside]))
    return chi2, chi2_motion


def velocity_of(
    tab: np.ndarray, where: str, default_sigma_ned: np.ndarray = DEFAULT_VELOCITY_SIGMA_MPS
) -> GnssVelocity:
    """Twist rows (ENU linear velocity and covariance) as a NED :class:`GnssVelocity`; rows
    without a covariance get ``default_sigma_ned`` [m/s]."""
    v_ned = tab[:, 1:4] @ ENU_NED.T
    lin = tab[:, 7:13]
    if np.all(np.isfinite(lin)) and np.any(lin[:, :3] > 0):
        cov = np.empty((len(tab), 3, 3))
        for a, b, k in ((0, 0, 0), (1, 1, 1), (2, 2, 2), (0, 1, 3), (0, 2, 4), (1, 2, 5)):
            cov[:, a, b] = cov[:, b, a] = lin[:, k]
        cov[:, (0, 1, 2), (0, 1, 2)] = np.where(lin[:, :3] > 0, lin[:, :3], 0.0)
        cov = ENU_NED @ cov @ ENU_NED.T
        vel = velocity_from_covariance(tab[:, 0], v_ned, cov, where, default_sigma_ned)
        if vel is not None:
            return vel
    sig = np.tile(np.asarray(default_sigma_ned, float), (len(tab), 1))
    return GnssVelocity(tab[:, 0].copy(), v_ned, sig, None, sigma_stated=False)
