"""Where a run starts: its IMU quality report, stationary spans, start state and yaw.

:func:`start_pieces` makes them once for a run (the preparation stage reuses them for the
estimators, and makes them again only for a correction the estimator is asked to judge).

What a recording states about its start is evidence with its real uncertainty. An IMU's own
orientation field (ROS ``sensor_msgs/Imu.orientation``) gives a good roll and pitch, but its yaw
comes from a magnetometer or from nothing: tens of degrees off near a vehicle's steel and motors
(and whatever its covariance claims). So the yaw bank decides the yaw whenever the motion tells it
(:mod:`gnssacc.prepare.yawbank`); the orientation's yaw is only kept when the vehicle never turns
or accelerates enough, then with at least :data:`MAGNETOMETER_YAW_SIGMA_DEG`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..checks.quality import QualityReport, check_imu
from ..core.config import RunConfig
from ..core.recording import InitialState, RecordedRun
from ..core.rotations import wrap_angle
from .filter_pass import FilterPass
from .stationary import StationaryReport, detect_stationary, params_from_config
from .yawbank import BankResult, select_yaw

#: 1-sigma of a yaw from an IMU's orientation field the motion did not confirm [deg]: a magnetometer
#: near a vehicle's steel and motors (calibrated or not).
MAGNETOMETER_YAW_SIGMA_DEG = 30.0


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


def start_of(
    run: RecordedRun, cfg: RunConfig, stationary, quality, filter_pass: FilterPass
) -> tuple[InitialState, BankResult | None]:
    """The run's own start, else the yaw bank's (with ``cfg``'s noise; fix sigmas as in ``run``).

    A start whose yaw comes from the IMU's own orientation field is evidence, not truth (module
    notes): the bank decides the yaw when the motion tells it, and the orientation's yaw is kept,
    with a magnetometer-grade sigma, only when it does not."""
    given = run.init
    if given is not None and given.yaw_evidence != "orientation":
        return given, None
    bank = select_yaw(run, cfg, stationary, quality, filter_pass=filter_pass)
    if given is None:
        return bank.init, bank
    return _with_orientation(given, bank), bank


def _with_orientation(given: InitialState, bank: BankResult) -> InitialState:
    """The bank's start, or the orientation's when the motion never decided the yaw (module
    notes)."""
    stated = float(np.degrees(given.rpy[2]))
    if bank.t_decided is not None:
        off = float(np.degrees(wrap_angle(bank.init.rpy[2] - given.rpy[2])))
        sig = float(np.degrees(bank.init.sigma_att_rad[2]))
        word = (
            "agrees"
            if abs(off) <= max(3.0 * sig, MAGNETOMETER_YAW_SIGMA_DEG)
            else "is magnetometer-grade: not used"
        )
        return replace(
            bank.init,
            how=f"{bank.init.how}; the IMU orientation field's yaw {stated:.0f} deg is "
            f"{off:+.0f} deg off it ({word})",
        )
    att = given.sigma_att_rad.copy()
    att[2] = max(float(att[2]), np.radians(MAGNETOMETER_YAW_SIGMA_DEG))
    return replace(
        given,
        sigma_att_rad=att,
        yaw_evidence="undetermined",
        how=f"{given.how}; yaw {stated:.0f} deg from the IMU's orientation field, not confirmed "
        "by the "
        f"motion (magnetometer-grade: +-{np.degrees(att[2]):.0f} deg)",
    )


def start_pieces(run: RecordedRun, cfg: RunConfig, filter_pass: FilterPass) -> StartPieces:
    """Quality, stationary spans and the start of ``run`` under ``cfg`` (its fixes' noise as the
    estimators model it: :mod:`gnssacc.prepare.initialise`)."""
    quality = check_imu(run.imu, cfg)
    stationary = detect_stationary(
        run.imu, run.gnss, run.origin, params_from_config(cfg), cfg.lever_arm_b, run.gnss_vel
    )
    init, bank = start_of(run, cfg, stationary, quality, filter_pass)
    return StartPieces(quality, stationary, init, bank)


def start_and_quality(
    run: RecordedRun,
    cfg: RunConfig,
    init=None,
    quality=None,
    stationary=None,
    *,
    filter_pass: FilterPass,
):
    """What every estimator starts from: the IMU data-quality findings (checked here when not
    given) and the initial state (``init``, else :func:`start_of`).

    Returns
    -------
    init : InitialState
    quality : gnssacc.checks.quality.QualityReport
    """
    quality = quality if quality is not None else check_imu(run.imu, cfg)
    if init is None:
        init = start_of(run, cfg, stationary, quality, filter_pass)[0]
    return init, quality


def start_for(
    run: RecordedRun, settings, init=None, quality=None, stationary=None, *, filter_pass: FilterPass
):
    """The start and quality report of an estimator's pass: as given, else found here for this run
    alone (:func:`start_and_quality`), which needs a run configuration: an estimator's own settings
    cannot self-start.

    Raises
    ------
    ValueError
        Settings without ``init`` (or a run's own) and ``quality``.
    """
    if isinstance(settings, RunConfig):
        return start_and_quality(run, settings, init, quality, stationary, filter_pass=filter_pass)
    init = init if init is not None else run.init
    if init is None or quality is None:
        raise ValueError(
            "an estimator given its settings needs init= and quality= (gnssacc.pipeline.prepare "
            "gives "
            "both)"
        )
    return init, quality
