"""The input checks' proposals settled by the estimator (:mod:`gnssacc.checks.plausibility` proposes,
:mod:`gnssacc.prepare.judge` proves).

:func:`settled` runs the checks up to their first proposal, asks the estimator for its verdict on
it, and acts on the verdict: a decisive one applies the correction when the configuration allows
it and otherwise refuses the data, with the evidence both ways; an inconclusive one is a
warning, and the data are used as given; a refuted one (the data as given are as likely or
more) is only recorded (``metrics.json``). The proposal is not made again. Then the checks run
again on the run as it now is, until nothing more is proposed. A recording with nothing to propose
costs no EKF pass here, and the start made for a verdict (quality, stationary spans, yaw bank) is
handed on, so the preparation makes none of them twice.
"""

from __future__ import annotations

from ..checks.corrections import offset_problem
from ..checks.findings import Finding
from ..checks.plausibility import CHECKS, Policy, check_run
from ..core.config import RunConfig
from ..core.errors import InputError, warn_data
from ..core.recording import RecordedRun
from .clock import evaluate_offset
from .filter_pass import FilterPass
from .judge import MIN_FIXES, Verdict, compare, innovations, judge
from .start import StartPieces, start_pieces

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
        return verdict, corrected, None
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


def _allowed(finding: Finding, policy: Policy) -> bool:
    """Whether the configuration lets a confirmed correction be applied."""
    if finding.check == "time_offset":
        return policy.offset_auto
    if finding.check == "mounting":
        return policy.mount_auto
    return policy.repair and finding.repairable


def _applied_cfg(cfg: RunConfig, finding: Finding) -> RunConfig:
    """The configuration after an applied offset or mounting (the values now in effect)."""
    if finding.check == "time_offset":
        value = finding.details.get("measured_s", finding.details["stage1_s"])
        return cfg.with_values(
            {"mounting": {"imu_time_offset_s": round(float(value), 4)}}, "input checks"
        )
    if finding.check == "mounting":
        return cfg.with_values(
            {"mounting": {"imu_to_body_rpy_deg": finding.details["rpy_deg"]}}, "input checks"
        )
    return cfg


def _refuse(finding: Finding, verdict: Verdict) -> InputError:
    hint = (
        ', or set [checks] repair = "auto" to let gnssacc do it'
        if finding.repairable and finding.check not in ("time_offset", "mounting")
        else ""
    )
    return InputError(
        finding.where,
        f"{finding.problem}; {finding.fix}{hint}; the estimator confirms it: {verdict.text()}",
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


def settled(
    run: RecordedRun, cfg: RunConfig, filter_pass: FilterPass
) -> tuple[RecordedRun, RunConfig, list, StartPieces | None]:
    """The run and configuration after the checks' proposals were settled (module notes).

    Returns
    -------
    run, cfg
        As corrected by confirmed corrections the configuration allows.
    findings : list of Finding
        Everything the checks said and did, with the estimator's verdicts (``details["verdict"]``).
    start : StartPieces or None
        The start of the final run, when a verdict needed it (else the caller makes it).

    Raises
    ------
    InputError
        A confirmed problem the configuration does not let gnssacc correct, with the evidence; or
        data that cannot be estimated at all.
    """
    policy = Policy.from_config(cfg)
    findings, seen, declined, base = [], set(), set(), None
    for _ in range(MAX_ROUNDS):
        res = check_run(run, cfg, frozenset(declined))
        _note_once(findings, seen, res.findings)
        f = res.proposal
        if f is None:
            return run, res.cfg, findings, base
        # One verdict per proposal; the offset and the mounting are measured again after a change,
        # so one verdict per check.
        declined.add(f.check if f.check in ("time_offset", "mounting") else f.key)
        start = _Start(run, cfg, filter_pass, base)
        verdict, corrected, pieces = _evaluate(run, cfg, f, start, filter_pass)
        base = start.pieces
        f.details["verdict"] = verdict.to_dict()
        if verdict.decisive and not _allowed(f, policy):
            f.action = "refused"
            raise _refuse(f, verdict)
        if verdict.decisive:
            f.action = "applied" if f.check in ("time_offset", "mounting") else "repaired"
            warn_data(
                f.where, f"{f.problem}; {f.repaired}, confirmed by the estimator: {verdict.text()}"
            )
            run, cfg, base = corrected, _applied_cfg(cfg, f), pieces
        elif (
            verdict.refuted
        ):  # the stamps, units or axes as given are the likelier: nothing to warn of
            f.action = "refuted"
        else:
            f.action = "not confirmed"
            warn_data(
                f.where,
                f"{f.problem}, but the estimator does not confirm it: {verdict.text()}; the data are "
                f"used as given",
            )
        findings.append(f)
    return run, cfg, findings, base
