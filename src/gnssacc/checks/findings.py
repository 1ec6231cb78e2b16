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
        ``RecordedRun -> RecordedRun``: the repair the evidence allows, ``None`` when it is not
        unambiguous (then the finding is always an error).
    repaired : str
        What the repair does, for the warning (e.g. "multiplied ax, ay, az by 9.80665").
    action : str
        Filled in by :func:`gnssacc.checks.plausibility.check_run`: ``"repaired"``, ``"applied"`` (a
        measured ``"auto"`` mounting or offset) or ``"noted"``.
    details : dict
        Numbers behind the verdict (JSON-friendly), for reports and tests.
    """

    check: str
    where: str
    problem: str
    fix: str = ""
    repair: Callable | None = None
    repaired: str = ""
    action: str = ""
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"check": self.check, "where": self.where, "problem": self.problem, "fix": self.fix,
                "action": self.action, "details": self.details}
