r"""Input checks: a recording checked against itself before estimation.

Input in the wrong units or layout often still runs and gives confident nonsense (an
accelerometer in g, a gyro in deg/s, IMU stamps in ms, GNSS on GPS time beside an IMU on UTC,
latitude and longitude swapped or in radians, an IMU upside down). :func:`check_run` looks for
each of these in the data themselves, once, at the top of :func:`gnssacc.prepare.prepared.prepare`, so
the command line, the benchmarks and the Python API all get it. In order:

1. ``time_units``: IMU and GNSS time stamps in seconds (:mod:`gnssacc.checks.unitcheck`,
   :mod:`gnssacc.checks.gnsscheck`); ``fix_count``: enough fixes in the IMU's span; ``heights``: heights
   in metres; ``accel_units``: the accelerometer reads gravity at rest.
2. The motion both sensors saw, compared without any attitude (:mod:`gnssacc.checks.motionmatch`): the
   clock offset by cross-correlation (:mod:`gnssacc.checks.timeoffset`), then ``latlon``: radians,
   mirror images (swapped latitude/longitude) and scale of the fixes; ``gyro_units``: the gyro's
   heading rate against the fixes' course rate.
3. ``time_offset``: the measured IMU-to-GNSS clock offset against ``[mounting]
   imu_time_offset_s`` (refined by the EKF's innovation likelihood when it matters).
4. ``mounting``: the IMU axes against the body axes (:mod:`gnssacc.checks.mountcheck`), and the IMU's
   gyro and accelerometer against each other (handedness).
5. ``init_position``: a given start near the fixes.

What happens with a finding
    An error (:class:`~gnssacc.core.errors.InputError`, exit 2 on the command line) that names the file,
    what the data show, the likely cause and the fix. Unit and layout problems whose evidence is
    unambiguous (accelerometer in g, gyro in deg/s, IMU stamps in ms/us/ns, latitude/longitude in
    radians confirmed by the IMU) are repaired instead, with a warning saying what was assumed,
    when the configuration allows it.

Configuration
    ``[checks] repair = "never"`` (default) or ``"auto"``: whether unambiguous unit and layout
    errors are repaired. ``[checks] skip = "name, name"``: checks to leave out (names above).
    ``[mounting] imu_time_offset_s = "auto"`` and ``imu_to_body_rpy_deg = "auto"`` apply the
    measured offset and mounting (with a warning); with numbers (the default 0 and [0, 0, 0]) a
    measurement that clearly contradicts them is an error naming the line that fixes it. A
    plausible mounting (within 20 deg of the configured one: road grade, sitting attitude) or
    offset (within 50 ms or 5 sigma of it) never triggers anything.

Example messages::

    gnssacc: error: run/imu.csv: the accelerometer reads 1.001 on average (median norm of the
      specific force), where local gravity is 9.795 m/s^2: the ax, ay, az columns are in g;
      multiply them by 9.80665, or set [checks] repair = "auto" to let gnssacc do it
    gnssacc: warning: run/imu.csv: IMU time stamps step by 10 (median) and span 1.2e+05 while the
      GNSS fixes span 120.0 s: the IMU stamps are in milliseconds (100 Hz); divided the IMU time
      stamps by 1000 ([checks] repair = "auto")
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.config import RunConfig
from ..core.earth import normal_gravity
from ..core.errors import InputError, warn_data
from ..core.recording import ImuData, RecordedRun
from ..core.rotations import dcm_to_euler
from . import gnsscheck, unitcheck
from .findings import Finding
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
from .mountcheck import estimate_mounting
from .mountcheck import rotation_angle_deg as rotation_angle
from .timeoffset import OffsetEstimate, coarse_offset, shifted

CHECKS = ("time_units", "fix_count", "heights", "accel_units", "gyro_units", "latlon", "init_position",
          "time_offset", "mounting")
REPAIR_MODES = ("never", "auto")
#: Smallest clock offset worth an error [s]: 50 ms is a metre at highway speed.
MIN_OFFSET_S = 0.05
#: Stage 1 (cross-correlation) must put the offset this many sigma from the configured one before
#: the EKF likelihood is asked; the EKF's verdict must then be this many of its own sigma away.
SUSPECT_SIGMAS, ERROR_SIGMAS = 3.0, 5.0


@dataclass(frozen=True)
class Policy:
    """What the configuration allows the checks to do (module notes).

    Attributes
    ----------
    repair : bool
        ``[checks] repair = "auto"``.
    skip : frozenset of str
    offset_auto, mount_auto : bool
        ``[mounting] imu_time_offset_s`` / ``imu_to_body_rpy_deg`` are ``"auto"``.
    """

    repair: bool
    skip: frozenset
    offset_auto: bool
    mount_auto: bool

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "Policy":
        """Read and check ``[checks]`` and the ``"auto"`` mounting keys; ``InputError`` naming the key."""
        c = cfg["checks"]
        if c["repair"] not in REPAIR_MODES:
            raise InputError("config", f'[checks] repair must be "never" or "auto", got {c["repair"]!r}')
        if not isinstance(c["skip"], str):
            raise InputError("config", f'[checks] skip must be a string of check names, e.g. "mounting", got {c["skip"]!r}')
        skip = frozenset(w for w in c["skip"].replace(",", " ").split())
        bad = sorted(skip - set(CHECKS))
        if bad:
            raise InputError("config", f"[checks] skip: unknown check(s) {', '.join(bad)} (known: {', '.join(CHECKS)})")
        m = cfg["mounting"]
        return cls(c["repair"] == "auto", skip, m["imu_time_offset_s"] == "auto", m["imu_to_body_rpy_deg"] == "auto")


def file_names(run: RecordedRun) -> tuple[str, str, str]:
    """Where the IMU, the fixes and the initial state came from, for messages: the files of a CSV
    run directory, else the run's ``where``."""
    if run.meta.get("source") == "csv":
        root = Path(run.where)
        return str(root / "imu.csv"), str(root / "gnss.csv"), str(root / "init.json")
    return run.where, run.where, run.where


def settle(run: RecordedRun, finding: Finding | None, policy: Policy, findings: list) -> RecordedRun:
    """Repair the run (with a warning) when the finding allows it and the policy does; else raise."""
    if finding is None or finding.check in policy.skip:
        return run
    if finding.repair is not None and policy.repair:
        finding.action = "repaired"
        findings.append(finding)
        warn_data(finding.where, f'{finding.problem}; {finding.repaired} ([checks] repair = "auto")')
        return finding.repair(run)
    hint = ', or set [checks] repair = "auto" to let gnssacc do it' if finding.repair is not None else ""
    raise InputError(finding.where, f"{finding.problem}; {finding.fix}{hint}")


def fix_imu_time_units(imu: ImuData, t_gnss: np.ndarray, where: str, cfg: RunConfig) -> ImuData:
    """For sources, before the configured time offset is added: IMU stamps in ms, us or ns found
    (:func:`gnssacc.checks.unitcheck.imu_time_units`) and rescaled with a warning, or an error.

    Parameters
    ----------
    imu : ImuData
        As read (IMU clock, IMU axes).
    t_gnss : ndarray
        The fixes' time stamps [s].
    where : str
        The IMU file.
    cfg : RunConfig
        ``[checks]``.
    """
    if len(imu) < 2 or len(t_gnss) < 1:
        return imu
    policy = Policy.from_config(cfg)
    finding = unitcheck.imu_time_units(np.asarray(imu.t, float), np.asarray(t_gnss, float), where)
    if finding is None or finding.check in policy.skip:
        return imu
    holder = RecordedRun("", where, imu, None, None)
    return settle(holder, finding, policy, []).imu


@dataclass
class Motion:
    """What the IMU and the fixes say about the motion, compared without an attitude.

    Attributes
    ----------
    lev : LevelledImu
    kin : gnssacc.checks.motionmatch.GnssKinematics or None
    offset : OffsetEstimate
        Stage 1, relative to the IMU stamps as they are.
    fit, turn, lateral
        :func:`gnssacc.checks.motionmatch.horizontal_fit`, ``turn_rate_fit``, ``lateral_fit`` at that
        offset (``None`` without enough moving epochs).
    """

    lev: LevelledImu
    kin: object
    offset: OffsetEstimate
    fit: object = None
    turn: object = None
    lateral: object = None


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
    tau = off.offset_s
    return Motion(lev, kin, off, horizontal_fit(lev, kin, tau), turn_rate_fit(lev, kin, tau), lateral_fit(lev, kin, tau))


def rest_rate(run: RecordedRun, m: Motion) -> float | None:
    """Median norm of the 1 s mean angular rate (all three axes: a gyro mounted sideways turns about
    any of them) where the fixes show the vehicle at rest, speed within two sigma of zero [IMU
    units]; ``None`` with fewer than 10 such epochs."""
    if m.kin is None:
        return None
    _, speed, _ = velocity_frame(m.kin)
    rest = speed < 2.0 * m.kin.sigma_v
    if rest.sum() < 10:
        return None
    imu = run.imu
    n = max(int(imu.t[-1] - imu.t[0]), 1)
    cells = box_average(imu.t, imu.omega_ib_b, float(imu.t[0]) + 0.5, 1.0, n)
    norm = at_times(float(imu.t[0]) + 0.5, 1.0, np.linalg.norm(cells, axis=1), m.kin.t[rest] - m.offset.offset_s)
    return float(np.median(norm))


def local_gravity(run: RecordedRun) -> float:
    """Normal gravity at the fixes' median latitude and height [m/s^2] (heights clipped to the
    range of roads, so that a height in the wrong units cannot move it)."""
    g = run.gnss
    return float(normal_gravity(float(np.median(g.lat)), float(np.clip(np.median(g.h), -1000.0, 10000.0))))


def _settle_motion(run: RecordedRun, m: Motion, finding: Finding | None, policy: Policy,
                   findings: list) -> tuple[RecordedRun, Motion]:
    """:func:`settle`, measuring the motion again when the run was repaired."""
    out = settle(run, finding, policy, findings)
    return out, (m if out is run else measure_motion(out))


def motion_checks(run: RecordedRun, policy: Policy, findings: list, imu_where: str,
                  gnss_where: str) -> tuple[RecordedRun, Motion]:
    """Step 2 of the module notes: radians, gyro units, mirror images and scale of the fixes."""
    m = measure_motion(run)
    run, m = _settle_motion(run, m, gnsscheck.latlon_radians(run, m.fit, gnss_where), policy, findings)
    run, m = _settle_motion(run, m, unitcheck.gyro_units(m.turn, rest_rate(run, m), imu_where), policy, findings)
    run = settle(run, gnsscheck.mirror_image(m.fit, m.turn, m.lateral, gnss_where, imu_where), policy, findings)
    run = settle(run, gnsscheck.gnss_scale(m.fit, gnss_where), policy, findings)
    return run, m


def _offset_error(off: OffsetEstimate, configured: float, where: str) -> Finding:
    ahead = "behind" if off.offset_s > 0 else "ahead of"
    total = configured + off.offset_s
    return Finding("time_offset", where,
                   f"the IMU time stamps run {abs(off.offset_s):.3f} s {ahead} the GNSS clock (measured from the motion: "
                   f"offset {off.text()}) with [mounting] imu_time_offset_s = {configured:g}",
                   f'set [mounting] imu_time_offset_s = {total:.3f} (or "auto")',
                   details={"offset_s": off.offset_s, "sigma_s": off.sigma_s, "configured_s": configured})


def _confirmed_offset(run: RecordedRun, cfg: RunConfig, off: OffsetEstimate, refine) -> OffsetEstimate | None:
    """The offset to report against a configured one: stage 1 when it is suspect, confirmed by the
    EKF likelihood (or, should that find no maximum near it, stage 1 alone when overwhelming)."""
    if not off.determined or abs(off.offset_s) <= max(MIN_OFFSET_S, SUSPECT_SIGMAS * off.sigma_s):
        return None
    est = refine(shifted(run, off.offset_s), cfg, off)
    if est is None:
        return off if abs(off.offset_s) >= max(0.5, 10.0 * off.sigma_s) else None
    return est if abs(est.offset_s) > max(MIN_OFFSET_S, ERROR_SIGMAS * est.sigma_s) else None


def offset_step(run: RecordedRun, cfg: RunConfig, policy: Policy, m: Motion, findings: list,
                where: str, refine) -> tuple[RecordedRun, RunConfig, float]:
    """Step 3 of the module notes. Returns the run and configuration (with a measured ``"auto"``
    offset applied) and the best offset between the IMU stamps as ``m`` saw them and the GNSS
    clock [s] (for the mounting's comparisons)."""
    off = m.offset
    left = off.offset_s if off.determined else 0.0
    if "time_offset" in policy.skip:
        return run, cfg, left
    if not policy.offset_auto:
        est = _confirmed_offset(run, cfg, off, refine)
        if est is not None:
            settle(run, _offset_error(est, float(cfg["mounting"]["imu_time_offset_s"]), where), policy, findings)
        return run, cfg, left
    est, apply, text = _auto_offset(run, cfg, off, refine)
    applied = est.offset_s if apply else 0.0
    findings.append(Finding("time_offset", where, f"IMU-to-GNSS clock offset: {text}", action="applied",
                            details={"offset_s": applied, "measured_s": est.offset_s if est else None,
                                     "sigma_s": est.sigma_s if est else float("inf")}))
    warn_data(where, f'[mounting] imu_time_offset_s = "auto": {text}')
    cfg = cfg.with_values({"mounting": {"imu_time_offset_s": round(float(applied), 4)}}, "input checks")
    return (shifted(run, applied), cfg, float(applied)) if apply else (run, cfg, left)


def _auto_offset(run: RecordedRun, cfg: RunConfig, off: OffsetEstimate, refine) -> tuple[OffsetEstimate | None, bool, str]:
    """The measured offset (``None`` without enough motion), whether ``"auto"`` applies it, and
    what to say: applied when the data tell it from zero (:data:`ERROR_SIGMAS` sigma, the evidence
    an error needs), else 0 s kept, so that a synchronised recording with noisy fixes is not
    shifted by the estimate's own noise."""
    if not off.determined:
        return None, False, "the recording has too little motion to measure it; 0 s assumed"
    est = refine(shifted(run, off.offset_s), cfg, off) or off
    if abs(est.offset_s) > ERROR_SIGMAS * est.sigma_s:
        return est, True, f"measured {est.text()}, added to the IMU time stamps"
    return est, False, (f"measured {est.text()}, not distinguishable from 0 s (that needs {ERROR_SIGMAS:g} sigma); "
                        f"0 s kept")


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
    how = (f"from the turns, +-{me.yaw_sigma_deg:.0f} deg" if me.yaw_determined
           else "assumed: too few turns to tell")
    return (f"the IMU's {fwd} axis points forward ({how}) and its {down} axis down (the specific force along IMU z "
            f"averages {f_mean_z:+.2f} m/s^2)")


def mount_step(run: RecordedRun, cfg: RunConfig, policy: Policy, m: Motion, tau: float, findings: list,
               where: str) -> tuple[RecordedRun, RunConfig]:
    """Step 4 of the module notes: the mounting against the configured one, or applied (``"auto"``)."""
    if "mounting" in policy.skip:
        return run, cfg
    lf = lateral_fit(m.lev, m.kin, tau) if m.kin is not None else None
    me = estimate_mounting(m.lev, lf)
    f_z = float(-m.lev.down[2] * m.lev.f_mean_norm)
    text = describe_mounting(me, f_z)
    if not policy.mount_auto:
        if me.implausible:
            settle(run, Finding("mounting", where, f"{text}, not as [mounting] imu_to_body_rpy_deg = "
                                f"{rpy_text(cfg.R_bi, True)} says",
                                f"set [mounting] imu_to_body_rpy_deg = {rpy_text(me.R_bi @ cfg.R_bi, me.snapped)} "
                                f'(or "auto")', details={"tilt_deg": me.tilt_deg}), policy, findings)
        return run, cfg
    line = rpy_text(me.R_bi, me.snapped)
    findings.append(Finding("mounting", where, text, action="applied", details={"rpy_deg": line}))
    if rotation_angle(me.R_bi) > 1e-6:
        warn_data(where, f'[mounting] imu_to_body_rpy_deg = "auto": {text}; applied imu_to_body_rpy_deg = {line}')
        R = me.R_bi
        run = replace(run, imu=ImuData(run.imu.t, run.imu.f_b @ R.T, run.imu.omega_ib_b @ R.T))
    rpy = [float(v) for v in np.degrees(np.array(dcm_to_euler(me.R_bi)))]
    return run, cfg.with_values({"mounting": {"imu_to_body_rpy_deg": rpy}}, "input checks")


def check_run(run: RecordedRun, cfg: RunConfig, refine_offset) -> tuple[RecordedRun, RunConfig, list]:
    """Check a run against itself before estimation (module notes).

    Parameters
    ----------
    run : RecordedRun
        As loaded (validated).
    cfg : RunConfig
        ``[checks]`` and ``[mounting]``.
    refine_offset : callable
        ``refine_offset(run, cfg, stage1) -> OffsetEstimate or None``: stage 2 of the clock offset,
        the EKF's innovation likelihood around stage 1 on ``run`` shifted by it
        (:func:`gnssacc.prepare.clock.refine_offset` with a filter pass; handed in because the
        checks precede the estimators).

    Returns
    -------
    run : RecordedRun
        With the repairs and the measured ``"auto"`` offset and mounting applied.
    cfg : RunConfig
        With the ``"auto"`` mounting keys replaced by the values applied.
    findings : list of Finding
        What was repaired or applied (errors raise instead).

    Raises
    ------
    InputError
        Naming the file, what the data show, the likely cause and the fix.
    """
    policy = Policy.from_config(cfg)
    imu_w, gnss_w, init_w = file_names(run)
    findings: list = []
    for check in (lambda r: unitcheck.imu_time_units(r.imu.t, r.gnss.t, imu_w),
                  lambda r: gnsscheck.gnss_time_units(r.gnss.t, gnss_w),
                  lambda r: gnsscheck.fix_count(r.gnss.t, r.t_start, r.t_end, gnss_w),
                  lambda r: gnsscheck.heights(r.gnss.h, gnss_w),
                  lambda r: unitcheck.accel_units(r.imu, local_gravity(r), imu_w)):
        run = settle(run, check(run), policy, findings)
    run, m = motion_checks(run, policy, findings, imu_w, gnss_w)
    run, cfg, tau = offset_step(run, cfg, policy, m, findings, imu_w, refine_offset)
    run, cfg = mount_step(run, cfg, policy, m, tau, findings, imu_w)
    run = settle(run, gnsscheck.init_position(run, init_w), policy, findings)
    return run, cfg, findings
