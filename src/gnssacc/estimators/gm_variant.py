"""The ``-gm`` methods: ``ekf`` and ``smoother`` run on the Gauss-Markov setup of the prepared
recording (:mod:`gnssacc.prepare.gauss_markov`,
:attr:`gnssacc.prepare.prepared.Prepared.gauss_markov`),
their solutions renamed."""

from __future__ import annotations

from dataclasses import replace

#: The ``-gm`` methods and the baseline each one runs as.
BASE_OF = {"ekf-gm": "ekf", "smoother-gm": "smoother"}


def run_gm(prep, method: str, show_progress: bool, runner) -> dict:
    """Run ``method`` (a key of :data:`BASE_OF`) through ``runner`` (the baseline's entry of
    :data:`gnssacc.pipeline.METHODS`) on ``prep.gauss_markov``; solutions renamed to ``method``.

    Raises
    ------
    ValueError
        The recording was prepared without the Gauss-Markov setup.
    """
    if prep.gauss_markov is None:
        raise ValueError(f"{method}: prepare the recording with gauss_markov=True")
    base = BASE_OF[method]
    gm_prep, how = prep.gauss_markov
    sols = runner(gm_prep, base, show_progress)
    out = {}
    for sid, sol in sols.items():
        new = method + sid[len(base) :]
        out[new] = replace(sol, method=new, stats={**sol.stats, "gauss_markov": how})
    return out
