"""The input checks' proposals settled by the estimator (:mod:`gnssacc.checks.plausibility` proposes,
:mod:`gnssacc.prepare.judge` proves).

:func:`settled` runs the checks up to their first proposal, asks the estimator for its verdict on
it, and acts on the verdict: a decisive one applies the correction (recorded with its evidence:
the caller states it) unless the configuration asks for a refusal (``[checks] on_proof =
"refuse"``) or the data cannot tell the correction from another
(:attr:`~gnssacc.checks.findings.Finding.alternatives`): then it refuses the data, with the
evidence both ways; a refuted or inconclusive one leaves the data as given and is only recorded
(``metrics.json``, the report), never warned of. The proposal is not made again. Then the checks
run again on the run as it now is, until nothing more is proposed; last, the truth is checked
against the fixes as the corrections left both (:func:`gnssacc.checks.truthcheck.checked_truth`).
A recording with nothing to propose costs no EKF pass here, and the start made for a verdict
(quality, stationary spans, yaw bank) is handed on, so the preparation makes none of them twice.
"""

from __future__ import annotations

import numpy as np

from ..checks.corrections import offset_problem
from ..checks.findings import Finding
from ..checks.plausibility import CHECKS, Policy, check_run, file_names
from ..checks.truthcheck import checked_truth
from ..core.config import RunConfig
from ..core.errors import InputError, warn_data
from ..core.recording import RecordedRun
from .clock import evaluate_offset, offset_sigma, unseen_offset
from .filter_pass import FilterPass
from .judge import MIN_FIXES, Verdict, compare, innovations, judge
from .start import StartPieces, start_pieces
from .velocity_time import evaluate_lag

#: Most proposals settled for one run (each check proposes at most once).
MAX_ROUNDS = len(CHECKS) + 2


class _Start:
    """The start of the run as given, made when a verdict first needs it (and kept)."""

    def __init__(self, run, cfg, filter_pass, pieces: StartPieces | None = None):
        self.run, self.cfg, self.filter_pass, self.pieces = run, cfg, filter_pass, pieces

    def __call__(self) -> StartPieces:
        if self.pieces is None:
            self.pieces = start_pieces(self.run, self.cfg, self.filter_pass)
        return self.pieces


def _fixes_in_imu_span(run: RecordedRun) -> int:
    return int(((run.gnss.t >= run.t_start) & (run.gnss.t <= run.t_end)).sum())


def _evaluate(
    run, cfg, finding: Finding, base, filter_pass
) -> tuple[Verdict, RecordedRun, StartPieces | None]:
    """The verdict on a proposal, the corrected run, and its start when one was made (``base``:
    a callable giving the start of ``run`` as given, made once)."""
    if not finding.details.get("estimable", True) or _fixes_in_imu_span(run) < MIN_FIXES:
        # As given there is nothing to estimate (stamps no IMU writes, fixes that meet no IMU data)
        corrected = finding.repair(run)
        pieces = start_pieces(corrected, cfg, filter_pass)
        inn = innovations(corrected, cfg, pieces, filter_pass)
        return compare(None, inn), corrected, pieces
    base = base()
    if finding.check == "time_offset":
        verdict, corrected, est = evaluate_offset(run, cfg, finding, base, filter_pass)
        d = finding.details
        if est is not None:  # the message tells the refined offset
            d["measured_s"], d["sigma_s"] = est.offset_s, est.sigma_s
            finding.problem = offset_problem(est, d["configured_s"], d["auto"])
            finding.fix = f'set [mounting] imu_time_offset_s = {d["configured_s"] + est.offset_s:.3f} (or "auto")'
        d["offset_s"] = (
            d.get("measured_s", d["stage1_s"]) if verdict.decisive else 0.0
        )  # what is applied
        total = d["configured_s"] + d.get("measured_s", d["stage1_s"])
        finding.repaired = f"imu_time_offset_s = {total:.3f} (the IMU and the streams on its clock)"
        return verdict, corrected, None
    if finding.check == "velocity_time":
        return evaluate_lag(run, cfg, finding, base, filter_pass)
    corrected = finding.repair(run)
    pieces = start_pieces(corrected, cfg, filter_pass)
    return (
        judge(
            run,
            corrected,
            cfg,
            base,
            pieces,
            filter_pass,
            finding.details.get("log_jacobian_per_fix", 0.0),
            vehicle=finding.check == "mounting",
        ),
        corrected,
        pieces,
    )


def _applied_cfg(cfg: RunConfig, finding: Finding) -> RunConfig:
    """The configuration after an applied offset or mounting (the values now in effect)."""
    if finding.check == "time_offset":
        value = finding.details.get("measured_s", finding.details["stage1_s"])
        total = float(finding.details.get("configured_s", 0.0)) + float(value)
        return cfg.with_values({"mounting": {"imu_time_offset_s": round(total, 4)}}, "input checks")
    if finding.check == "mounting":
        return cfg.with_values(
            {"mounting": {"imu_to_body_rpy_deg": finding.details["rpy_deg"]}}, "input checks"
        )
    return cfg


def _refuse(finding: Finding, verdict: Verdict, policy: Policy) -> InputError:
    """The refusal of a proven correction: ambiguous, or the configuration asks for it."""
    if finding.alternatives:
        others = " or ".join(finding.alternatives)
        return InputError(
            finding.where,
            f"{finding.problem}; the estimator proves the data as given wrong ({verdict.text()}), "
            f"but the data cannot tell {finding.repaired} from {others}: not guessed; "
            f"{finding.fix}",
        )
    return InputError(
        finding.where,
        f"{finding.problem}; {finding.fix}; the estimator proves it: {verdict.text()}; refused as "
        f"{policy.refusal_reason(finding.check)}",
    )


def _note_once(findings: list, seen: set, new: list) -> None:
    """Warn of the notes not warned of in an earlier round, and keep them."""
    for f in new:
        if f.action == "noted" and f.key not in seen:
            seen.add(f.key)
            findings.append(f)
            warn_data(f.where, f"{f.problem}; {f.fix}" if f.fix else f.problem)
        elif f.action != "noted":
            findings.append(f)


def _settle(f: Finding, verdict: Verdict, policy: Policy) -> bool:
    """Record the verdict on ``f`` and say whether to apply it; raise a refusal (module notes)."""
    f.details["verdict"] = verdict.to_dict()
    f.details["evidence"] = verdict.text()
    if verdict.decisive and (f.alternatives or not policy.allows(f.check)):
        f.action = "refused"
        raise _refuse(f, verdict, policy)
    if verdict.decisive:
        f.action = "applied" if f.check in ("time_offset", "mounting") else "repaired"
        return True
    # The stamps, units or axes as given are as likely or more (refuted), or the evidence does not
    # decide: the data are used as given, and the verdict is recorded, not warned of.
    f.action = "refuted" if verdict.refuted else "not confirmed"
    return False


def settled(
    run: RecordedRun, cfg: RunConfig, filter_pass: FilterPass
) -> tuple[RecordedRun, RunConfig, list, StartPieces | None]:
    """The run and configuration after the checks' proposals were settled (module notes).

    Returns
    -------
    run, cfg
        As corrected by the proven corrections (and without a truth that disagrees with the fixes).
    findings : list of Finding
        Everything the checks said and did, with the estimator's verdicts (``details["verdict"]``,
        ``details["evidence"]``), and the truth's check when it failed.
    start : StartPieces or None
        The start of the final run, when a verdict needed it (else the caller makes it).

    Raises
    ------
    InputError
        A proven problem the configuration does not let gnssacc correct, or one the data cannot
        tell from another, with the evidence; or data that cannot be estimated at all.
    """
    policy = Policy.from_config(cfg)
    findings, seen, declined, base = [], set(), set(), None
    motion = None  # the views of the run as it is: measured once, again only for a corrected run
    for _ in range(MAX_ROUNDS):
        res = check_run(run, cfg, frozenset(declined), motion)
        motion = res.motion
        _note_once(findings, seen, res.findings)
        f = res.proposal
        if f is None:
            cfg = res.cfg
            break
        # One verdict per proposal; the offset and the mounting are measured again after a change,
        # so one verdict per check.
        declined.add(f.check if f.check in ("time_offset", "mounting") else f.key)
        start = _Start(run, cfg, filter_pass, base)
        verdict, corrected, pieces = _evaluate(run, cfg, f, start, filter_pass)
        base = start.pieces
        if _settle(f, verdict, policy):
            run, cfg, base, motion = corrected, _applied_cfg(cfg, f), pieces, None
        findings.append(f)
    return _with_truth_checked(run, cfg, policy, findings) + (base,)


def clock_bound(
    run: RecordedRun, cfg: RunConfig, findings: list, pieces: StartPieces, filter_pass: FilterPass
) -> Finding | None:
    """How well the data tell the IMU-to-GNSS clock offset, and how large one could go unseen
    (:func:`gnssacc.prepare.clock.unseen_offset`), as a finding of the ``time_offset`` check
    (action ``"bound"``): from the offset's verdict when one was made, else from the likelihood's
    curvature at the stamps as given (a few EKF passes from the run's start ``pieces``). ``None``
    when the check is skipped or too few fixes meet the IMU."""
    if "time_offset" in Policy.from_config(cfg).skip or _fixes_in_imu_span(run) < MIN_FIXES:
        return None
    judged = [f for f in findings if f.check == "time_offset" and "sigma_s" in f.details]
    if judged:
        d = judged[-1].details
        sigma, minutes = float(d["sigma_s"]), float(d["verdict"]["minutes"])
    else:
        sigma, minutes = offset_sigma(run, cfg, pieces, filter_pass)
    unseen = unseen_offset(sigma, minutes)
    text = (
        f"the IMU-to-GNSS clock offset is told to +-{sigma:.3f} s (1-sigma, EKF likelihood): an "
        f"offset below {unseen:.2f} s cannot be proven and could go unseen"
        if np.isfinite(unseen)
        else "the motion does not show the IMU-to-GNSS clock offset (a 1 s shift changes the EKF "
        "likelihood by less than 2): an offset of a second or more could go unseen"
    )
    return Finding(
        "time_offset",
        file_names(run)[0],
        text,
        action="bound",
        details={
            "sigma_s": sigma if np.isfinite(sigma) else None,
            "unseen_s": unseen if np.isfinite(unseen) else None,
        },
    )


def _with_truth_checked(run, cfg, policy: Policy, findings: list) -> tuple:
    """``(run, cfg, findings)`` after the truth's check against the fixes (unless skipped)."""
    if "truth" in policy.skip:
        return run, cfg, findings
    run, truth_finding = checked_truth(run, cfg)
    return run, cfg, findings + ([truth_finding] if truth_finding is not None else [])
