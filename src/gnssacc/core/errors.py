"""Errors and warnings raised for bad input: one clear line naming the file and the problem."""

from __future__ import annotations

import warnings


class InputError(Exception):
    """Bad or unusable input data or configuration.

    Parameters
    ----------
    where : str
        The file (or source name) the problem is in.
    problem : str
        One line saying what is wrong and, where possible, how to fix it.
    """

    def __init__(self, where: str, problem: str):
        self.where = str(where)
        self.problem = problem
        super().__init__(f"{self.where}: {problem}")

    def __reduce__(self):
        # Picklable, so an error in a worker process (``gnssacc bench --jobs N``) reaches the CLI intact.
        return type(self), (self.where, self.problem)


class DataWarning(UserWarning):
    """Something in the input was repaired or dropped; the message says what and how much."""


def warn_data(where: str, problem: str) -> None:
    """Emit a :class:`DataWarning` naming the file and the repair that was made.

    One line wherever it is shown: attributed to ``gnssacc`` at line 0, so Python's default
    display prints no source line of gnssacc's own code under it (``gnssacc:0: DataWarning:
    <where>: <problem>``), and each run shows its own warnings (no registry of those seen)."""
    warnings.warn_explicit(f"{where}: {problem}", DataWarning, "gnssacc", 0, module="gnssacc")
