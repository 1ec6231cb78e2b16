"""What an input check found (:mod:`gnssacc.checks.plausibility`): the problem, the fix, and the repair
the evidence allows."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable


@dataclass
class Finding:
    """One finding of an input check.

    Attributes
    ----------
    check : str
        The check's name (one of :data:`gnssacc.checks.plausibility.CHECKS`; ``[checks] skip`` takes it).
    where : str
        The file (or source) named in the message.
    problem : str
        What the data show and the likely cause, one line without a final period.
    fix : str
        What the user can do about it (edit the file, a configuration line).
    repair : callable or None
        ``RecordedRun -> RecordedRun``: the correction the views propose. It is a *proposal*: the
        preparation stage runs the EKF on the data as given and as corrected and acts only when
        the corrected data are decisively more likely (:mod:`gnssacc.prepare.judge`). ``None``:
        nothing to propose (then the finding is a warning, or a refusal when ``impossible``).
    repaired : str
        What the repair does, for the warning (e.g. "multiplied ax, ay, az by 9.80665").
    action : str
        Filled in as the finding is settled: ``"repaired"`` (units, layout), ``"applied"`` (a
        measured mounting or offset), ``"refused"``, ``"refuted"`` or ``"not confirmed"`` (the
        data were used as given), ``"noted"`` (one view alone: a warning), ``"kept"`` (an
        ``"auto"`` mounting measured as the axes already are), ``"not scored"`` (a truth that
        disagrees with the fixes) or ``"bound"`` (how large a clock offset could go unseen).
    details : dict
        Numbers behind the verdict (JSON-friendly), for reports and tests; once settled,
        ``verdict`` (:meth:`gnssacc.prepare.judge.Verdict.to_dict`) and ``evidence`` (its text).
    alternatives : tuple of str
        Other readings of the data that explain them as well as the proposal does (swapped and
        sign-lost coordinates are mirror images alike; an IMU whose forward axis the motion never
        showed): the estimator cannot tell them apart, so a proof is refused, naming them all,
        never guessed.
    impossible : bool
        The data as given cannot be estimated at all (no fixes in the IMU's span, fix stamps no
        receiver writes): refused without asking the estimator.
    """

    check: str
    where: str
    problem: str
    fix: str = ""
    repair: Callable | None = None
    repaired: str = ""
    action: str = ""
    details: dict = field(default_factory=dict)
    alternatives: tuple = ()
    impossible: bool = False

    @property
    def key(self) -> str:
        """Identifies the proposal, so that one the estimator did not confirm is not made again."""
        return f"{self.check}:{self.repaired or self.problem}"

    def to_dict(self) -> dict:
        return {
            "check": self.check,
            "where": self.where,
            "problem": self.problem,
            "fix": self.fix,
            "correction": self.repaired,
            "action": self.action,
            "details": self.details,
            **({"alternatives": list(self.alternatives)} if self.alternatives else {}),
        }
