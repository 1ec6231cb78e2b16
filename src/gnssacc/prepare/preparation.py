"""The preparation: what a recording says about itself, found once before estimation.

:func:`prepare` runs, in order,

0. fix sigmas the recording does not state, from the fixes' scatter
(:mod:`gnssacc.prepare.fix_noise`);
   then the input checks (:mod:`gnssacc.checks.plausibility`): units, clocks, coordinates and
   mounting checked against the data themselves, their proposals settled by the estimator
   (:mod:`gnssacc.prepare.settle`), so every later step and estimator sees the corrected run,
   and how large a clock offset could go unseen (:func:`gnssacc.prepare.settle.clock_bound`);
1. the IMU data-quality check (:mod:`gnssacc.checks.quality`);
2. stationary detection from windowed IMU statistics and GNSS agreement
   (:mod:`gnssacc.prepare.stationary`), and the noise the IMU shows at rest;
3. the start state and the yaw bank (:mod:`gnssacc.prepare.initialise`,
   :mod:`gnssacc.prepare.yawbank`), unless the source gives an initial state;
4. with ``tune_mode="auto"``, noise identification (:mod:`gnssacc.prepare.tuning`; on a long run
   on representative windows, confirmed over the whole run: :mod:`gnssacc.prepare.tune_windows`),
   after which the bank runs again with the tuned noise (the initial sigmas and the hypotheses'
   filters depend on it); should its choice of yaw change, the noise is identified once more from
   the new start;
5. when asked, the ``-gm`` methods' own Gauss-Markov setup (:mod:`gnssacc.prepare.gauss_markov`).

The result is one immutable :class:`~gnssacc.prepare.prepared.Prepared`; every estimator starts
from its start with its configuration and stationary spans, and the report reads it. The decisions
that need an innovation likelihood run through the filter pass the caller hands in
(:class:`~gnssacc.prepare.filter_pass.FilterPass`).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Callable

import numpy as np

from ..core.config import RunConfig
from ..core.memory import release_free_memory
from ..core.parallel import close_pool
from ..core.recording import InitialState, RecordedRun
from .filter_pass import FilterPass
from .fix_noise import with_measured_sigmas
from .prepared import Prepared
from .settle import clock_bound, settled
from .start import start_of, start_pieces
from .stationary import noise_from_stationary
from .tune_windows import tuned_on_windows
from .tuning import tune
from .turn_allowance import rest_allowance


def _other_heading(a: InitialState, b: InitialState) -> bool:
    """Whether two starts differ in yaw by more than 3 sigma (neighbouring hypotheses converge to
    the
    same heading; a different heading means the noise the tuner saw came from another
    trajectory)."""
    d = abs((a.rpy[2] - b.rpy[2] + np.pi) % (2 * np.pi) - np.pi)
    return d > 3.0 * max(a.sigma_att_rad[2], b.sigma_att_rad[2])


def _with_turn_allowance(run, cfg, stationary, quality, init, bank, noise, filter_pass):
    """``(cfg, init, bank)`` with an ``"auto"`` gyro turn allowance set from the gyro noise at rest
    (:func:`gnssacc.prepare.turn_allowance.rest_allowance`) and, when it was, the start found
    again under it: the yaw bank's passes weigh the heading hypotheses by their likelihood, which
    the allowance changes (a simulated consumer UGV started under the fallback 1000 ppm and run at
    9022 had an attitude NEES of 4.5, yaw 10.5; started under 9022, 1.2 and 0.7)."""
    got = rest_allowance(cfg, run.imu, stationary, noise)
    if got is cfg:
        return cfg, init, bank
    init, bank = start_of(run, got, stationary, quality, filter_pass)
    return got, init, bank


def _tune(run, cfg, stationary, quality, init, noise, filter_pass):
    """The noise identification, on windows of a long run when the whole run confirms it
    (:func:`gnssacc.prepare.tune_windows.tuned_on_windows`), else over the whole run."""
    got = tuned_on_windows(run, cfg, stationary, quality, init, noise, filter_pass=filter_pass)
    return got or tune(run, cfg, stationary, quality, init, noise, filter_pass=filter_pass)


def _tuned(run, cfg, stationary, quality, init, bank, noise, filter_pass):
    """Step 4 of the module notes: the tuned configuration and result, and the start and bank
    under it."""
    cfg_t, result = _tune(run, cfg, stationary, quality, init, noise, filter_pass)
    init2, bank2 = start_of(run, cfg_t, stationary, quality, filter_pass)
    if bank is not None and _other_heading(init, bank2.init):
        cfg_t, result = _tune(run, cfg, stationary, quality, init2, noise, filter_pass)
        init2, bank2 = start_of(run, cfg_t, stationary, quality, filter_pass)
    return cfg_t, result, init2, bank2


def checked(
    run: RecordedRun, cfg: RunConfig, filter_pass: FilterPass
) -> tuple[RecordedRun, RunConfig, list]:
    """Step 0 of the module notes: the input checks, their proposals settled by ``filter_pass``
    (:func:`gnssacc.prepare.settle.settled`)."""
    run, cfg, findings, _ = settled(run, cfg, filter_pass)
    return run, cfg, findings


def prepare(
    run: RecordedRun,
    cfg: RunConfig,
    tune_mode: str | None = None,
    *,
    filter_pass: FilterPass,
    gauss_markov: bool = False,
    on_checked: Callable[[list], None] | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> Prepared:
    """Checks, quality, stationary spans, start state and (``tune_mode="auto"``) noise, in that
    order.

    Parameters
    ----------
    run : RecordedRun
        As a source loaded it.
    cfg : RunConfig
    tune_mode : {"auto", "none"}, optional
        Default: ``[tune] mode`` of the configuration.
    filter_pass : FilterPass
        The EKF pass the likelihood-based decisions use
        (:func:`gnssacc.prepare.passes.filter_pass`).
    gauss_markov : bool
        Also set up the ``-gm`` methods' Gauss-Markov model (:attr:`Prepared.gauss_markov`).
    on_checked : callable, optional
        Told the input checks' findings as soon as they are settled (before the start and the
        tuning), so that a caller can state the corrections at once.
    on_stage : callable, optional
        Told each stage's name as it starts (``"input checks"``, ``"start"``, ``"noise
        identification"``), for progress.
    """
    tune_mode = tune_mode or cfg["tune"]["mode"]
    stage = on_stage or (lambda name: None)
    secs = {}
    t = time.perf_counter()
    stage("input checks")
    run, sigma_note = with_measured_sigmas(run)  # before any decision uses the fixes' noise
    run, cfg, checks, pieces = settled(run, cfg, filter_pass)
    checks = ([sigma_note] if sigma_note else []) + checks
    if on_checked is not None:
        on_checked(checks)
    release_free_memory()  # the checks' temporaries, before the next stage's
    secs["input_checks_s"] = time.perf_counter() - t
    t = time.perf_counter()
    stage("start (stationary spans, attitude, yaw)")
    pieces = pieces or start_pieces(run, cfg, filter_pass)  # made once: by a verdict, or here
    bound = clock_bound(run, cfg, checks, pieces, filter_pass)
    checks += [bound] if bound is not None else []
    quality, stationary, init, bank = pieces.quality, pieces.stationary, pieces.init, pieces.bank
    noise = noise_from_stationary(run.imu, stationary)
    cfg, init, bank = _with_turn_allowance(
        run, cfg, stationary, quality, init, bank, noise, filter_pass
    )
    release_free_memory()  # before the estimators build on the heap
    secs["start_s"] = time.perf_counter() - t
    result = None
    if tune_mode == "auto":
        t = time.perf_counter()
        stage("noise identification (EKF passes)")
        cfg, result, init, bank = _tuned(
            run, cfg, stationary, quality, init, bank, noise, filter_pass
        )
        secs["tuning_s"] = time.perf_counter() - t
    prep = Prepared(run, cfg, quality, stationary, init, noise, result, bank, tuple(checks), secs)
    if gauss_markov:
        from .gauss_markov import gm_setup

        prep = replace(prep, gauss_markov=gm_setup(prep, filter_pass=filter_pass))
    close_pool()  # the tuner's workers (evaluating its passes side by side) are done
    return prep
