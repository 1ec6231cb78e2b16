"""The filter pass the preparation stage asks for its likelihood-based decisions.

Several decisions before estimation need an estimator's verdict: the yaw bank scores start
hypotheses, the noise identification maximises an innovation likelihood, a proposed correction
(clock offset, units, mounting) is kept only when the corrected data are decisively more likely.
They take the pass as an argument (:func:`gnssacc.prepare.passes.filter_pass`, the EKF, from
:mod:`gnssacc.pipeline`), so that each decision can be tested with any pass (one that counts its
calls, or a cheaper one). :class:`FilterPass` says what such a pass must do.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..core.recording import InitialState, RecordedRun
from ..core.solution import NavSolution


class FilterPass(Protocol):
    """One EKF pass over a run (the signature of :func:`gnssacc.estimators.ekf.run_ekf`).

    Parameters
    ----------
    run : RecordedRun
    cfg : gnssacc.core.config.RunConfig
        The noise model and settings of this pass.
    method : str
        ``"ekf"`` (position updates) or ``"ekf-acc"`` (and the GNSS-derived acceleration).
    init : InitialState
        Where the pass starts.
    quality, stationary
        The IMU quality report and stationary spans (``None``: no stationary updates).
    output_times : ndarray
        Epochs to report (empty: statistics only).
    record_innovations : bool
        Keep every update's time, NIS and log-likelihood in ``stats``.
    t_stop : float, optional
        Stop after this time [s].
    cov_every : int
        Propagate the covariance every this many IMU samples.
    store_P : bool
        Keep the full covariance at every output epoch.

    Returns
    -------
    NavSolution
        Its ``stats`` hold the innovation log-likelihood per update kind (``loglik_pos``, ...),
        the NIS and, with ``record_innovations``, the series.
    """

    def __call__(
        self,
        run: RecordedRun,
        cfg,
        method: str = "ekf",
        *,
        init: InitialState | None = None,
        quality=None,
        stationary=None,
        output_times: np.ndarray | None = None,
        record_innovations: bool = False,
        t_stop: float | None = None,
        cov_every: int = 1,
        store_P: bool = False,
    ) -> NavSolution: ...
