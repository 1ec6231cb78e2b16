"""The recorded-run model: IMU samples, GNSS fixes, optional truth and initial state.

Every source (KITTI, CSV directory, simulator, bags, RTKLIB ``.pos``, NMEA) produces a
:class:`RecordedRun`; every estimator consumes one. Validation lives here so that all sources get
the same checks.

Frames and units: body frame b is Front-Right-Down, navigation frame n is North-East-Down,
times are seconds on one clock, angles radians, positions geodetic (lat, lon [rad], h [m]).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .earth import LocalTangentFrame
from .errors import InputError, warn_data
from .rotations import dcm_to_euler, euler_to_dcm


@dataclass
class ImuData:
    """Strapdown IMU samples.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times [s]. Sample k holds over the interval ``(t[k-1], t[k]]``.
    f_b : ndarray, shape (N, 3)
        Specific force in the body frame (FRD) [m/s^2].
    omega_ib_b : ndarray, shape (N, 3)
        Angular rate of the body w.r.t. inertial space, body frame [rad/s].
    """

    t: np.ndarray
    f_b: np.ndarray
    omega_ib_b: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask) -> "ImuData":
        return ImuData(self.t[mask], self.f_b[mask], self.omega_ib_b[mask])

    def sample_range(self, t: float, avg_s: float = 0.0) -> tuple[int, int]:
        """Indices ``[k0, k1)`` of the samples covering ``[t - avg_s, t]`` (the one holding at ``t`` if 0)."""
        k = min(int(np.searchsorted(self.t, t, side="left")), len(self.t) - 1)
        k0 = int(np.searchsorted(self.t, t - avg_s, side="left")) if avg_s > 0 else k
        return min(k0, k), k + 1


#: Fix quality codes of :attr:`GnssFixes.quality` (RTKLIB's ``Q`` numbering, which NMEA GGA
#: qualities and other receivers' flags are mapped onto by their readers), by name.
FIX_QUALITY = {
    "unknown": 0,
    "fix": 1,
    "float": 2,
    "sbas": 3,
    "dgps": 4,
    "single": 5,
    "ppp": 6,
    "estimated": 7,
}
#: Quality code -> name.
FIX_QUALITY_NAMES = {v: k for k, v in FIX_QUALITY.items()}


def cov_from_sigmas(sigma, corr=None) -> np.ndarray:
    """NED covariances ``diag(sigma) C diag(sigma)`` from 1-sigmas ``sigma`` (shape (..., 3)) and
    correlations ``corr = (rho_ne, rho_nd, rho_ed)`` (shape (..., 3); None: the identity ``C``)."""
    s = np.asarray(sigma, float)
    C = np.broadcast_to(np.eye(3), s.shape[:-1] + (3, 3)).copy()
    if corr is not None:
        r = np.asarray(corr, float)
        C[..., 0, 1] = C[..., 1, 0] = r[..., 0]
        C[..., 0, 2] = C[..., 2, 0] = r[..., 1]
        C[..., 1, 2] = C[..., 2, 1] = r[..., 2]
    return s[..., :, None] * C * s[..., None, :]


@dataclass
class GnssFixes:
    """GNSS position fixes of the antenna.

    Attributes
    ----------
    t : ndarray, shape (M,)
        Fix times [s].
    lat, lon : ndarray, shape (M,)
        Geodetic latitude and longitude [rad].
    h : ndarray, shape (M,)
        Ellipsoidal height [m].
    sigma_ned : ndarray, shape (M, 3)
        1-sigma position uncertainty along north, east, down [m].
    quality : ndarray of int, shape (M,), or None
        Per-fix quality code (:data:`FIX_QUALITY`: 1 fix, 2 float, 3 sbas, 4 dgps, 5 single,
        6 ppp, 7 estimated, 0 unknown), when the source states one.
    corr_ned : ndarray, shape (M, 3), or None
        Correlation coefficients ``(rho_ne, rho_nd, rho_ed)`` of the position error, when the
        source states them (e.g. RTKLIB's ``sdne, sdeu, sdun``); None: uncorrelated axes. Kept
        as correlations rather than covariances so that every operation on ``sigma_ned`` (the
        tuner's ``gnss.sigma_scale``, a quality's inflation) scales the whole covariance
        (:meth:`cov_ned`).
    sigma_stated : bool
        Whether the source states the sigmas (False: a configured default stands in for them,
        which the preparation replaces by what the fixes' own scatter shows,
        :mod:`gnssacc.prepare.fix_noise`).
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    sigma_ned: np.ndarray
    quality: np.ndarray | None = None
    corr_ned: np.ndarray | None = None
    sigma_stated: bool = True

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask) -> "GnssFixes":
        return GnssFixes(
            self.t[mask],
            self.lat[mask],
            self.lon[mask],
            self.h[mask],
            self.sigma_ned[mask],
            None if self.quality is None else self.quality[mask],
            None if self.corr_ned is None else self.corr_ned[mask],
            self.sigma_stated,
        )

    def cov_ned(self, k) -> np.ndarray:
        """The NED covariance [m^2] of fix ``k`` (shape (3, 3)) or of fixes ``k`` (an index array:
        shape (K, 3, 3)): ``diag(sigma) C diag(sigma)``, ``C`` from :attr:`corr_ned` (the
        identity without it)."""
        corr = None if self.corr_ned is None else self.corr_ned[k]
        return cov_from_sigmas(self.sigma_ned[k], corr)


@dataclass
class GnssVelocity:
    """GNSS (Doppler) velocities of the antenna, on the fixes' clock.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Receiver time tags [s], on the same clock as :attr:`GnssFixes.t`.
    v_ned : ndarray, shape (K, 3)
        Velocity of the antenna along north, east, down [m/s]; NaN on an axis the source does
        not measure (e.g. NMEA speed and course: no down component).
    sigma_ned : ndarray, shape (K, 3)
        1-sigma velocity uncertainty along north, east, down [m/s]; NaN where ``v_ned`` is NaN.
    corr_ned : ndarray, shape (K, 3), or None
        Correlation coefficients ``(rho_ne, rho_nd, rho_ed)`` of the velocity error when the
        source states them (RTKLIB's ``sdvne, sdveu, sdvun``); None: uncorrelated axes.
    sigma_stated : bool
        Whether the source states the sigmas (False: a documented default stands in, which the
        tuner scales).
    """

    t: np.ndarray
    v_ned: np.ndarray
    sigma_ned: np.ndarray
    corr_ned: np.ndarray | None = None
    sigma_stated: bool = True

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask) -> "GnssVelocity":
        return GnssVelocity(
            self.t[mask],
            self.v_ned[mask],
            self.sigma_ned[mask],
            None if self.corr_ned is None else self.corr_ned[mask],
            self.sigma_stated,
        )

    def measured(self) -> np.ndarray:
        """Boolean mask, shape (K, 3): the axes each velocity measures."""
        return np.isfinite(self.v_ned) & np.isfinite(self.sigma_ned)

    def cov_ned(self, k) -> np.ndarray:
        """The NED covariance [m^2/s^2] of velocity ``k`` (shape (3, 3)) or of velocities ``k``
        (an index array: shape (K, 3, 3)); rows and columns of unmeasured axes are NaN."""
        corr = None if self.corr_ned is None else self.corr_ned[k]
        return cov_from_sigmas(self.sigma_ned[k], corr)


def check_gnss_velocity(vel: GnssVelocity, where: str) -> None:
    """Shapes, time order and ranges of GNSS velocities; raise :class:`InputError` naming the
    problem."""
    k = len(vel)
    if vel.v_ned.shape != (k, 3) or vel.sigma_ned.shape != (k, 3):
        raise InputError(where, "GNSS velocity arrays must have shape (K, 3)")
    check_increasing(vel.t, where, "GNSS velocity")
    if not np.all(np.isfinite(vel.t)):
        raise InputError(where, "GNSS velocity time contains NaN or inf values")
    if np.any(np.isfinite(vel.v_ned) != np.isfinite(vel.sigma_ned)):
        raise InputError(where, "GNSS velocity: a component and its sigma must both be given")
    s = vel.sigma_ned[np.isfinite(vel.sigma_ned)]
    if np.any(s <= 0):
        raise InputError(where, "GNSS velocity sigmas must be positive m/s")
    v = vel.v_ned[np.isfinite(vel.v_ned)]
    if np.any(np.abs(v) > 600.0):
        raise InputError(
            where, "GNSS velocity above 600 m/s: not m/s (km/h, knots, cm/s?) or not a velocity"
        )


@dataclass
class WheelOdometry:
    """Wheel (drive-controller) odometry: the vehicle's forward speed, optionally its yaw rate.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Sample times [s] on the run's clock (they share the IMU's clock: a source shifts them
        with the IMU's time stamps).
    v_forward : ndarray, shape (K,)
        Forward speed of the vehicle's odometry reference point along the vehicle x axis
        (forward) [m/s]; negative when reversing.
    yaw_rate : ndarray, shape (K,), or None
        Turn rate about the vehicle's z axis, down (FRD): positive turning right, i.e. clockwise
        seen from above [rad/s]. (ROS REP-103's ``angular.z`` is about z up: the negative.)
    sigma_v : ndarray, shape (K,), or None
        Per-sample 1-sigma of ``v_forward`` [m/s] as the source states it.
    sigma_yaw_rate : ndarray, shape (K,), or None
        Per-sample 1-sigma of ``yaw_rate`` [rad/s] as the source states it.
    frame : str
        Where the samples came from (file, topic, frame id), for messages and reports.
    """

    t: np.ndarray
    v_forward: np.ndarray
    yaw_rate: np.ndarray | None = None
    sigma_v: np.ndarray | None = None
    sigma_yaw_rate: np.ndarray | None = None
    frame: str = ""

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask) -> "WheelOdometry":
        def pick(a):
            return None if a is None else a[mask]

        return WheelOdometry(
            self.t[mask],
            self.v_forward[mask],
            pick(self.yaw_rate),
            pick(self.sigma_v),
            pick(self.sigma_yaw_rate),
            self.frame,
        )

    def shifted(self, delta_s: float) -> "WheelOdometry":
        """A copy with ``delta_s`` [s] added to every time stamp (a shift of the IMU's clock)."""
        return replace(self, t=self.t + float(delta_s))


@dataclass
class Truth:
    """Reference trajectory.

    Attributes
    ----------
    t : ndarray, shape (K,)
    lat, lon : ndarray [rad]
    h : ndarray [m]
    v_n : ndarray, shape (K, 3) or None
        NED velocity [m/s], when known.
    rpy : ndarray, shape (K, 3) or None
        Roll, pitch, yaw [rad], when known.
    caveat : str
        How far the reference falls short of a truth, when it does (e.g. a dataset's own
        post-processed solution, of another point than the antenna); "" for an independent one.
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    v_n: np.ndarray | None = None
    rpy: np.ndarray | None = None
    caveat: str = ""

    def select(self, mask) -> "Truth":
        def pick(a):
            return None if a is None else a[mask]

        return Truth(
            self.t[mask], self.lat[mask], self.lon[mask], self.h[mask],
            pick(self.v_n), pick(self.rpy), self.caveat,
        )  # fmt: skip


@dataclass
class InitialState:
    """Initial navigation state and its 1-sigma uncertainty.

    Attributes
    ----------
    t : float
        Time of the state [s].
    lat, lon : float
        [rad].
    h : float
        [m].
    v_n : ndarray, shape (3,)
        NED velocity [m/s].
    rpy : ndarray, shape (3,)
        Roll, pitch, yaw [rad].
    sigma_pos_m, sigma_vel_mps, sigma_att_rad : ndarray, shape (3,)
        1-sigma of the NED position, NED velocity and of the attitude error (n frame).
    how : str
        A short account of how the state was obtained (shown in reports).
    b_a, b_g : ndarray, shape (3,)
        Initial accelerometer [m/s^2] and gyro [rad/s] bias estimates, body axes (zero unless
        measured, e.g. the gyro bias from a static start).
    sigma_b_a, sigma_b_g : ndarray, shape (3,) or None
        Their 1-sigma; ``None``: the configured turn-on bias sigmas.
    fit_window : tuple of float or None
        ``(t_first, t_last)`` of the fixes the initial position/velocity were fitted to [s].
    levelled : bool
        Roll and pitch come from accelerometer levelling: their error is then tied to the
        accelerometer bias (the estimators start with that correlation).
    gyro_bias_at_rest : bool
        ``b_g`` was measured at rest as the mean gyro rate minus the earth rate at this attitude:
        its error is then tied to the attitude error, the yaw's above all (the estimators start
        with that correlation, so the earth rate tells them no more of the yaw than the data do).
    cov : ndarray, shape (15, 15) or None
        The full covariance of the navigation error states (position, velocity, attitude,
        accelerometer and gyro bias; SI, NED, as the estimators order them), e.g. a filter's at
        this time: it replaces the sigmas above and keeps their correlations (``None``: the
        sigmas, uncorrelated but for ``levelled``).
    yaw_evidence : str
        What the yaw rests on: ``"given"`` (the source states the start, e.g. ``init.json``),
        ``"orientation"`` (an IMU's own orientation field: magnetometer-grade until the motion
        confirms it, :mod:`gnssacc.prepare.start`), ``"bank"`` (the motion decided it) or
        ``"undetermined"`` (the motion never did: the yaw sigma says how little is known).
    """

    t: float
    lat: float
    lon: float
    h: float
    v_n: np.ndarray
    rpy: np.ndarray
    sigma_pos_m: np.ndarray
    sigma_vel_mps: np.ndarray
    sigma_att_rad: np.ndarray
    how: str = "given"
    b_a: np.ndarray = field(default_factory=lambda: np.zeros(3))
    b_g: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sigma_b_a: np.ndarray | None = None
    sigma_b_g: np.ndarray | None = None
    fit_window: tuple | None = None
    levelled: bool = False
    yaw_evidence: str = "given"
    gyro_bias_at_rest: bool = False
    cov: np.ndarray | None = None

    @property
    def yaw_determined(self) -> bool:
        """Whether the yaw is known from the data or the source (not a guess of the start)."""
        return self.yaw_evidence in ("given", "bank")

    @property
    def R_nb(self) -> np.ndarray:
        return euler_to_dcm(*self.rpy)


@dataclass
class SimTruth:
    """What only a simulation knows about its IMU (:func:`gnssacc.sources.sim.simulate`).

    Attributes
    ----------
    bias : gnssacc.sources.sim_true_bias.TrueBias
        The accelerometer [m/s^2] and gyro [rad/s] bias in effect at each IMU sample (turn-on +
        Gauss-Markov + drift), body axes: drawn again from the run's streams when asked
        (``bias.at(t)`` at chosen epochs), not kept per sample.
    segments : list of dict
        The scenario log: one dict per motion segment (``kind``, ``t0``, ``t1`` [s], ``reverse``, ...).
    imu_error_draws : dict
        Per-run constants of the IMU error model (turn-on biases, scale factors, misalignments ...).
    imu_params : dict
        The filter-visible noise parameters of the simulated grade (configuration keys and units).
    imu_error_model : dict
        The full error description it was drawn from.
    odometry : dict or None
        The wheel odometry's per-run draws (``scale_factor``, ``yaw_factor``, ``kind`` ...:
        :func:`gnssacc.sources.sim_odometry.simulate_odometry`), when the run has odometry.
    """

    bias: object  # gnssacc.sources.sim_true_bias.TrueBias (a source type: the model does not import it)
    segments: list
    imu_error_draws: dict
    imu_params: dict
    imu_error_model: dict
    odometry: dict | None = None

    @property
    def true_bias_a(self) -> np.ndarray:
        """The accelerometer bias at every IMU sample [m/s^2], shape (N, 3) (drawn on each access)."""
        return self.bias.samples()[0]

    @property
    def true_bias_g(self) -> np.ndarray:
        """The gyro bias at every IMU sample [rad/s], shape (N, 3) (drawn on each access)."""
        return self.bias.samples()[1]


@dataclass
class RecordedRun:
    """One recorded (or simulated) run, ready for the estimators.

    Attributes
    ----------
    name : str
        Short name used in output folder names (e.g. ``kitti``).
    where : str
        Where the data came from (a path or a description); named in every error message.
    imu : ImuData
    gnss : GnssFixes
        The fixes the estimators may use (after noise and outages, for sources with truth).
    origin : LocalTangentFrame
        Tangent-plane origin for metric work and plots.
    truth : Truth or None
    init : InitialState or None
        Given initial state; ``None`` lets the estimators initialise themselves.
    outages : tuple of (float, float)
        GNSS outage spans applied to the fixes, seconds from the start (:func:`gnssacc.sources.gnss_noise.apply_outages`).
    sim : SimTruth or None
        A simulated run's IMU truths (true biases, scenario segments).
    odometry : WheelOdometry or None
        Wheel odometry, on the IMU's clock (shifted with it), when the source has it.
    gnss_vel : GnssVelocity or None
        GNSS (Doppler) velocities of the antenna, on the fixes' clock, when the source has them.
    truth_on_imu_clock : bool
        Whether the truth is stamped on the IMU's clock (a CSV run directory's ``truth.csv``,
        logged beside ``imu.csv``) and so shifted with it; else it is on the fixes' clock.
    meta : dict
        Small facts about the source (noise profile, seed, bag topics, ...): those of
        :data:`gnssacc.outputs.report.RUN_FIELDS` are written to ``metrics.json``.
    """

    name: str
    where: str
    imu: ImuData
    gnss: GnssFixes
    origin: LocalTangentFrame
    truth: Truth | None = None
    init: InitialState | None = None
    outages: tuple = ()
    sim: SimTruth | None = None
    meta: dict = field(default_factory=dict)
    odometry: WheelOdometry | None = None
    truth_on_imu_clock: bool = False
    gnss_vel: GnssVelocity | None = None

    @property
    def t_start(self) -> float:
        return float(self.imu.t[0])

    @property
    def t_end(self) -> float:
        return float(self.imu.t[-1])

    @property
    def duration_s(self) -> float:
        return self.t_end - self.t_start

    def validate(self) -> "RecordedRun":
        """Check shapes, finiteness and time order; raise :class:`InputError` naming the problem."""
        imu, gnss = self.imu, self.gnss
        if len(imu) < 2:
            raise InputError(self.where, "no IMU samples (need at least two)")
        if imu.f_b.shape != (len(imu), 3) or imu.omega_ib_b.shape != (len(imu), 3):
            raise InputError(self.where, "IMU arrays must have shape (N, 3)")
        check_increasing(imu.t, self.where, "IMU")
        if len(gnss) == 0:
            raise InputError(
                self.where, "no GNSS fix at all: at least one fix is needed to initialise"
            )
        check_increasing(gnss.t, self.where, "GNSS")
        for name, arr in (
            ("IMU time", imu.t),
            ("specific force", imu.f_b),
            ("angular rate", imu.omega_ib_b),
            ("GNSS time", gnss.t),
            ("GNSS latitude", gnss.lat),
            ("GNSS longitude", gnss.lon),
            ("GNSS height", gnss.h),
            ("GNSS sigma", gnss.sigma_ned),
        ):
            if not np.all(np.isfinite(arr)):
                raise InputError(self.where, f"{name} contains NaN or inf values")
        if np.any(gnss.sigma_ned <= 0):
            raise InputError(self.where, "GNSS sigmas must be positive metres")
        if np.any(np.abs(gnss.lat) > np.pi / 2) or np.any(np.abs(gnss.lon) > 2 * np.pi):
            raise InputError(
                self.where, "GNSS latitude/longitude out of range (are they degrees, not radians?)"
            )
        overlap = (gnss.t >= imu.t[0]) & (gnss.t <= imu.t[-1])
        if not np.any(overlap):
            raise InputError(
                self.where,
                f"GNSS fixes ({gnss.t[0]:.3f}..{gnss.t[-1]:.3f} s) do not overlap the IMU "
                f"time span ({imu.t[0]:.3f}..{imu.t[-1]:.3f} s): different clocks?",
            )
        _check_fix_extras(gnss, self.where)
        if self.truth is not None:
            check_increasing(self.truth.t, self.where, "truth")
        if self.gnss_vel is not None:
            check_gnss_velocity(self.gnss_vel, self.where)
        if self.odometry is not None:
            check_odometry(self.odometry, self.where)
            odo_t = self.odometry.t
            if odo_t[-1] < imu.t[0] or odo_t[0] > imu.t[-1]:
                raise InputError(
                    self.where,
                    f"wheel odometry ({odo_t[0]:.3f}..{odo_t[-1]:.3f} s) does not overlap the "
                    f"IMU time span ({imu.t[0]:.3f}..{imu.t[-1]:.3f} s): its times must be on "
                    f"the IMU's clock",
                )
        return self

    def with_imu_shift(self, delta_s: float) -> "RecordedRun":
        """A copy with ``delta_s`` [s] added to the time stamps of every stream on the IMU's clock:
        the IMU's, the wheel odometry's, and the truth's when :attr:`truth_on_imu_clock` (the
        fixes keep theirs)."""
        imu = self.imu
        odo = None if self.odometry is None else self.odometry.shifted(delta_s)
        truth = self.truth
        if truth is not None and self.truth_on_imu_clock:
            truth = replace(truth, t=truth.t + delta_s)
        return replace(
            self, imu=ImuData(imu.t + delta_s, imu.f_b, imu.omega_ib_b), odometry=odo, truth=truth
        )

    def with_mounting(self, R_bi: np.ndarray) -> "RecordedRun":
        """A copy with the body axes turned by ``R_bi`` (``x_b = R_bi x``, from the axes the run
        has): everything that lives in the IMU frame, in one place. The samples are rotated; a
        given start's attitude becomes ``R_nb R_bi^T`` and its bias estimates ``R_bi b`` (their
        variances rotated with them); its attitude sigmas are in n and stay."""
        R = np.asarray(R_bi, float)
        imu = ImuData(self.imu.t, self.imu.f_b @ R.T, self.imu.omega_ib_b @ R.T)
        init = self.init
        if init is not None:
            R2 = R * R

            def var_rot(sig):
                return None if sig is None else np.sqrt(R2 @ np.asarray(sig, float) ** 2)

            init = replace(
                init,
                rpy=np.array(dcm_to_euler(init.R_nb @ R.T)),
                b_a=R @ np.asarray(init.b_a, float),
                b_g=R @ np.asarray(init.b_g, float),
                sigma_b_a=var_rot(init.sigma_b_a),
                sigma_b_g=var_rot(init.sigma_b_g),
            )
        return replace(self, imu=imu, init=init)

    def imu_range(self, t_a: float, t_b: float) -> tuple[int, int]:
        """IMU samples ``[i0, i1)`` that :meth:`between` keeps for ``t_a`` .. ``t_b`` [s]: those
        stamped in it and the one holding at ``t_b`` (sample ``k`` holds over ``(t[k-1],
        t[k]]``)."""
        t = self.imu.t
        i0 = int(np.searchsorted(t, t_a, side="left"))
        i1 = min(int(np.searchsorted(t, t_b, side="left")) + 1, len(t))
        return i0, max(i0, i1)

    def between(self, t_a: float, t_b: float) -> "RecordedRun":
        """The run from ``t_a`` to ``t_b`` [s]: every stream's samples stamped in that span (the
        IMU's as views, :meth:`imu_range`), the truth too; the rest as it is but the start and
        the simulator's draws (per sample of the whole run), which it does not have. An
        estimator's pass over part of a long run reads this (the noise tuner's windows,
        :mod:`gnssacc.prepare.tune_windows`): its setup then costs the span, not the run."""
        i0, i1 = self.imu_range(t_a, t_b)
        imu = ImuData(self.imu.t[i0:i1], self.imu.f_b[i0:i1], self.imu.omega_ib_b[i0:i1])

        def inside(stream):
            if stream is None:
                return None
            return stream.select((stream.t >= t_a) & (stream.t <= t_b))

        return replace(
            self,
            imu=imu,
            gnss=inside(self.gnss),
            gnss_vel=inside(self.gnss_vel),
            odometry=inside(self.odometry),
            truth=inside(self.truth),
            init=None,
            sim=None,
        )

    def with_gnss(self, gnss: GnssFixes, **meta) -> "RecordedRun":
        """A copy with other GNSS fixes (e.g. noisy or with outages) and extra metadata."""
        return replace(self, gnss=gnss, meta={**self.meta, **meta})


def _check_fix_extras(gnss: GnssFixes, where: str) -> None:
    """Shapes and ranges of the optional per-fix quality codes and correlations."""
    m = len(gnss)
    if gnss.quality is not None and np.shape(gnss.quality) != (m,):
        raise InputError(where, f"GNSS quality codes must have shape ({m},)")
    if gnss.corr_ned is None:
        return
    if np.shape(gnss.corr_ned) != (m, 3):
        raise InputError(where, f"GNSS correlations must have shape ({m}, 3)")
    if not np.all(np.isfinite(gnss.corr_ned)) or np.any(np.abs(gnss.corr_ned) >= 1.0):
        raise InputError(where, "GNSS correlation coefficients must be finite and inside (-1, 1)")
    r_ne, r_nd, r_ed = np.asarray(gnss.corr_ned, float).T
    det = (
        1.0 + 2.0 * r_ne * r_nd * r_ed - r_ne**2 - r_nd**2 - r_ed**2
    )  # det of the correlation matrix
    bad = np.flatnonzero(det <= 0.0)
    if bad.size:
        k = int(bad[0])
        raise InputError(
            where,
            f"the GNSS fix covariance at t = {gnss.t[k]:.3f} s is not positive definite "
            f"(correlations {r_ne[k]:.3f}, {r_nd[k]:.3f}, {r_ed[k]:.3f}); {bad.size} such fix(es)",
        )


def check_odometry(odo: WheelOdometry, where: str) -> None:
    """Raise :class:`InputError` for wheel odometry of wrong shapes, non-finite values, times not
    increasing or non-positive sigmas."""
    k = len(odo.t)
    what = f"wheel odometry ({odo.frame})" if odo.frame else "wheel odometry"
    for name, arr in (
        ("speed", odo.v_forward),
        ("yaw rate", odo.yaw_rate),
        ("speed sigma", odo.sigma_v),
        ("yaw-rate sigma", odo.sigma_yaw_rate),
    ):
        if arr is None:
            continue
        if np.shape(arr) != (k,):
            raise InputError(where, f"{what}: {name} must have shape ({k},), as the times")
        if not np.all(np.isfinite(arr)):
            raise InputError(where, f"{what}: {name} contains NaN or inf values")
    for name, arr in (("speed sigma", odo.sigma_v), ("yaw-rate sigma", odo.sigma_yaw_rate)):
        if arr is not None and np.any(arr <= 0):
            raise InputError(where, f"{what}: {name} must be positive")
    check_increasing(odo.t, where, what)


def check_increasing(t: np.ndarray, where: str, what: str) -> None:
    """Raise :class:`InputError` if time stamps are not strictly increasing."""
    d = np.diff(t)
    bad = np.flatnonzero(d <= 0)
    if bad.size:
        k = int(bad[0])
        kind = "goes backwards" if d[k] < 0 else "repeats"
        raise InputError(
            where,
            f"{what} time {kind} at sample {k + 1} ({t[k]:.6f} s -> {t[k + 1]:.6f} s); "
            f"{bad.size} such place(s)",
        )


def drop_nonfinite(table: np.ndarray, where: str, what: str, max_fraction: float) -> np.ndarray:
    """Drop rows with NaN/inf, warning with the count; error above ``max_fraction`` of the rows.

    Parameters
    ----------
    table : ndarray, shape (N, K)
    where, what : str
        File and table names for the messages.
    max_fraction : float
        Largest tolerated fraction of bad rows (0..1).
    """
    good = np.all(np.isfinite(table), axis=1)
    n_bad = int((~good).sum())
    if n_bad:
        frac = n_bad / len(table)
        if frac > max_fraction:
            raise InputError(
                where,
                f"{n_bad} of {len(table)} {what} rows ({100 * frac:.1f}%) contain NaN/inf, "
                f"more than the allowed {100 * max_fraction:.1f}% (data.max_bad_fraction)",
            )
        warn_data(where, f"dropped {n_bad} of {len(table)} {what} rows with NaN/inf values")
        return table[good]
    return table  # no copy when every row is good: the common case, and a long run's largest array


def gap_indices(t: np.ndarray, factor: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The one gap rule (IMU checks, bag summaries): intervals ``t[k+1] - t[k]`` longer than
    ``factor`` (``[quality] gap_factor``) times the median interval.

    Returns
    -------
    idx : ndarray of int
        The ``k`` of each gap.
    dt : ndarray
        Every interval [s].
    dt_med : float
        The median interval [s] (NaN with fewer than two samples).
    """
    if len(t) < 2:
        return np.zeros(0, int), np.zeros(0), float("nan")
    dt = np.diff(t)
    dt_med = float(np.median(dt))
    return np.flatnonzero(dt > factor * dt_med), dt, dt_med
