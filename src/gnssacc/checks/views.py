"""The views the input checks compare: what the IMU and the fixes each say about the motion,
before any attitude, mounting, clock offset or units are trusted (:mod:`gnssacc.checks.motionmatch`).

Two independent views place the IMU on the GNSS clock: the accelerations (stage 1 of
:mod:`gnssacc.checks.timeoffset`: the magnitude of the horizontal specific force against the
GNSS-derived acceleration) and the turns (the IMU heading rate against the GNSS course rate,
:func:`gnssacc.checks.motionmatch.turn_rate_fit`). Every fit that needs an offset is made at the
offset the turns favour of the two candidates (as given, or the accelerations' peak), so that a
chance correlation peak of the accelerations cannot shift the unit and mirror checks onto
unrelated epochs (a slow UGV parked for minutes: 3 m fixes show accelerations that are only noise).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.recording import RecordedRun
from .motionmatch import (
    LevelledImu,
    at_times,
    box_average,
    choose_window,
    horizontal_fit,
    lateral_fit,
    level_imu,
    turn_rate_fit,
    velocity_frame,
)
from .timeoffset import OffsetEstimate, coarse_offset

#: The turn view contradicts the accelerations' offset when its correlation there falls this far
#: below its correlation with the stamps as given (the margin stage 1 itself demands of a peak over
#: its rivals, :data:`gnssacc.checks.timeoffset.MIN_MARGIN`).
TURN_MARGIN = 0.2


@dataclass
class Motion:
    """What the IMU and the fixes say about the motion, compared without an attitude.

    Attributes
    ----------
    lev : LevelledImu
    kin : gnssacc.checks.motionmatch.GnssKinematics or None
    offset : OffsetEstimate
        Stage 1 (the accelerations), relative to the IMU stamps as they are.
    fit_offset_s : float
        The offset the fits below were made at [s]: 0 or ``offset.offset_s``, whichever the turns favour.
    turn_rho : dict
        The turn view's correlation at each candidate offset (``{offset: rho}``).
    fit, turn, lateral
        :func:`gnssacc.checks.motionmatch.horizontal_fit`, ``turn_rate_fit``, ``lateral_fit`` at
        ``fit_offset_s`` (``None`` without enough moving epochs).
    """

    lev: LevelledImu
    kin: object
    offset: OffsetEstimate
    fit_offset_s: float = 0.0
    turn_rho: dict = None
    fit: object = None
    turn: object = None
    lateral: object = None

    @property
    def turns_contradict(self) -> bool:
        """Whether the turns favour the stamps as given over the accelerations' offset by
        :data:`TURN_MARGIN` (two views disagree: no offset can be proposed)."""
        rho0, rho1 = (self.turn_rho or {}).get(0.0), (self.turn_rho or {}).get(self.offset.offset_s)
        return rho0 is not None and rho1 is not None and rho0 - rho1 >= TURN_MARGIN


def _turn_rho(lev, kin, tau: float) -> float | None:
    tf = turn_rate_fit(lev, kin, tau)
    return None if tf is None or not np.isfinite(tf.rho) else float(tf.rho)


def measure_motion(run: RecordedRun) -> Motion:
    """The comparisons of :class:`Motion` for a run (IMU and fixes as they are).

    The IMU's horizontal specific force is averaged in a frame fixed on the ground, which needs
    the gyro's heading rate in rad/s, or in the IMU axes (:func:`gnssacc.checks.motionmatch.smooth_horizontal`):
    the gyro is not checked yet, so whichever gives the higher clock-offset correlation peak is used."""
    lev = level_imu(run.imu)
    kin = choose_window(run.gnss, run.origin, run.duration_s)
    if kin is None:
        return Motion(lev, None, OffsetEstimate(0.0, float("inf"), False))
    off = coarse_offset(lev, kin)
    imu_axes = replace(lev, ground_frame=False)
    off_imu = coarse_offset(imu_axes, kin)
    if np.nan_to_num(off_imu.rho, nan=-1.0) > np.nan_to_num(off.rho, nan=-1.0):
        lev, off = imu_axes, off_imu
    rho = {0.0: _turn_rho(lev, kin, 0.0)}
    tau = 0.0
    if off.determined and off.offset_s != 0.0:
        rho[off.offset_s] = _turn_rho(lev, kin, off.offset_s)
        # The fits follow the view that is not contradicted: the accelerations' peak unless the
        # turns clearly favour the stamps as given.
        tau = (
            0.0
            if rho[0.0] is not None
            and (rho[off.offset_s] is None or rho[0.0] - rho[off.offset_s] >= TURN_MARGIN)
            else off.offset_s
        )
    return Motion(
        lev,
        kin,
        off,
        tau,
        rho,
        horizontal_fit(lev, kin, tau),
        turn_rate_fit(lev, kin, tau),
        lateral_fit(lev, kin, tau),
    )


def rest_rate(run: RecordedRun, m: Motion) -> float | None:
    """Median norm of the 1 s mean angular rate (all three axes: a gyro mounted sideways turns about
    any of them) where the fixes show the vehicle at rest, speed within two sigma of zero, at the
    fits' offset [IMU units]; ``None`` with fewer than 10 such epochs."""
    if m.kin is None:
        return None
    _, speed, _ = velocity_frame(m.kin)
    rest = speed < 2.0 * m.kin.sigma_v
    if rest.sum() < 10:
        return None
    imu = run.imu
    n = max(int(imu.t[-1] - imu.t[0]), 1)
    cells = box_average(imu.t, imu.omega_ib_b, float(imu.t[0]) + 0.5, 1.0, n)
    norm = at_times(
        float(imu.t[0]) + 0.5, 1.0, np.linalg.norm(cells, axis=1), m.kin.t[rest] - m.fit_offset_s
    )
    return float(np.median(norm))
