"""The estimators: strapdown mechanization, the Kalman update, the paper's EKF and the GTSAM
iSAM2 fixed-lag smoother with its marginals, the state layout (:mod:`.layout`) and the aids, one
module per measurement (:mod:`.aids`).

Inputs: a run, its start and the estimator's own settings (a prepared recording from
:mod:`gnssacc.prepare` gives all three); an estimator never looks for a start. Outputs: one
:class:`~gnssacc.core.solution.NavSolution` per method (per-epoch state, sigmas, statistics such
as innovation counts, NIS and log-likelihood). The GTSAM factors live in :mod:`gnssacc.factors`
(the repository's ``factors/`` folder) at this stage's level.
"""
