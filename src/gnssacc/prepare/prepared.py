"""The prepared recording: one immutable :class:`Prepared`, what the preparation found.

The preparation itself (the input checks and their verdicts, quality, stationary spans, the start
and the yaw bank, the noise identification) is :func:`gnssacc.prepare.preparation.prepare`; this
module holds only its outcome, which every estimator starts from and the report reads. A run that
reuses a kept preparation (:mod:`gnssacc.prepare.cache`) imports this module and the modules of
the outcome's parts, not the preparation's steps (their checks load scipy's FFT, for instance).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..checks.quality import QualityReport
from ..core.config import RunConfig
from ..core.recording import InitialState, RecordedRun
from ..estimators.settings import GnssModel

if TYPE_CHECKING:  # the parts' own modules: the unpickling of a kept preparation imports them
    from .stationary import StationaryNoise, StationaryReport
    from .tuning import TuneResult
    from .yawbank import BankResult


@dataclass(frozen=True)
class Prepared:
    """Everything the estimators share for one run, made once
    (:func:`gnssacc.prepare.preparation.prepare`).

    Attributes
    ----------
    run : RecordedRun
        The run the estimators read: the input checks' repairs and measured offsets applied, the
        fixes' sigmas as stated (the estimators apply the noise model of ``cfg``:
        :attr:`modelled_run`).
    cfg : RunConfig
        The configuration they use (tuned where allowed); estimators read their own settings
        from it (:mod:`gnssacc.estimators.settings`).
    quality : QualityReport
    stationary : StationaryReport
    init : InitialState
    rest_noise : gnssacc.prepare.stationary.StationaryNoise
        What the IMU shows at rest (white-noise densities per channel, the seconds used).
    tuning : TuneResult or None
    bank : BankResult or None
        ``None`` when the source gave the initial state.
    checks : tuple of gnssacc.checks.findings.Finding
        What the input checks repaired or applied, with their evidence (they raise on anything
        else).
    seconds : dict
        Time spent per step [s].
    gauss_markov : tuple or None
        ``(Prepared, how)`` for the ``-gm`` methods (:func:`gnssacc.prepare.gauss_markov.gm_setup`)
        when asked for.
    cache : dict or None
        With a preparation cache (:mod:`gnssacc.prepare.cache`): ``reused`` (whether this outcome
        was read from it), ``file`` and ``key``.
    """

    run: RecordedRun
    cfg: RunConfig
    quality: QualityReport
    stationary: StationaryReport
    init: InitialState
    rest_noise: StationaryNoise | None = None
    tuning: TuneResult | None = None
    bank: BankResult | None = None
    checks: tuple = ()
    seconds: dict = field(default_factory=dict)
    gauss_markov: tuple | None = None
    cache: dict | None = None

    @property
    def modelled_run(self) -> RecordedRun:
        """:attr:`run` with the fixes' noise as the estimators model it under :attr:`cfg` (their
        sigmas times ``[gnss] sigma_scale``: :meth:`gnssacc.estimators.settings.GnssModel.fixes`),
        for a figure that compares an estimate with that noise."""
        return self.run.with_gnss(GnssModel.from_config(self.cfg).fixes(self.run.gnss))
