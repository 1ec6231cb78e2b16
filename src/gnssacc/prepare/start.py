"""Where a run starts: its IMU quality report, stationary spans, start state and yaw.

:func:`start_pieces` makes them once for a run (the preparation stage reuses them for the
estimators, and makes them again only for a correction the estimator is asked to judge).
"""
from __future__ import annotations

from dataclasses import dataclass

from ..checks.quality import QualityReport, check_imu
from ..core.config import RunConfig
from ..core.recording import InitialState, RecordedRun
from .filter_pass import FilterPass
from .stationary import StationaryReport, detect_stationary, params_from_config
from .tuning import scaled_gnss
from .yawbank import BankResult, select_yaw


@dataclass(frozen=True)
class StartPieces:
    """The quality report, stationary spans, start state and yaw bank of one run.

    Attributes
    ----------
    quality : QualityReport
    stationary : StationaryReport
    init : InitialState
    bank : BankResult or None
        ``None`` when the run gave its own start.
    """

    quality: QualityReport
    stationary: StationaryReport
    init: InitialState
    bank: BankResult | None


def start_of(run: RecordedRun, cfg: RunConfig, stationary, quality, filter_pass: FilterPass
             ) -> tuple[InitialState, BankResult | None]:
    """The run's own start, else the yaw bank's (with ``cfg``'s noise; fix sigmas as in ``run``)."""
    if run.init is not None:
        return run.init, None
    bank = select_yaw(run, cfg, stationary, quality, filter_pass=filter_pass)
    return bank.init, bank


def start_pieces(run: RecordedRun, cfg: RunConfig, filter_pass: FilterPass) -> StartPieces:
    """Quality, stationary spans and the start of ``run`` under ``cfg`` (fix sigmas times
    ``gnss.sigma_scale`` for the start, as the estimators see them)."""
    quality = check_imu(run.imu, cfg)
    stationary = detect_stationary(run.imu, run.gnss, run.origin, params_from_config(cfg))
    init, bank = start_of(scaled_gnss(run, float(cfg["gnss"]["sigma_scale"])), cfg, stationary, quality, filter_pass)
    return StartPieces(quality, stationary, init, bank)
