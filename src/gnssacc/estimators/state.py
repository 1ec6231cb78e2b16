"""The EKF's state and how a pass starts: the filter state, its layout for a run, the initial
covariance from a start (:class:`gnssacc.core.recording.InitialState`), and the closed-loop
correction.

A start is what the preparation stage found (:mod:`gnssacc.prepare`, or the run's own); an
estimator never looks for one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..checks.quality import QualityReport, check_imu
from ..core.config import RunConfig
from ..core.earth import earth_rate_n, gravity_n
from ..core.recording import InitialState, RecordedRun
from ..core.rotations import skew
from .layout import ATT, BA, BG, GNSS_ERROR, I_ATT, ODOMETRY_SCALE, POS, StateLayout
from .mechanization import apply_correction


def start_of_pass(
    run: RecordedRun, settings, init: InitialState | None, quality: QualityReport | None
) -> tuple[InitialState, QualityReport]:
    """The start and IMU quality report of an estimator's pass: ``init`` (else the run's own, as
    it is) and ``quality`` (else checked here, which takes a run configuration).

    Raises
    ------
    ValueError
        Neither ``init`` nor a start of the run's own (:func:`gnssacc.prepare.passes.run_ekf`
        finds one), or no ``quality`` with an estimator's own settings.
    """
    init = init if init is not None else run.init
    if init is None:
        raise ValueError(
            "an estimator needs a start: init= (gnssacc.pipeline.prepare, or "
            "gnssacc.prepare.passes.run_ekf / run_smoother, which find one)"
        )
    if quality is None:
        if not isinstance(settings, RunConfig):
            raise ValueError(
                "an estimator given its settings needs quality= (gnssacc.pipeline.prepare gives it)"
            )
        quality = check_imu(run.imu, settings)
    return init, quality


@dataclass
class FilterState:
    """Nominal state and error covariance (updated in place by the loop).

    The state vector has the paper's 15 navigation states, then the run's Gauss-Markov states
    (:class:`gnssacc.estimators.layout.StateLayout`: the GNSS fix error's three when modelled,
    the odometry scale factor with wheel odometry). Without them it is the paper's 15-state
    filter, with the same arithmetic.

    Attributes
    ----------
    pos : ndarray (3,)
        lat, lon [rad], h [m].
    v_n : ndarray (3,)
        NED velocity [m/s].
    R_nb : ndarray (3, 3)
    b_a, b_g : ndarray (3,)
        Accumulated bias estimates, body [m/s^2], [rad/s].
    P : ndarray (n, n)
        Error covariance, in the order of :attr:`layout`.
    x_e : ndarray (n - 15,)
        Nominal values of the states after the navigation ones, in the order of :attr:`layout`.
    layout : StateLayout
    consider : int
        Index of a Schmidt consider state (-1: none): the yaw error when the start found the yaw
        undetermined (:func:`initial_state`).
    """

    pos: np.ndarray
    v_n: np.ndarray
    R_nb: np.ndarray
    b_a: np.ndarray
    b_g: np.ndarray
    P: np.ndarray
    x_e: np.ndarray = field(default_factory=lambda: np.zeros(0))
    layout: StateLayout = field(default_factory=StateLayout)
    consider: int = -1

    def extra(self, name: str) -> np.ndarray:
        """The nominal values of block ``name`` (a view into :attr:`x_e`; empty without it)."""
        return self.x_e[self.layout.extra_block(name)]

    @property
    def gm(self) -> np.ndarray:
        """Estimated GNSS fix error [m, NED] (a view into :attr:`x_e`; zeros without that model)."""
        return self.extra(GNSS_ERROR) if self.layout.has(GNSS_ERROR) else np.zeros(3)

    @property
    def i_scale(self) -> int:
        """Index of the odometry scale-factor state, -1 without it."""
        return self.layout.offset(ODOMETRY_SCALE)

    @property
    def scale(self) -> float:
        """Estimated odometry scale-factor error ``k`` (the odometry reads ``(1 + k)`` times the
        speed)."""
        k = self.extra(ODOMETRY_SCALE)
        return float(k[0]) if len(k) else 0.0


def initial_state(init: InitialState, settings, layout: StateLayout | None = None) -> FilterState:
    """The filter state at ``init.t``: the initial state, its sigmas and the bias priors
    (``settings``: either estimator's settings, :mod:`gnssacc.estimators.settings`), and the
    Gauss-Markov states of ``layout`` at zero with their stationary sigmas (default: none)."""
    sig_p, sig_v, sig_att = initial_sigmas(init, settings.start_sigmas)
    sig_ba = (
        settings.imu.accel_bias_sigma0
        if init.sigma_b_a is None
        else np.asarray(init.sigma_b_a, float)
    )
    sig_bg = (
        settings.imu.gyro_bias_sigma0
        if init.sigma_b_g is None
        else np.asarray(init.sigma_b_g, float)
    )
    layout = layout or StateLayout()
    P = np.diag(
        np.concatenate([sig_p, sig_v, sig_att, sig_ba, sig_bg] + [b.sigma for b in layout.markov])
        ** 2
    )
    if init.cov is not None:  # a filter's covariance, correlations kept
        P[: layout.nav, : layout.nav] = np.asarray(init.cov, float)
    elif init.levelled:
        _tie_tilt_to_accel_bias(P, init)
    if init.gyro_bias_at_rest:
        P = _tie_gyro_bias_to_attitude(P, init)
    if layout.has(GNSS_ERROR) and init.fit_window is not None:
        # A start taken from the fixes carries their correlated error x_g: dp = x_g while the
        # x_g state starts at zero (dx_g = -x_g), so the two are known only in sum.
        g = layout.block(GNSS_ERROR)
        var = np.diag(next(b.sigma for b in layout.markov if b.name == GNSS_ERROR) ** 2)
        P[POS, POS] += var
        P[POS, g] = P[g, POS] = -var
    return FilterState(
        np.array([init.lat, init.lon, init.h]),
        np.array(init.v_n, float).copy(),
        init.R_nb.copy(),
        np.array(init.b_a, float).copy(),
        np.array(init.b_g, float).copy(),
        P,
        np.zeros(layout.n - layout.nav),
        layout,
        consider_for(init),
    )


def consider_for(init: InitialState) -> int:
    """The state the filter holds as a Schmidt consider state: the yaw error (``phi`` down) when
    the start found the yaw undetermined (``init.yaw_evidence``), else none (-1).

    Such a run never told the yaw (the yaw bank's verdict over the whole run): an update can
    then only "learn" it from the filter's own linearisation, a specific force that is noise or
    the filter's tilt-bias error turned by a yaw error (false observability; docs/
    consistency.md). Considered, the yaw keeps the start's guess and the start's sigma (grown by
    the gyro noise), and its uncertainty still weighs on every other state."""
    return I_ATT + 2 if init.yaw_evidence == "undetermined" else -1


def _tie_tilt_to_accel_bias(P: np.ndarray, init: InitialState) -> None:
    """Levelling makes ``-R_est^T g = f_mean = -R^T g + b_a``, so the tilt error is ``phi = M b_a``
    with ``M = [[0, -1, 0], [1, 0, 0], [0, 0, 0]] R / g``: add that part of the tilt covariance and
    its cross-covariance with the bias (in place), so the filter knows the combination that
    matters for navigation, ``g phi - R b_a``, from the start."""
    g = float(gravity_n(init.lat, init.h)[2])
    M = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]) @ init.R_nb / g
    MP = M @ P[BA, BA]
    P[ATT, ATT] += MP @ M.T
    P[ATT, BA] = MP
    P[BA, ATT] = MP.T


def gyro_bias_attitude_jacobian(init: InitialState) -> np.ndarray:
    """``d b_g / d phi`` (3, 3) of a gyro bias measured at rest, ``b_g = omega_mean - R^T w``
    with ``w`` the earth rate [rad/s, NED] and ``R`` the start's attitude (``init.R_nb``).

    With ``R_est = (I + [phi x]) R`` and the residual bias ``x_bg = b_g - b_g_est`` (the EKF's
    conventions, :mod:`gnssacc.estimators.mechanization`), ``x_bg = R^T [w x] phi`` to first order:
    a yaw error of the start is a bias error of ``|w_h|`` per radian, along the body's image of
    the horizontal earth rate turned by 90 deg."""
    return init.R_nb.T @ skew(earth_rate_n(init.lat))


def _tie_gyro_bias_to_attitude(P: np.ndarray, init: InitialState) -> np.ndarray:
    """The covariance of ``x_bg = n_psi psi + n`` (``n_psi`` the yaw column of
    :func:`gyro_bias_attitude_jacobian`, ``psi`` the yaw error ``phi`` down; ``n`` the mean rate's
    own error, ``P``'s gyro-bias block as given): ``A P A^T`` with ``A`` the identity but
    ``A[BG, yaw] = n_psi``. The bias then is as uncertain as the yaw makes it and correlated with
    it, so the earth rate it would have to tell the yaw from is cancelled by the bias error the
    same yaw error made (module notes of :mod:`gnssacc.prepare.initialise`).

    The tilt columns are left out. Their share of the bias error, ``Omega`` times the tilt sigma
    (0.1-0.4 deg/h for 0.5-1.5 deg), is below the mean rate's own sigma (at least 1 deg/h), and
    where the tie matters, a yaw undetermined, they are evaluated at a yaw that may be half a turn
    off: the tilt-bias correlation through the horizontal earth rate then has a guessed sign,
    which the zero-rate updates act on. Measured without them: the static runs' yaw as with them,
    their tilt NEES within the seeds' spread; the moving runs' unchanged (docs/consistency.md)."""
    A = np.eye(P.shape[0])
    A[BG, I_ATT + 2] = gyro_bias_attitude_jacobian(init)[:, 2]
    return A @ P @ A.T


def initial_sigmas(init: InitialState, over: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Initial 1-sigma of position [m], velocity [m/s] and attitude error (n frame) [rad].

    The initial state's own sigmas, replaced by any ``[init]`` overrides of the configuration
    (``over``: :meth:`gnssacc.core.config.RunConfig.initial_sigma_overrides`); both estimators start
    from these.
    """
    att = np.array(init.sigma_att_rad, float)
    if "roll_pitch" in over:
        att[:2] = over["roll_pitch"]
    if "yaw" in over:
        att[2] = over["yaw"]
    return (
        np.asarray(over.get("pos", init.sigma_pos_m), float),
        np.asarray(over.get("vel", init.sigma_vel_mps), float),
        att,
    )


def correct(s: FilterState, dx: np.ndarray) -> None:
    """Closed-loop feedback of an estimated error (estimate minus truth) into the nominal state."""
    apply_correction(s.pos, s.v_n, s.R_nb, s.b_a, s.b_g, s.x_e, dx)
