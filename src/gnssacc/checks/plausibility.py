r"""Input checks: a recording checked against itself before estimation.

Input in the wrong units or layout often still runs and gives confident nonsense (an
accelerometer in g, a gyro in deg/s, IMU stamps in ms, GNSS on GPS time beside an IMU on UTC,
latitude and longitude swapped or in radians, an IMU upside down). :func:`check_run` looks for
each of these in the data themselves, in order:

1. ``time_units``: IMU and GNSS time stamps in seconds (:mod:`gnssacc.checks.unitcheck`,
   :mod:`gnssacc.checks.gnsscheck`); ``fix_count``: enough fixes in the IMU's span; ``heights``:
   heights in metres; ``accel_units``: the accelerometer reads gravity at rest.
2. The motion both sensors saw, compared without any attitude (:mod:`gnssacc.checks.views`), then
   ``latlon``: radians, mirror images (swapped latitude/longitude) and scale of the fixes;
   ``gyro_units``: the gyro's heading rate against the fixes' course rate, and its rest rate.
3. ``time_offset``: the IMU-to-GNSS clock offset the accelerations and the turns show, against
   ``[mounting] imu_time_offset_s`` (:mod:`gnssacc.checks.corrections`).
4. ``mounting``: the IMU axes against the body axes (:mod:`gnssacc.checks.mountcheck`), and the
   IMU's gyro and accelerometer against each other (handedness).
5. ``init_position``: a given start near the fixes.

What happens with a finding (:func:`consider`)
    A check proposes; only the estimator proves. A finding with a correction (a ``repair``) is a
    *proposal*: :func:`check_run` stops at the first one and returns it, and the preparation stage
    runs the EKF on the data as given and as corrected (:mod:`gnssacc.prepare.judge`). Only when
    the corrected data are decisively more likely does it act: it applies the correction when the
    configuration allows it (``[checks] repair = "auto"``, or the ``"auto"`` offset and mounting)
    and otherwise refuses the data with the evidence both ways in one error line; when they are
    not, it warns and the data are used as given (the proposal is not made again). A finding
    without a correction is one view alone: a warning. Only data that cannot be estimated at all
    (no fixes in the IMU's span, fix stamps no receiver writes) are refused outright.

Configuration
    ``[checks] repair = "never"`` (default) or ``"auto"``: whether confirmed unit and layout
    errors are repaired. ``[checks] skip = "name, name"``: checks to leave out (names above).
    ``[mounting] imu_time_offset_s = "auto"`` and ``imu_to_body_rpy_deg = "auto"`` apply the
    measured offset and mounting once confirmed; with numbers (the default 0 and [0, 0, 0]) a
    confirmed contradiction is an error naming the line that fixes it. A plausible mounting
    (within 20 deg of the configured one: road grade, sitting attitude) or offset (within 50 ms
    or 3 sigma of it) is not even proposed.

Example messages::

    gnssacc: error: run/imu.csv: the accelerometer reads 1.001 on average (median norm of the
      specific force), where local gravity is 9.795 m/s^2: the ax, ay, az columns are in g;
      multiply them by 9.80665, or set [checks] repair = "auto" to let gnssacc do it; the
      estimator confirms it: log-likelihood +48210 as corrected over 110 fixes (26300 per minute)
    gnssacc: warning: run/imu.csv: the IMU time stamps run 45.000 s behind the GNSS clock (...),
      but the estimator does not confirm it: log-likelihood -201 as corrected over 180 fixes
      (-67 per minute); the data are used as given
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.config import RunConfig
from ..core.earth import normal_gravity
from ..core.errors import InputError, warn_data
from ..core.recording import ImuData, RecordedRun
from . import gnsscheck, unitcheck
from .corrections import mount_proposal, mounting_rpy_deg, offset_proposal
from .findings import Finding
from .views import measure_motion, rest_rate

CHECKS = (
    "time_units",
    "fix_count",
    "heights",
    "accel_units",
    "gyro_units",
    "latlon",
    "init_position",
    "time_offset",
    "mounting",
)
REPAIR_MODES = ("never", "auto")


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
            raise InputError(
                "config", f'[checks] repair must be "never" or "auto", got {c["repair"]!r}'
            )
        if not isinstance(c["skip"], str):
            raise InputError(
                "config",
                f'[checks] skip must be a string of check names, e.g. "mounting", got {c["skip"]!r}',
            )
        skip = frozenset(w for w in c["skip"].replace(",", " ").split())
        bad = sorted(skip - set(CHECKS))
        if bad:
            raise InputError(
                "config",
                f"[checks] skip: unknown check(s) {', '.join(bad)} (known: {', '.join(CHECKS)})",
            )
        m = cfg["mounting"]
        return cls(
            c["repair"] == "auto",
            skip,
            m["imu_time_offset_s"] == "auto",
            m["imu_to_body_rpy_deg"] == "auto",
        )


def file_names(run: RecordedRun) -> tuple[str, str, str]:
    """Where the IMU, the fixes and the initial state came from, for messages: the files of a CSV
    run directory, else the run's ``where``."""
    if run.meta.get("source") == "csv":
        root = Path(run.where)
        return str(root / "imu.csv"), str(root / "gnss.csv"), str(root / "init.json")
    return run.where, run.where, run.where


@dataclass
class CheckResult:
    """What :func:`check_run` found.

    Attributes
    ----------
    run : RecordedRun
        As given (nothing is corrected without the estimator's verdict).
    cfg : RunConfig
        With an ``"auto"`` offset or mounting that the data leave as it is written as numbers.
    findings : list of Finding
        Warnings (one view alone) and what the ``"auto"`` keys settled.
    proposal : Finding or None
        The first correction the views propose, for the estimator to judge.
    """

    run: RecordedRun
    cfg: RunConfig
    findings: list
    proposal: Finding | None = None


class _Proposed(Exception):
    """Stops :func:`check_run` at a proposal."""

    def __init__(self, finding: Finding):
        self.finding = finding


def consider(finding: Finding | None, policy: Policy, findings: list, declined=frozenset()) -> None:
    """What the data alone decide about a finding (module notes): nothing, a note for a warning (one
    view), or a refusal of data that cannot be estimated; a proposal settled before (``declined``
    holds its key, or its check's name) is not made again."""
    if (
        finding is None
        or finding.check in policy.skip
        or finding.key in declined
        or finding.check in declined
    ):
        return
    if finding.repair is not None:
        raise _Proposed(finding)
    if finding.impossible:
        raise InputError(finding.where, f"{finding.problem}; {finding.fix}")
    finding.action = (
        finding.action or "noted"
    )  # the caller warns of notes (once, however often the checks run)
    findings.append(finding)


def settle_now(run: RecordedRun, finding: Finding | None, policy: Policy) -> RecordedRun:
    """For a source that cannot wait for the estimator (IMU stamps that never meet the fixes: as
    given there is nothing to estimate): repair (with a warning) when the policy allows it, else
    raise."""
    if finding is None or finding.check in policy.skip:
        return run
    if finding.repair is not None and policy.repair:
        warn_data(
            finding.where, f'{finding.problem}; {finding.repaired} ([checks] repair = "auto")'
        )
        return finding.repair(run)
    hint = (
        ', or set [checks] repair = "auto" to let gnssacc do it'
        if finding.repair is not None
        else ""
    )
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
    return settle_now(holder, finding, policy).imu


def local_gravity(run: RecordedRun) -> float:
    """Normal gravity at the fixes' median latitude and height [m/s^2] (heights clipped to the
    range of roads, so that a height in the wrong units cannot move it)."""
    g = run.gnss
    return float(
        normal_gravity(float(np.median(g.lat)), float(np.clip(np.median(g.h), -1000.0, 10000.0)))
    )


def _auto_offset_note(cfg: RunConfig, m, where: str, findings: list, settled: bool) -> RunConfig:
    """``imu_time_offset_s = "auto"`` with nothing (more) to propose: 0 s kept, said so unless a
    verdict on the proposal said it already (``settled``)."""
    if not settled:
        text = (
            "the recording has too little motion to measure it; 0 s assumed"
            if not m.offset.determined
            else f"measured {m.offset.text()}, 0 s kept"
        )
        findings.append(
            Finding(
                "time_offset",
                where,
                f'[mounting] imu_time_offset_s = "auto": {text}',
                action="noted",
                details={"offset_s": 0.0},
            )
        )
    return cfg.with_values({"mounting": {"imu_time_offset_s": 0.0}}, "input checks")


def _motion_steps(run, cfg, policy, findings, declined, imu_w, gnss_w) -> RunConfig:
    """Steps 2-4 of the module notes (raise :class:`_Proposed` at a proposal)."""
    m = measure_motion(run)
    consider(gnsscheck.latlon_radians(run, m.fit, gnss_w), policy, findings, declined)
    consider(unitcheck.gyro_units(m.turn, rest_rate(run, m), imu_w), policy, findings, declined)
    consider(
        gnsscheck.mirror_image(m.fit, m.turn, m.lateral, gnss_w, imu_w, run.gnss.lat, run.gnss.lon),
        policy,
        findings,
        declined,
    )
    consider(gnsscheck.gnss_scale(m.fit, gnss_w), policy, findings, declined)
    if "time_offset" not in policy.skip:
        offset = offset_proposal(run, cfg, m, policy.offset_auto, imu_w)
        consider(offset, policy, findings, declined)
        if policy.offset_auto:  # nothing (more) to propose: the offset stays 0 s
            cfg = _auto_offset_note(cfg, m, imu_w, findings, "time_offset" in declined)
    if "mounting" not in policy.skip:
        mount, text = mount_proposal(run, cfg, m, policy.mount_auto, imu_w)
        consider(mount, policy, findings, declined)
        if policy.mount_auto:  # nothing (more) to propose: the axes stay as they are
            if "mounting" not in declined:
                findings.append(
                    Finding(
                        "mounting",
                        imu_w,
                        text,
                        action="applied",
                        details={"rpy_deg": [0.0, 0.0, 0.0]},
                    )
                )
            cfg = cfg.with_values(
                {"mounting": {"imu_to_body_rpy_deg": mounting_rpy_deg(np.eye(3))}}, "input checks"
            )
    return cfg


def check_run(run: RecordedRun, cfg: RunConfig, declined=frozenset()) -> CheckResult:
    """Check a run against itself before estimation (module notes), up to the first proposal.

    Parameters
    ----------
    run : RecordedRun
        As loaded (validated), or as corrected by proposals the estimator confirmed.
    cfg : RunConfig
        ``[checks]`` and ``[mounting]``.
    declined : set of str
        Keys of proposals the estimator did not confirm (:attr:`Finding.key`): not made again.

    Raises
    ------
    InputError
        Data that cannot be estimated at all, naming the file, what the data show and the fix.
    """
    policy = Policy.from_config(cfg)
    imu_w, gnss_w, init_w = file_names(run)
    findings: list = []
    try:
        for check in (
            lambda r: unitcheck.imu_time_units(r.imu.t, r.gnss.t, imu_w),
            lambda r: gnsscheck.gnss_time_units(r.gnss.t, gnss_w),
            lambda r: gnsscheck.fix_count(r.gnss.t, r.t_start, r.t_end, gnss_w),
            lambda r: gnsscheck.heights(r.gnss.h, gnss_w, declined),
            lambda r: unitcheck.accel_units(r.imu, local_gravity(r), imu_w),
        ):
            consider(check(run), policy, findings, declined)
        cfg = _motion_steps(run, cfg, policy, findings, declined, imu_w, gnss_w)
        consider(gnsscheck.init_position(run, init_w), policy, findings, declined)
    except _Proposed as p:
        return CheckResult(run, cfg, findings, p.finding)
    return CheckResult(run, cfg, findings)
