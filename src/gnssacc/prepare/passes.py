"""Estimator passes from the preparation stage: the EKF pass its decisions use, and the
estimators run on a recording alone (their start found here when not given).

The estimators take a start and never look for one; the preparation finds it (the yaw bank, the
tuner and the input checks' likelihood stage all run EKF passes). :func:`filter_pass` is the
pass those decisions use by default (:class:`gnssacc.prepare.filter_pass.FilterPass`);
:func:`run_ekf` and :func:`run_smoother` prepare what a script or a test did not give (the IMU
quality report, the start: :func:`gnssacc.prepare.start.start_for`) and run the estimator.
"""

from __future__ import annotations

from ..core.recording import InitialState, RecordedRun
from ..core.solution import NavSolution
from ..estimators import ekf, kernels
from .start import start_for


def filter_pass(*args, **kwargs) -> NavSolution:
    """One EKF pass (:func:`gnssacc.estimators.ekf.run_ekf`'s arguments) once the kernels are ready
    (compiled or loaded in the background: a first run waits here, the steps before it do not)."""
    kernels.warm_up()
    return ekf.run_ekf(*args, **kwargs)


def run_ekf(
    run: RecordedRun,
    settings,
    method: str = "ekf",
    *,
    init: InitialState | None = None,
    quality=None,
    stationary=None,
    **options,
) -> NavSolution:
    """:func:`gnssacc.estimators.ekf.run_ekf` with its start found when not given: the run's own,
    else the yaw bank's for this run alone (which needs a run configuration as ``settings``)."""
    init, quality = start_for(run, settings, init, quality, stationary, filter_pass=filter_pass)
    return ekf.run_ekf(
        run, settings, method, init=init, quality=quality, stationary=stationary, **options
    )


def run_smoother(
    run: RecordedRun,
    settings,
    method: str = "smoother",
    *,
    init: InitialState | None = None,
    quality=None,
    stationary=None,
    **options,
) -> dict[str, NavSolution]:
    """:func:`gnssacc.estimators.smoother.run_smoother` with its start found when not given (as
    :func:`run_ekf`)."""
    from ..estimators import smoother  # gtsam only when a smoother runs

    init, quality = start_for(run, settings, init, quality, stationary, filter_pass=filter_pass)
    return smoother.run_smoother(
        run, settings, method, init=init, quality=quality, stationary=stationary, **options
    )
