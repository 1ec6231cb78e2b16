"""GNSS (Doppler) velocities as the file formats give them, made into one
:class:`~gnssacc.core.recording.GnssVelocity`: covariances to sigmas and correlations, speed and
course to north and east, and the documented defaults where a format states no sigma.

Defaults (a stated assumption, not a measurement; ``sigma_stated`` is then False and the tuner
scales them)
    ``[velocity] default_sigma_mps``, by default :data:`DEFAULT_VELOCITY_SIGMA_MPS`: 0.1 m/s
    north and east, 0.2 m/s down: the order of a consumer receiver's Doppler velocity accuracy
    (u-blox states 0.05-0.5 m/s ``sAcc``).
Speed and course (NMEA RMC/VTG, comma2k19's u-blox speed and bearing)
    A receiver's speed over ground and course are the horizontal part of its Doppler velocity:
    ``v_n = s cos(c)``, ``v_e = s sin(c)``, no down component (NaN). With an isotropic
    horizontal velocity error ``sigma`` the course's error is ``sigma / s``, so north and east
    keep ``sigma`` each at every speed above :data:`COURSE_MIN_SPEED_MPS`. Below it the course
    is meaningless (a walking-pace or standing receiver's course wanders, or is frozen by its
    static hold): the course is not used, and the velocity is taken as zero with a speed-based
    sigma ``hypot(s, sigma)`` on north and east (what the speed alone says: the velocity is
    within about ``s`` of zero).
"""

from __future__ import annotations

import numpy as np

from ..core.config import DEFAULTS
from ..core.errors import warn_data
from ..core.recording import GnssVelocity

#: 1-sigma N, E, D [m/s] of velocities whose format states none: ``[velocity] default_sigma_mps``
#: as shipped (the readers take the configured one).
DEFAULT_VELOCITY_SIGMA_MPS = np.array(DEFAULTS["velocity"]["default_sigma_mps"], float)
#: Below this speed over ground [m/s] a course is not used (see the module docstring).
COURSE_MIN_SPEED_MPS = 1.0
#: A velocity covariance whose correlation matrix has a determinant below this is taken as
#: uncorrelated (the file's rounding).
MIN_CORRELATION_DET = 1e-6


def velocity_from_covariance(
    t: np.ndarray,
    v_ned: np.ndarray,
    cov_ned: np.ndarray,
    where: str,
    default_sigma_ned=DEFAULT_VELOCITY_SIGMA_MPS,
) -> GnssVelocity | None:
    """A :class:`GnssVelocity` from velocities and their covariances as a file states them.

    Parameters
    ----------
    t : ndarray, shape (K,)
        Time tags [s] (the fixes').
    v_ned : ndarray, shape (K, 3)
        NED velocity [m/s]; NaN on an axis not measured.
    cov_ned : ndarray, shape (K, 3, 3)
        NED covariance [m^2/s^2]; a zero variance is "not stated".
    where : str
        The file, for warnings.
    default_sigma_ned : array, shape (3,)
        Sigmas [m/s] of rows that state none.

    Returns
    -------
    GnssVelocity or None
        None when no row has a velocity. Rules: a row with every velocity and variance zero is
        "no velocity" (RTKLIB writes such rows without Doppler) and dropped; a row whose
        variances are all zero gets ``default_sigma_ned`` (counted in one warning, and
        ``sigma_stated`` is False when every row is so); a zero variance beside stated ones marks
        that axis unmeasured (NaN, as our writers write an unmeasured axis). Correlations that
        rounding made inconsistent are dropped.
    """
    v = np.array(v_ned, float)
    var = np.diagonal(cov_ned, axis1=1, axis2=2).copy()
    stated = var > 0.0
    empty = ~stated.any(axis=1) & np.all(np.nan_to_num(v) == 0.0, axis=1)
    if empty.all():
        return None
    none = ~stated.any(axis=1) & ~empty
    sig = np.sqrt(np.where(stated, var, np.nan))
    sig[none] = default_sigma_ned
    v[(~none)[:, None] & ~stated] = np.nan
    sig[~np.isfinite(v)] = np.nan
    corr = _correlations(cov_ned, sig, none)
    if none.any() and not none[~empty].all():
        k = int(np.flatnonzero(none)[0])
        warn_data(
            where,
            f"{int(none.sum())} velocit(ies) state no standard deviation (first at {t[k]:.3f} s): "
            f"the default {format_sigma(default_sigma_ned)} m/s used",
        )
    keep = ~empty
    return GnssVelocity(
        np.asarray(t, float)[keep],
        v[keep],
        sig[keep],
        None if corr is None else corr[keep],
        sigma_stated=not none[keep].all(),
    )


def _correlations(cov_ned: np.ndarray, sig: np.ndarray, none: np.ndarray) -> np.ndarray | None:
    """``(rho_ne, rho_nd, rho_ed)`` per row (0 where an axis is unmeasured or the matrix is not
    a valid correlation), None when every row has none."""
    s = np.nan_to_num(sig, nan=np.inf)
    corr = np.column_stack(
        [
            cov_ned[:, 0, 1] / (s[:, 0] * s[:, 1]),
            cov_ned[:, 0, 2] / (s[:, 0] * s[:, 2]),
            cov_ned[:, 1, 2] / (s[:, 1] * s[:, 2]),
        ]
    )
    corr[none] = 0.0
    r_ne, r_nd, r_ed = corr.T
    det = 1.0 + 2.0 * r_ne * r_nd * r_ed - r_ne**2 - r_nd**2 - r_ed**2
    corr[det < MIN_CORRELATION_DET] = 0.0
    return corr if np.any(corr != 0.0) else None


def velocity_from_speed_course(
    t: np.ndarray,
    speed_mps: np.ndarray,
    course_deg: np.ndarray,
    sigma_mps: float = float(DEFAULT_VELOCITY_SIGMA_MPS[0]),
    min_speed_mps: float = COURSE_MIN_SPEED_MPS,
) -> GnssVelocity | None:
    """Horizontal velocities from speed over ground and course (rules in the module docstring).

    Parameters
    ----------
    t : ndarray, shape (K,)
        Time tags [s].
    speed_mps : ndarray, shape (K,)
        Speed over ground [m/s]; NaN: no velocity at that epoch (dropped).
    course_deg : ndarray, shape (K,)
        Course over ground [deg], clockwise from true north; NaN: none (the speed-only rule).
    sigma_mps : float
        1-sigma of the north and east velocity [m/s] (the format states none).
    min_speed_mps : float
        Below this speed the course is not used.

    Returns
    -------
    GnssVelocity or None
        North and east measured, down NaN; ``sigma_stated`` False. None without any speed.
    """
    s = np.asarray(speed_mps, float)
    c = np.radians(np.asarray(course_deg, float))
    keep = np.isfinite(s)
    if not keep.any():
        return None
    use_course = keep & np.isfinite(c) & (s >= min_speed_mps)
    k = len(s)
    v = np.full((k, 3), np.nan)
    sig = np.full((k, 3), np.nan)
    v[:, 0] = np.where(use_course, s * np.cos(c), 0.0)
    v[:, 1] = np.where(use_course, s * np.sin(c), 0.0)
    sig[:, :2] = np.where(use_course, sigma_mps, np.hypot(np.nan_to_num(s), sigma_mps))[:, None]
    return GnssVelocity(np.asarray(t, float)[keep], v[keep], sig[keep], None, sigma_stated=False)


def speed_course(v_ned: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Speed over ground [m/s] and course [deg, 0..360) of NED velocities (K, 3)."""
    v = np.asarray(v_ned, float)
    return np.hypot(v[:, 0], v[:, 1]), np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360.0


def format_sigma(s) -> str:
    """``0.1/0.1/0.2``: N/E/D sigmas for messages."""
    return "/".join(f"{float(x):g}" for x in np.asarray(s, float))


def velocity_on_fixes(vel: GnssVelocity | None, t_fix_old, t_fix_new) -> GnssVelocity | None:
    """``vel`` with its times moved as the fixes' times were (``t_fix_old`` -> ``t_fix_new``):
    a velocity tagged at a fix's time gets that fix's new time (velocities share the fixes'
    clock); None stays None."""
    if vel is None:
        return None
    shift = np.interp(vel.t, t_fix_old, np.asarray(t_fix_new, float) - np.asarray(t_fix_old))
    return GnssVelocity(vel.t + shift, vel.v_ned, vel.sigma_ned, vel.corr_ned, vel.sigma_stated)
