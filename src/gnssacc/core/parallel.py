"""How many processes a run may use for independent work (figures, likelihood passes).

``$GNSSACC_JOBS`` when set (a campaign task sets it to 1: one task, one core, the worker's
share); else the cores this process may run on (its CPU affinity), at most :data:`MAX_JOBS`;
1 where processes cannot be forked (the parallel work forks, so that the children share the
loaded recording without copying it).
"""

from __future__ import annotations

import os

#: Most processes used without ``$GNSSACC_JOBS``.
MAX_JOBS = 4
#: The environment variable that sets it.
JOBS_ENV = "GNSSACC_JOBS"


def usable_jobs() -> int:
    """Processes this run may use (module notes)."""
    env = os.environ.get(JOBS_ENV, "").strip()
    if env:
        return max(1, int(env)) if env.isdigit() else 1
    if not hasattr(os, "fork"):
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(MAX_JOBS, cores or 1))
