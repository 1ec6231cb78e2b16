"""What a recording says about itself before estimation: where the vehicle stands still, how noisy
its IMU and fixes are, and where and how it starts.

:func:`identify` runs, in order,

0. the input checks (:mod:`gnssacc.checks.plausibility`): units, clocks, coordinates and mounting checked
   against the data themselves; repairs and measured ``"auto"`` offsets and mountings are applied
   here, so every later step and estimator sees the corrected run;
1. the IMU data-quality check (:mod:`gnssacc.checks.quality`);
2. stationary detection from windowed IMU statistics and GNSS agreement (:mod:`gnssacc.prepare.stationary`);
3. the start state and the yaw bank (:mod:`gnssacc.prepare.initialise`, :mod:`gnssacc.prepare.yawbank`), unless
   the source gives an initial state;
4. with ``tune="auto"``, noise identification (:mod:`gnssacc.prepare.tuning`), after which the bank runs
   again with the tuned noise (the initial sigmas depend on it); should its choice of yaw change,
   the noise is identified once more from the new start;
5. a check of the final noise model against the recording: one EKF pass's innovations
   (:class:`gnssacc.analysis.consistency.ModelCheck`).

Every estimator then starts from the same state with the same configuration and stationary spans.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..analysis.consistency import ModelCheck, rest_noise_findings
from ..checks.plausibility import check_run
from ..checks.quality import QualityReport, check_imu
from ..core.config import RunConfig
from ..core.memory import release_free_memory
from ..core.recording import InitialState, RecordedRun
from ..estimators.ekf import run_ekf
from .stationary import StationaryReport, detect_stationary, noise_from_stationary, params_from_config
from .tuning import TuneResult, scaled_gnss, tune
from .yawbank import BankResult, select_yaw


@dataclass
class Identified:
    """Everything the estimators share for one run.

    Attributes
    ----------
    run : RecordedRun
        The run as the estimators see it (fix sigmas times ``gnss.sigma_scale``).
    cfg : RunConfig
        The configuration they use (tuned where allowed).
    quality : QualityReport
    stationary : StationaryReport
    init : InitialState
    tuning : TuneResult or None
    bank : BankResult or None
        ``None`` when the source gave the initial state.
    model : ModelCheck or None
        The final noise model against the recording (one EKF pass's innovations).
    seconds : dict
        Time spent per step [s].
    checks : list of gnssacc.checks.findings.Finding
        What the input checks repaired or applied (they raise on anything else).
    derived : dict
        Setups that several methods derive from this identification and share, made on first
        use (e.g. the ``-gm`` methods' Gauss-Markov search, :func:`gnssacc.estimators.gm_variant.gm_setup`).
        Not copied by ``dataclasses.replace``: a changed identification starts empty.
    """

    run: RecordedRun
    cfg: RunConfig
    quality: QualityReport
    stationary: StationaryReport
    init: InitialState
    tuning: TuneResult | None = None
    bank: BankResult | None = None
    model: ModelCheck | None = None
    seconds: dict = field(default_factory=dict)
    checks: list = field(default_factory=list)
    derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)


def _start(run, cfg, stationary, quality) -> tuple[InitialState, BankResult | None]:
    if run.init is not None:
        return run.init, None
    bank = select_yaw(run, cfg, stationary, quality)
    return bank.init, bank


def _other_heading(a: InitialState, b: InitialState) -> bool:
    """Whether two starts differ in yaw by more than 3 sigma (neighbouring hypotheses converge to the
    same heading; a different heading means the noise the tuner saw came from another trajectory)."""
    d = abs((a.rpy[2] - b.rpy[2] + np.pi) % (2 * np.pi) - np.pi)
    return d > 3.0 * max(a.sigma_att_rad[2], b.sigma_att_rad[2])


def identify(run: RecordedRun, cfg: RunConfig, tune_mode: str | None = None) -> Identified:
    """Quality, stationary spans, start state and (``tune_mode="auto"``) noise, in that order.

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
    tune_mode : {"auto", "none"}, optional
        Default: ``[tune] mode`` of the configuration.
    """
    tune_mode = tune_mode or cfg["tune"]["mode"]
    secs = {}
    t = time.perf_counter()
    run, cfg, checks = check_run(run, cfg)
    release_free_memory()   # the checks' temporaries, before the next stage's
    secs["input_checks_s"] = time.perf_counter() - t
    t = time.perf_counter()
    quality = check_imu(run.imu, cfg)
    release_free_memory()
    stationary = detect_stationary(run.imu, run.gnss, run.origin, params_from_config(cfg))
    release_free_memory()   # before the estimators build on the heap
    secs["quality_and_stationary_s"] = time.perf_counter() - t
    t = time.perf_counter()
    est_run = scaled_gnss(run, float(cfg["gnss"]["sigma_scale"]))
    init, bank = _start(est_run, cfg, stationary, quality)
    secs["initialisation_s"] = time.perf_counter() - t
    result = None
    noise = noise_from_stationary(run.imu, stationary)
    if tune_mode == "auto":
        t = time.perf_counter()
        cfg_t, result = tune(run, cfg, stationary, quality, init, noise)
        est_run = scaled_gnss(run, float(cfg_t["gnss"]["sigma_scale"]))
        init2, bank2 = _start(est_run, cfg_t, stationary, quality)
        if bank is not None and _other_heading(init, bank2.init):
            cfg_t, result = tune(run, cfg, stationary, quality, init2, noise)
            est_run = scaled_gnss(run, float(cfg_t["gnss"]["sigma_scale"]))
            init2, bank2 = _start(est_run, cfg_t, stationary, quality)
        cfg, init, bank = cfg_t, init2, bank2
        secs["tuning_s"] = time.perf_counter() - t
    t = time.perf_counter()
    check = run_ekf(est_run, cfg, "ekf", init=init, stationary=stationary, quality=quality, output_times=np.zeros(0),
                    cov_every=int(cfg["tune"]["cov_every"]))
    secs["model_check_s"] = time.perf_counter() - t
    rest = rest_noise_findings(noise.white_density, np.sqrt(np.r_[cfg.accel_psd, cfg.gyro_psd]), noise.total_s)
    model = ModelCheck.from_stats(check.stats, rest)
    return Identified(est_run, cfg, quality, stationary, init, result, bank, model, secs, checks)
