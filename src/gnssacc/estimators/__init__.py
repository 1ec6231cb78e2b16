"""The estimators: strapdown mechanization, the Kalman update, measurement models, the paper's EKF,
the GNSS least-squares acceleration, and the GTSAM iSAM2 fixed-lag smoother with its marginals.

Inputs: a prepared recording (:mod:`gnssacc.prepare`) and the estimator's settings. Outputs: one
:class:`~gnssacc.core.solution.NavSolution` per method (per-epoch state, sigmas, statistics such as
innovation counts, NIS and log-likelihood). The GTSAM factors live in :mod:`gnssacc.factors` (the
repository's ``factors/`` folder) at this stage's level.
"""
