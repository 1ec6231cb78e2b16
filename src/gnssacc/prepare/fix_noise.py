"""The fixes' noise from the fixes themselves, when the recording does not state it.

A log without sigma columns gets the configured ``gnss.default_sigma_m`` (3 / 3 / 5 m) from its
source. Every decision before the noise identification would then use that default: a slow
rover's 20 Hz fixes, whose scatter is centimetres, look "stationary" to a speed test that
allows 3 m of noise, and zero-velocity updates pull the estimate off while it drives. So the
default is replaced by what the fixes show: their scatter about quadratics over ~7 fixes
(:func:`gnssacc.checks.motionmatch.fix_scatter`), horizontal and vertical, floored at
:data:`MIN_SIGMA_M`. That is the *white* part of their error; what varies slowly (a receiver's
own filter, multipath) is the noise identification's business (its Gauss-Markov stage), and the
stationary test allows for it as the fixes show it (:mod:`gnssacc.prepare.fix_wander`) and for
fixes correlated from one to the next (``[stationary] gnss_corr_s``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..checks.findings import Finding
from ..checks.motionmatch import fix_scatter
from ..core.errors import warn_data
from ..core.recording import RecordedRun

#: Smallest 1-sigma taken from the scatter [m] (the tuner's smallest white fix sigma too).
MIN_SIGMA_M = 0.01
#: Fewest fixes to measure the scatter from.
MIN_FIXES = 20
#: ``run.meta["fix_sigmas"]`` of a run whose fix sigmas were measured here (what the recording
#: did not state: :mod:`gnssacc.checks.truthcheck` judges its truth by the configured default).
FROM_SCATTER = "the fixes' scatter"


def with_measured_sigmas(run: RecordedRun) -> tuple[RecordedRun, Finding | None]:
    """``run`` with its default fix sigmas replaced by the fixes' measured scatter (module notes),
    and the note saying so; unchanged (and ``None``) when the source states its sigmas."""
    g = run.gnss
    if g.sigma_stated or len(g) < MIN_FIXES:
        return run, None
    p = run.origin.to_ned(g.lat, g.lon, g.h)
    w = np.ones(len(g))
    s_h = max(fix_scatter(g.t, p[:, :2], w), MIN_SIGMA_M)
    s_v = max(fix_scatter(g.t, p[:, 2:3], w), MIN_SIGMA_M)
    old = np.median(g.sigma_ned, axis=0)
    sigma = np.tile([s_h, s_h, s_v], (len(g), 1))
    note = Finding(
        "gnss_sigma",
        run.where,
        f"the fixes state no sigmas: their scatter about local quadratics is {s_h:.3f} m horizontal, "
        f"{s_v:.3f} m vertical, used as their 1-sigma instead of gnss.default_sigma_m "
        f"{old[0]:g} / {old[1]:g} / {old[2]:g} m (the noise identification scales it)",
        action="noted",
        details={"sigma_h_m": s_h, "sigma_v_m": s_v},
    )
    warn_data(note.where, note.problem)
    measured = replace(g, sigma_ned=sigma, sigma_stated=True)
    return run.with_gnss(measured, fix_sigmas=FROM_SCATTER), note
