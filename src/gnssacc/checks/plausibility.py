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
6. The GNSS velocities against the fixes (:mod:`gnssacc.checks.velcheck`), when the run has
   them: ``velocity_frame``: ENU written as NED, the vertical sign; ``velocity_time``: their time
   tags against the fixes'; ``velocity``: an axis (north, east, down) on which they contradict
   the fixes (a warning naming it).
7. ``truth``: once every proven correction is applied, the truth against the fixes
   (:mod:`gnssacc.checks.truthcheck`, run by the preparation stage): a truth that disagrees is
   reported and not scored.

What happens with a finding (:func:`consider`)
    A check proposes; only the estimator proves. A finding with a correction (a ``repair``) is a
    *proposal*: :func:`check_run` stops at the first one and returns it, and the preparation stage
    runs the EKF on the data as given and as corrected (:mod:`gnssacc.prepare.judge`). A proven
    correction is applied and stated (the run's header line, ``metrics.json``, the report), unless
    the configuration asks for a refusal (``[checks] on_proof = "refuse"``, ``--strict``): then the
    run stops with the evidence both ways in one error line. A correction the data cannot tell from
    another (:attr:`~gnssacc.checks.findings.Finding.alternatives`) is refused either way, naming
    both. A refuted or inconclusive proposal leaves the data as given and is recorded
    (``metrics.json``, the report), not warned of; it is not made again. A finding without a
    correction is one view alone: a warning. Only data that cannot be estimated at all (no fixes
    in the IMU's span, fix stamps no receiver writes) are refused outright.

Configuration
    ``[checks] on_proof = "apply"`` (default) or ``"refuse"``; ``[checks] repair = "auto"``
    (default) or ``"never"`` (unit and layout repairs refused even when proven); ``[checks] skip =
    "name, name"``: checks to leave out (names above). ``[mounting] imu_time_offset_s = "auto"``
    and ``imu_to_body_rpy_deg = "auto"`` propose every measured offset and mounting (and apply a
    proven one whatever ``on_proof`` says); with numbers (the default 0 and [0, 0, 0]) only a
    contradiction is proposed: a plausible mounting (within 20 deg of the configured one: road
    grade, sitting attitude) or offset (within 50 ms or 3 sigma of it) is not.

Example messages (with ``--strict``; by default the first is applied and stated)::

    gnssacc: error: run/imu.csv: the accelerometer reads 1.001 on average (median norm of the
      specific force), where local gravity is 9.795 m/s^2: the ax, ay, az columns are in g;
      multiply them by 9.80665; the estimator proves it: log-likelihood +48210 as corrected over
      110 fixes (26300 per minute); refused as [checks] on_proof = "refuse" (--strict) asks
    gnssacc: error: run/gnss.csv: the fixes' track is the mirror image of the motion the IMU
      measured (...); the estimator proves the data as given wrong (...), but the data cannot tell
      swapped latitude and longitude from a lost sign of the latitude (hemisphere) or a lost sign
      of the longitude: not guessed; check the lat_deg and lon_deg columns
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.config import RunConfig
from ..core.earth import normal_gravity
from ..core.errors import InputError, warn_data
from ..core.recording import ImuData, RecordedRun
from . import gnsscheck, unitcheck, velcheck
from .corrections import mount_proposal, mounting_rpy_deg, offset_proposal
from .findings import Finding
from .views import Motion, measure_motion, rest_rate

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
    "velocity_frame",
    "velocity_time",
    "velocity",
    "truth",
)
REPAIR_MODES = ("never", "auto")
ON_PROOF = ("apply", "refuse")


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
    apply : bool
        ``[checks] on_proof = "apply"``: a proven correction is applied (else refused).
    """

    repair: bool
    skip: frozenset
    offset_auto: bool
    mount_auto: bool
    apply: bool = True

    def allows(self, check: str) -> bool:
        """Whether a proven correction of ``check`` may be applied (module notes)."""
        if check == "time_offset":
            return self.offset_auto or self.apply
        if check == "mounting":
            return self.mount_auto or self.apply
        return self.apply and self.repair

    def refusal_reason(self, check: str) -> str:
        """Why :meth:`allows` says no, for the error line."""
        if self.apply and check not in ("time_offset", "mounting"):
            return '[checks] repair = "never" asks for it'
        return '[checks] on_proof = "refuse" (--strict) asks for it'

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "Policy":
        """Read and check ``[checks]`` and the ``"auto"`` mounting keys; ``InputError`` naming the key."""
        c = cfg["checks"]
        if c["repair"] not in REPAIR_MODES:
            raise InputError(
                "config", f'[checks] repair must be "never" or "auto", got {c["repair"]!r}'
            )
        if c["on_proof"] not in ON_PROOF:
            raise InputError(
                "config", f'[checks] on_proof must be "apply" or "refuse", got {c["on_proof"]!r}'
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
            c["on_proof"] == "apply",
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
    motion : Motion or None
        The views of the run's motion (:func:`gnssacc.checks.views.measure_motion`), when the
        checks came so far: a later call on the same run may take them.
    """

    run: RecordedRun
    cfg: RunConfig
    findings: list
    proposal: Finding | None = None
    motion: Motion | None = None


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
    given there is nothing to estimate, and one unit alone lines them up): repair, with a notice
    of what was reconstructed, when the policy allows it, else raise."""
    if finding is None or finding.check in policy.skip:
        return run
    if finding.repair is not None and policy.allows(finding.check):
        warn_data(
            finding.where,
            f"{finding.problem}; {finding.repaired} (as given the IMU never meets the fixes)",
        )
        return finding.repair(run)
    why = (
        f"; not repaired as {policy.refusal_reason(finding.check)}"
        if finding.repair is not None
        else ""
    )
    raise InputError(finding.where, f"{finding.problem}; {finding.fix}{why}")


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


def _motion_steps(run, cfg, m: Motion, policy, findings, declined, imu_w, gnss_w) -> RunConfig:
    """Steps 2-4 of the module notes on the views ``m`` of the run (raise :class:`_Proposed` at a
    proposal)."""
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
                        action="kept",  # measured: the axes as they are
                        details={"rpy_deg": [0.0, 0.0, 0.0]},
                    )
                )
            cfg = cfg.with_values(
                {"mounting": {"imu_to_body_rpy_deg": mounting_rpy_deg(np.eye(3))}}, "input checks"
            )
    return cfg


def _velocity_steps(run, cfg, policy, findings, declined, gnss_w) -> None:
    """Step 6 of the module notes (raise :class:`_Proposed` at a proposal); nothing to do, and
    nothing computed, without velocities."""
    if not velcheck.in_use(run, cfg):
        return
    for check, step in (
        ("velocity_frame", velcheck.frame_proposal),
        ("velocity_time", velcheck.time_proposal),
        ("velocity", velcheck.axis_contradictions),
    ):
        if check not in policy.skip:
            consider(step(run, cfg, gnss_w), policy, findings, declined)


def check_run(
    run: RecordedRun, cfg: RunConfig, declined=frozenset(), motion: Motion | None = None
) -> CheckResult:
    """Check a run against itself before estimation (module notes), up to the first proposal.

    Parameters
    ----------
    run : RecordedRun
        As loaded (validated), or as corrected by proposals the estimator confirmed.
    cfg : RunConfig
        ``[checks]`` and ``[mounting]``.
    declined : set of str
        Keys of proposals the estimator did not confirm (:attr:`Finding.key`): not made again.
    motion : Motion, optional
        The views of this same run from an earlier call (:attr:`CheckResult.motion`; they depend
        on the run alone), else measured here.

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
        motion = motion if motion is not None else measure_motion(run)
        cfg = _motion_steps(run, cfg, motion, policy, findings, declined, imu_w, gnss_w)
        consider(gnsscheck.init_position(run, init_w), policy, findings, declined)
        _velocity_steps(run, cfg, policy, findings, declined, gnss_w)
    except _Proposed as p:
        return CheckResult(run, cfg, findings, p.finding, motion)
    return CheckResult(run, cfg, findings, motion=motion)
