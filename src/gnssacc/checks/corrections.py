"""The clock offset and the mounting: what the views propose against the configuration.

Both are proposals (a :class:`~gnssacc.checks.findings.Finding` with a ``repair``): the
preparation stage asks the estimator whether the corrected data are decisively more likely than
the data as given before it applies or refuses anything (:mod:`gnssacc.prepare.judge`). For the
clock offset it also refines the offset by the likelihood (:mod:`gnssacc.prepare.clock`).

* **Clock offset**: stage 1 (the accelerations) must put the offset :data:`SUSPECT_SIGMAS` of
  its sigma and :data:`MIN_OFFSET_S` from the configured one, and the turn view must not
  contradict it (:attr:`gnssacc.checks.views.Motion.turns_contradict`; a contradicted offset is
  one view against another: recorded as refuted, never a refusal, and nothing a user need read). With ``imu_time_offset_s = "auto"`` every
  determined stage-1 offset is proposed (the estimator decides whether it is told from 0 s).
* **Mounting**: the IMU's down axis from the mean specific force and its forward axis from the
  turns (:mod:`gnssacc.checks.mountcheck`) against ``imu_to_body_rpy_deg``; implausible when a
  right-angle orientation other than the configured one, or an oblique one beyond the tilt of
  road grades and seating. The correction rotates everything that lives in the IMU frame in one
  place (:meth:`gnssacc.core.recording.RecordedRun.with_mounting`: samples and a given start's
  attitude).
"""

from __future__ import annotations

import numpy as np

from ..core.config import RunConfig
from ..core.recording import RecordedRun
from ..core.rotations import dcm_to_euler
from .findings import Finding
from .mountcheck import estimate_mounting
from .mountcheck import rotation_angle_deg as rotation_angle
from .timeoffset import OffsetEstimate, shifted
from .views import Motion

#: Smallest clock offset worth a correction [s]: 50 ms is a metre at highway speed.
MIN_OFFSET_S = 0.05
#: Stage 1 must put the offset this many of its sigma from the configured one for a proposal.
SUSPECT_SIGMAS = 3.0


def offset_proposal(
    run: RecordedRun, cfg: RunConfig, m: Motion, auto: bool, where: str
) -> Finding | None:
    """The clock-offset proposal (module notes), or ``None``; its ``repair`` shifts the IMU stamps
    by stage 1's offset (the preparation stage refines it), ``details`` hold stage 1."""
    off = m.offset
    configured = 0.0 if auto else float(cfg["mounting"]["imu_time_offset_s"])
    if not off.determined:
        return None
    suspect = abs(off.offset_s) > max(MIN_OFFSET_S, SUSPECT_SIGMAS * off.sigma_s)
    if not auto and not suspect:
        return None
    details = {
        "stage1_s": off.offset_s,
        "stage1_sigma_s": off.sigma_s,
        "configured_s": configured,
        "turn_rho": {f"{k:+.3f}": v for k, v in (m.turn_rho or {}).items()},
        "auto": auto,
    }
    if m.turns_contradict:  # one view against another: recorded, nothing to tell the user
        rho = m.turn_rho
        return Finding(
            "time_offset",
            where,
            f"the accelerations put the IMU time stamps {off.text()} off the GNSS "
            f"clock, but the turns match the stamps as given (correlation {rho[0.0]:.2f} against "
            f"{rho[off.offset_s]:.2f} at that offset)",
            action="refuted",
            details=details,
        )
    return Finding(
        "time_offset",
        where,
        offset_problem(off, configured, auto),
        f'set [mounting] imu_time_offset_s = {configured + off.offset_s:.3f} (or "auto")',
        lambda r: shifted(r, off.offset_s),
        "added to the IMU time stamps",
        details=details,
    )


def offset_problem(off: OffsetEstimate, configured: float, auto: bool) -> str:
    """What a measured offset means, for messages."""
    if auto:
        return f'[mounting] imu_time_offset_s = "auto": measured {off.text()}'
    ahead = "behind" if off.offset_s > 0 else "ahead of"
    return (
        f"the IMU time stamps run {abs(off.offset_s):.3f} s {ahead} the GNSS clock (measured from the motion: "
        f"offset {off.text()}) with [mounting] imu_time_offset_s = {configured:g}"
    )


def _axis_name(v: np.ndarray) -> str:
    """The IMU axis (with sign) closest to a unit vector given in IMU axes, e.g. ``"-z"``."""
    j = int(np.argmax(np.abs(v)))
    return ("+" if v[j] > 0 else "-") + "xyz"[j]


def rpy_text(R: np.ndarray, snapped: bool) -> str:
    """``[roll, pitch, yaw]`` [deg] of ``R`` as a configuration value (whole degrees when snapped)."""
    rpy = np.degrees(np.array(dcm_to_euler(R)))
    vals = np.round(rpy).astype(int) if snapped else np.round(rpy, 1)
    vals = [abs(v) if abs(abs(v) - 180) < 1e-9 or v == 0 else v for v in vals.tolist()]
    return "[" + ", ".join(f"{v:g}" for v in vals) + "]"


def describe_mounting(me, f_mean_z: float) -> str:
    """Which IMU axes point forward and down, and on what evidence."""
    fwd, down = _axis_name(me.R_est[0]), _axis_name(me.R_est[2])
    how = (
        f"from the turns, +-{me.yaw_sigma_deg:.0f} deg"
        if me.yaw_determined
        else "assumed: too few turns to tell"
    )
    return (
        f"the IMU's {fwd} axis points forward ({how}) and its {down} axis down (the specific force along IMU z "
        f"averages {f_mean_z:+.2f} m/s^2)"
    )


def mounting_rpy_deg(R: np.ndarray) -> list[float]:
    """``[roll, pitch, yaw]`` [deg] of a mounting rotation, as the configuration holds it."""
    return [float(v) for v in np.degrees(np.array(dcm_to_euler(R)))]


def mount_proposal(
    run: RecordedRun, cfg: RunConfig, m: Motion, auto: bool, where: str
) -> tuple[Finding | None, str]:
    """The mounting proposal (module notes), or ``None``, and the account of what the data show.

    With ``auto`` the measured mounting is proposed unless it is the identity; otherwise only an
    implausible one. The repair rotates the run by the measured rotation (relative to the axes
    as loaded); ``details["rpy_deg"]`` is the configuration value to write (absolute)."""
    lf = m.lateral  # lateral_fit(m.lev, m.kin, m.fit_offset_s), made with the views
    me = estimate_mounting(m.lev, lf)
    text = describe_mounting(me, float(-m.lev.down[2] * m.lev.f_mean_norm))
    if (auto and rotation_angle(me.R_bi) <= 1e-6) or (not auto and not me.implausible):
        return None, text
    absolute = me.R_bi if auto else me.R_bi @ cfg.R_bi
    line = rpy_text(absolute, me.snapped)
    problem = (
        text
        if auto
        else f"{text}, not as [mounting] imu_to_body_rpy_deg = {rpy_text(cfg.R_bi, True)} says"
    )
    R = me.R_bi
    others = (
        () if me.yaw_determined else _forward_alternatives(absolute, lf is not None, me.snapped)
    )
    fix = (
        "set [mounting] imu_to_body_rpy_deg to the one whose x axis points forward"
        if others
        else f'set [mounting] imu_to_body_rpy_deg = {line} (or "auto")'
    )
    return Finding(
        "mounting",
        where,
        problem,
        fix,
        lambda r: r.with_mounting(R),
        f"imu_to_body_rpy_deg = {line}",
        details={"tilt_deg": me.tilt_deg, "rpy_deg": mounting_rpy_deg(absolute)},
        alternatives=others,
    ), text


def _forward_alternatives(absolute: np.ndarray, moved: bool, snapped: bool) -> tuple[str, ...]:
    """The mountings with the same down axis that the data explain as well when the motion never
    showed the forward axis: the one turned by 180 deg (the ground-vehicle model cannot tell
    forward from backward), and those turned by 90 deg when the vehicle never moved enough to
    show even along which axis it drives."""
    turns = (2,) if moved else (1, 2, 3)
    out = []
    for k in turns:
        c, s = np.cos(k * np.pi / 2), np.sin(k * np.pi / 2)
        Rz = np.round(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))
        out.append(f"imu_to_body_rpy_deg = {rpy_text(Rz @ absolute, snapped)}")
    return tuple(out)
