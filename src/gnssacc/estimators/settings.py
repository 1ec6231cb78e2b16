"""What each estimator needs to know of the configuration, in SI units: its own small settings.

The run configuration (:class:`gnssacc.core.config.RunConfig`) is the user's file with its
documentation, presets and provenance; an estimator reads none of that. It reads one frozen
settings object, made from the configuration in one place here (:meth:`EkfSettings.from_config`,
:meth:`SmootherSettings.from_config`): the IMU noise model, the GNSS model (lever arm, Gauss-Markov
error), the acceleration window, the stationary updates, the non-holonomic constraint, the wheel
odometry, the start's sigma overrides, the
inflation of suspect IMU spans, and the estimator's own keys. The self-tuning changes the
configuration; the estimators see the result through a new settings object.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..checks.quality import SuspectNoise
from ..core.config import RunConfig, vec3
from ..core.recording import GnssFixes, GnssVelocity
from ..core.rotations import euler_to_dcm


@dataclass(frozen=True, eq=False)
class ImuNoise:
    """The IMU noise model per body axis.

    Attributes
    ----------
    accel_psd, gyro_psd : ndarray (3,)
        White noise PSD [(m/s^2)^2/s], [rad^2/s].
    accel_bias_rw_psd, gyro_bias_rw_psd : ndarray (3,)
        Bias random-walk PSD [(m/s^2)^2/s^3 s], [(rad/s)^2/s].
    accel_bias_sigma0, gyro_bias_sigma0 : ndarray (3,)
        Turn-on bias 1-sigma [m/s^2], [rad/s].
    gyro_turn_psd : float
        Gyro noise per unit rotation rate [rad^2/s per rad/s]: both estimators add
        ``gyro_turn_psd |omega|`` to each body axis's gyro PSD, ``omega`` the bias-corrected
        body rate [rad/s]. It stands for the constant scale-factor and cross-axis errors the
        model does not carry (:attr:`gnssacc.core.config.RunConfig.gyro_turn_psd`): the attitude
        variance they add grows with the angle turned, not with time.
    """

    accel_psd: np.ndarray
    gyro_psd: np.ndarray
    accel_bias_rw_psd: np.ndarray
    gyro_bias_rw_psd: np.ndarray
    accel_bias_sigma0: np.ndarray
    gyro_bias_sigma0: np.ndarray
    gyro_turn_psd: float = 0.0

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "ImuNoise":
        return cls(
            cfg.accel_psd,
            cfg.gyro_psd,
            cfg.accel_bias_rw_psd,
            cfg.gyro_bias_rw_psd,
            cfg.accel_bias_sigma0,
            cfg.gyro_bias_sigma0,
            cfg.gyro_turn_psd,
        )


@dataclass(frozen=True, eq=False)
class GnssModel:
    """The fixes' noise model: their stated sigmas times a scale, and what they do not state.

    Attributes
    ----------
    lever_arm_b : ndarray (3,)
        Antenna position relative to the IMU, body FRD [m].
    gm_sigma, gm_tau : ndarray (3,)
        First-order Gauss-Markov fix error per N, E, D: 1-sigma [m] (zeros: not modelled) and
        correlation time [s].
    sigma_scale : float
        The white fix noise is the stated sigma times this (``[gnss] sigma_scale``, which the
        noise tuner identifies); applied by :meth:`fixes`, where the estimators build the fixes'
        noise, and nowhere else.
    """

    lever_arm_b: np.ndarray
    gm_sigma: np.ndarray
    gm_tau: np.ndarray
    sigma_scale: float = 1.0

    @property
    def gauss_markov(self) -> bool:
        """Whether the Gauss-Markov error states are on."""
        return bool(np.any(self.gm_sigma > 0))

    def fixes(self, gnss: GnssFixes) -> GnssFixes:
        """The fixes ``gnss`` (as read) with this model's white noise: every sigma times
        :attr:`sigma_scale` (their correlations, when stated, unchanged)."""
        if self.sigma_scale == 1.0:
            return gnss
        return replace(gnss, sigma_ned=gnss.sigma_ned * self.sigma_scale)

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "GnssModel":
        return cls(
            cfg.lever_arm_b,
            cfg.gnss_gm_sigma,
            cfg.gnss_gm_tau,
            float(cfg["gnss"]["sigma_scale"]),
        )


@dataclass(frozen=True, eq=False)
class AccelSettings:
    """The GNSS-derived acceleration (``[accel]``).

    Attributes
    ----------
    window : int
        Fixes per least-squares window.
    max_gap_s : float
        A longer interval between fixes restarts the window [s].
    specific_force_avg_s : float
        Averaging of the measured specific force the paper's prediction uses [s].
    sigma_override : ndarray (3,) or None
        Fixed 1-sigma N, E, D [m/s^2] instead of the propagated covariance.
    """

    window: int
    max_gap_s: float
    specific_force_avg_s: float
    sigma_override: np.ndarray | None

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "AccelSettings":
        a = cfg["accel"]
        return cls(
            int(a["window"]),
            float(a["max_gap_s"]),
            float(a["specific_force_avg_s"]),
            cfg.accel_sigma_override,
        )


@dataclass(frozen=True)
class ZuptSettings:
    """The stationary updates (``[zupt]``): on or off, one every ``interval_s`` [s] inside a
    stationary span, zero-velocity 1-sigma [m/s], and the NIS gate (0: none)."""

    enabled: bool
    interval_s: float
    velocity_sigma_mps: float
    gate_nis: float

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "ZuptSettings":
        z = cfg["zupt"]
        return cls(
            bool(z["enabled"]),
            float(z["interval_s"]),
            float(z["velocity_sigma_mps"]),
            float(z["gate_nis"]),
        )


@dataclass(frozen=True, eq=False)
class NhcSettings:
    """The non-holonomic constraint (``[nhc]``; :mod:`gnssacc.estimators.aids.nhc`).

    Attributes
    ----------
    enabled : bool
    interval_s : float
        Spacing of the constraint's epochs [s].
    sigma_mps : ndarray (2,)
        1-sigma of the lateral and the vertical velocity at the reference point [m/s].
    lever_arm_b : ndarray (3,)
        The reference point from the IMU, body FRD [m].
    pivot_offset_m : float
        How far along the vehicle a turn's centre on the spot may lie from the reference point [m].
    R_vb : ndarray (3, 3) or None
        Body to vehicle axes (``[nhc] pitch_offset_deg``, ``yaw_offset_deg``: the vehicle's axes
        are the body's turned by that yaw, then that pitch); the wheel odometry's too. ``None``
        when both are zero (the body's axes).
    """

    enabled: bool
    interval_s: float
    sigma_mps: np.ndarray
    lever_arm_b: np.ndarray
    pivot_offset_m: float
    R_vb: np.ndarray | None

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "NhcSettings":
        c = cfg["nhc"]
        pitch, yaw = float(c["pitch_offset_deg"]), float(c["yaw_offset_deg"])
        R_vb = euler_to_dcm(0.0, np.radians(pitch), np.radians(yaw)).T if pitch or yaw else None
        return cls(
            bool(c["enabled"]),
            float(c["interval_s"]),
            np.array([float(c["sigma_lateral_mps"]), float(c["sigma_vertical_mps"])]),
            vec3(c["lever_arm_b_m"], "[nhc] lever_arm_b_m", "config"),
            float(c["pivot_offset_m"]),
            R_vb,
        )

    @property
    def forward_b(self) -> np.ndarray:
        """The vehicle's forward axis in body axes."""
        return np.array([1.0, 0.0, 0.0]) if self.R_vb is None else self.R_vb[0]


@dataclass(frozen=True, eq=False)
class OdometrySettings:
    """The wheel odometry (``[odometry]``; :mod:`gnssacc.estimators.aids.odometry`).

    Attributes
    ----------
    enabled : bool
        Use the recording's odometry when it has some.
    interval_s : float
        At most one sample every this many seconds [s].
    speed_sigma_mps : float
        1-sigma of the forward speed [m/s] (a sample's own larger sigma wins).
    lever_arm_b : ndarray (3,)
        The odometry's reference point from the IMU, body FRD [m].
    scale_sigma : float
        1-sigma of the scale-factor error (a first-order Gauss-Markov state) [-].
    scale_tau_s : float
        Its correlation time [s].
    """

    enabled: bool
    interval_s: float
    speed_sigma_mps: float
    lever_arm_b: np.ndarray
    scale_sigma: float
    scale_tau_s: float

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "OdometrySettings":
        c = cfg["odometry"]
        return cls(
            bool(c["enabled"]),
            float(c["interval_s"]),
            float(c["speed_sigma_mps"]),
            vec3(c["lever_arm_b_m"], "[odometry] lever_arm_b_m", "config"),
            float(c["scale_sigma"]),
            float(c["scale_tau_s"]),
        )


@dataclass(frozen=True)
class VelocitySettings:
    """The GNSS (Doppler) velocity (``[velocity]``; :mod:`gnssacc.estimators.aids.gnss_velocity`):
    on or off, the scale of the stated (or default) sigmas, and the NIS gate (0: none)."""

    enabled: bool = True
    sigma_scale: float = 1.0
    gate_nis: float = 0.0

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "VelocitySettings":
        v = cfg["velocity"]
        return cls(bool(v["enabled"]), float(v["sigma_scale"]), float(v["gate_nis"]))

    def velocities(self, vel: GnssVelocity | None) -> GnssVelocity | None:
        """The run's velocities with this model's noise (every sigma times :attr:`sigma_scale`),
        or ``None`` when off or the run has none."""
        if vel is None or not self.enabled or len(vel.t) == 0:
            return None
        if self.sigma_scale == 1.0:
            return vel
        return replace(vel, sigma_ned=vel.sigma_ned * self.sigma_scale)


@dataclass(frozen=True, eq=False)
class _Common:
    """Settings both estimators share (see the subclasses).

    Attributes
    ----------
    imu : ImuNoise
    gnss : GnssModel
    accel : AccelSettings
    zupt : ZuptSettings
    nhc : NhcSettings
    odometry : OdometrySettings
    velocity : VelocitySettings
    suspect : gnssacc.checks.quality.SuspectNoise
        The noise assumed over suspect IMU spans.
    start_sigmas : dict
        ``[init]`` overrides of the start's sigmas (SI: ``pos``, ``vel`` (3,), ``roll_pitch``,
        ``yaw`` [rad]); empty when none.
    """

    imu: ImuNoise
    gnss: GnssModel
    accel: AccelSettings
    zupt: ZuptSettings
    nhc: NhcSettings
    odometry: OdometrySettings
    velocity: VelocitySettings
    suspect: SuspectNoise
    start_sigmas: dict

    @staticmethod
    def common(cfg: RunConfig) -> dict:
        return dict(
            imu=ImuNoise.from_config(cfg),
            gnss=GnssModel.from_config(cfg),
            accel=AccelSettings.from_config(cfg),
            zupt=ZuptSettings.from_config(cfg),
            nhc=NhcSettings.from_config(cfg),
            odometry=OdometrySettings.from_config(cfg),
            velocity=VelocitySettings.from_config(cfg),
            suspect=SuspectNoise.from_config(cfg),
            start_sigmas=cfg.initial_sigma_overrides(),
        )


@dataclass(frozen=True, eq=False)
class EkfSettings(_Common):
    """The EKF's settings: the shared ones and ``[ekf]``.

    Attributes
    ----------
    phi_order : int
        Order of the transition matrix's series.
    position_gate_nis : float
        Reject a position update whose NIS exceeds this (0: never).
    """

    phi_order: int = 2
    position_gate_nis: float = 0.0

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "EkfSettings":
        e = cfg["ekf"]
        return cls(
            **cls.common(cfg),
            phi_order=int(e["phi_order"]),
            position_gate_nis=float(e["position_gate_nis"]),
        )

    @classmethod
    def of(cls, settings) -> "EkfSettings":
        """``settings`` as they are, or made from a :class:`RunConfig`."""
        return settings if isinstance(settings, cls) else cls.from_config(settings)


@dataclass(frozen=True, eq=False)
class SmootherSettings(_Common):
    """The smoother's settings: the shared ones and ``[smoother]``.

    Attributes
    ----------
    lag_s : float
        Fixed lag [s].
    max_node_spacing_s : float
        Longest interval between nodes [s] (nodes are added in long gaps between fixes).
    min_node_spacing_s : float
        Shortest interval between fixes taken as nodes [s] (faster fixes are folded into the
        node before them; 0: every fix is a node).
    factorization : str
        iSAM2's ``"QR"`` or ``"CHOLESKY"``.
    relinearize_threshold : float
    relinearize_skip : int
    integration_sigma : float
        Preintegration's integration 1-sigma.
    """

    lag_s: float = 20.0
    max_node_spacing_s: float = 1.0
    min_node_spacing_s: float = 0.5
    factorization: str = "QR"
    relinearize_threshold: float = 0.1
    relinearize_skip: int = 10
    integration_sigma: float = 1e-4

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "SmootherSettings":
        s = cfg["smoother"]
        return cls(
            **cls.common(cfg),
            lag_s=float(s["lag_s"]),
            max_node_spacing_s=float(s["max_node_spacing_s"]),
            min_node_spacing_s=float(s["min_node_spacing_s"]),
            factorization=str(s["factorization"]).upper(),
            relinearize_threshold=float(s["relinearize_threshold"]),
            relinearize_skip=int(s["relinearize_skip"]),
            integration_sigma=float(s["integration_sigma"]),
        )

    @classmethod
    def of(cls, settings) -> "SmootherSettings":
        """``settings`` as they are, or made from a :class:`RunConfig`."""
        return settings if isinstance(settings, cls) else cls.from_config(settings)
