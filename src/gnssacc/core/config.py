"""Run configuration: one TOML file, documented defaults, named presets.

Precedence: built-in defaults < preset (``--preset NAME``) < user file (``--config FILE``).
Every key is in physical units named in the key itself (``_deg_rth`` = deg/sqrt(h),
``_mps_rth`` = m/s/sqrt(h), ``_deg_h`` = deg/h, ``_mg`` = milli-g); internally everything is SI.
Vector keys take a scalar (same for all axes) or a list of three numbers (x, y, z of the IMU /
body frame, or N, E, D for navigation-frame quantities).

An example with every key at its default is printed by ``gnssacc config --show`` and listed in
docs/configuration.md.
"""

from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass, field
from dataclasses import fields as dataclass_fields
from importlib import resources
from pathlib import Path

import numpy as np

from .config_check import check_value, show
from .errors import InputError
from .rotations import euler_to_dcm
from .stationary_params import StationaryParams
from .units import DEG, G0  # noqa: F401 (re-exported: the configuration's units)


#: The turn angle [rad] over which the attitude error of a constant gyro cross-axis or scale-factor
#: error decorrelates: the error's direction turns with the body, so the tilt it builds over a turn
#: of angle ``a`` is ``2 sin(a / 2)`` times the error (per-axis variance ``sigma^2 (2 - 2 cos a)``,
#: ``0.92 sigma^2`` at one radian, at most ``4 sigma^2``). A random walk in the angle turned whose
#: variance grows by ``sigma^2`` per radian matches it at one radian.
TURN_DECORRELATION_RAD = 1.0
#: The turn allowance [ppm] of ``gyro_turn_error_ppm = "auto"`` until the gyro noise at rest is
#: known (:mod:`gnssacc.prepare.turn_allowance`), and on runs without a stationary span:
#: industrial MEMS.
FALLBACK_TURN_ERROR_PPM = 1000.0

#: Built-in defaults. Comments double as the documentation of each key.
DEFAULTS: dict[str, dict] = {
    "imu": {
        # Angle random walk of each gyro [deg/sqrt(h)] (white rate noise).
        "gyro_arw_deg_rth": 0.3,
        # Velocity random walk of each accelerometer [m/s/sqrt(h)] (white specific-force noise).
        "accel_vrw_mps_rth": 0.1,
        # Bias instability [deg/h] and [mg]; with bias_correlation_time_s they set the bias
        # random-walk density q = 2 sigma^2 / tau of the filter's random-walk bias states.
        "gyro_bias_instability_deg_h": 10.0,
        "accel_bias_instability_mg": 0.5,
        "bias_correlation_time_s": 300.0,
        # 1-sigma of the biases at start-up (turn-on bias) [deg/h] and [mg].
        "gyro_bias_sigma0_deg_h": 100.0,
        "accel_bias_sigma0_mg": 20.0,
        # 1-sigma of each gyro's constant scale-factor and cross-axis error [ppm] (datasheet:
        # scale-factor error, cross-axis sensitivity or misalignment). The 15-state model does not
        # carry them: every turn tilts the attitude by that fraction of the angle turned. Both
        # estimators cover it with gyro noise that grows with the rotation performed
        # (gnssacc.estimators.settings.ImuNoise.gyro_turn_psd); 0: none. "auto": from the gyro
        # white noise measured at rest (stationary spans of 10 s or more; without one, those of
        # 4 s or more) by the datasheet relation of gnssacc.prepare.turn_allowance (0.05
        # deg/sqrt(h): 150 ppm, 0.2: 1000, 0.6 and above: 10000); 1000 on a run without such a
        # span. A number is used as given.
        "gyro_turn_error_ppm": "auto",
        # 1-sigma of each accelerometer cross-axis error [ppm] (datasheet: cross-axis
        # sensitivity, axis-to-axis misalignment). The estimators follow the accelerometers' axes,
        # which these errors turn against the IMU's case by a rotation no measurement separates
        # from the attitude: 1/sqrt(2) of it per axis is the floor of the reported attitude sigma
        # (gnssacc.prepare.attitude_axes; not on the [nhc] angles the tuner searched). "auto":
        # the gyro turn allowance's value (the same IMU's class); 0: a calibrated triad.
        "accel_misalignment_ppm": "auto",
    },
    "mounting": {
        # Rotation from IMU axes to body (FRD) axes as roll, pitch, yaw [deg]:
        # f_body = R(roll, pitch, yaw) @ f_imu. An upside-down IMU is [180, 0, 0]. "auto": measured
        # from the recording (gravity gives roll/pitch, turns give yaw; gnssacc.checks.mountcheck)
        # and applied once the estimator proves it. With numbers, a recording that shows a clearly
        # different mounting (upside down, sideways, turned by 90 deg or more than 30 deg) is
        # proposed to the estimator, and a proven one is applied (or, with [checks] on_proof =
        # "refuse", an error naming the line to write).
        "imu_to_body_rpy_deg": [0.0, 0.0, 0.0],
        # Added to every IMU time stamp to put it on the GNSS clock [s]. A logger that stamps IMU
        # samples 0.1 s late needs -0.1; IMU stamps on UTC beside fixes on GPS time need +18.
        # "auto": measured from the recording (gnssacc.checks.timeoffset, up to +-60 s) and applied
        # once the estimator proves it. With a number, a measured offset many sigma and more than
        # 50 ms away from it is proposed to the estimator, and a proven one is applied (or, with
        # [checks] on_proof = "refuse", an error naming the measured value). Every stream on the
        # IMU's clock moves with it (a CSV run's odometry and truth: docs/formats.md).
        "imu_time_offset_s": 0.0,
    },
    "checks": {
        # Plausibility checks of the input before estimation (gnssacc.checks.plausibility): units, clocks,
        # coordinates and mounting checked against the data themselves; what they propose, the
        # estimator proves or refutes (gnssacc.prepare.judge). What to do with a proven correction
        # (a clock offset, a mounting, a unit): "apply" uses it and states it on the run's header
        # line, in metrics.json and in the report, with the evidence; "refuse" stops with an error
        # naming the setting that makes the data right, with the evidence (also: --strict).
        # Corrections the data cannot tell from another (swapped or sign-lost coordinates) are
        # refused either way, naming both.
        "on_proof": "apply",
        # Unit and layout repairs (accelerometer in g, gyro in deg/s, IMU stamps in ms/us/ns,
        # latitude/longitude in radians, the GNSS velocities' frame and time tags) under
        # on_proof = "apply": "auto" lets them be applied,
        # "never" refuses them as on_proof = "refuse" does.
        "repair": "auto",
        # Checks to leave out, comma-separated, for a recording that really is unusual: time_units,
        # fix_count, heights, accel_units, gyro_units, latlon, init_position, time_offset, mounting,
        # velocity_frame, velocity_time, velocity (the GNSS velocities: ENU as NED or the vertical
        # as up, their time tags, an axis against the fixes), truth (the truth against the fixes:
        # one that disagrees is not scored).
        "skip": "",
    },
    "gnss": {
        # Antenna position relative to the IMU, body frame FRD [m].
        "lever_arm_b_m": [0.0, 0.0, 0.0],
        # 1-sigma N, E, D [m] for fixes that carry no uncertainty of their own.
        "default_sigma_m": [3.0, 3.0, 5.0],
        # Every fix's 1-sigma is multiplied by this (receivers often state optimistic sigmas);
        # identified from the innovations by the noise tuner unless set here.
        "sigma_scale": 1.0,
        # Time-correlated part of the fix errors (multipath, atmosphere): a first-order
        # Gauss-Markov process per N, E, D axis with this 1-sigma [m] and correlation time [s],
        # estimated by the EKF as three more states. 0: white fixes. The tuner adds it when the
        # innovations show time-correlated errors.
        "gm_sigma_m": 0.0,
        "gm_tau_s": 60.0,
        # Fixes by their stated quality (RTKLIB .pos Q, NMEA GGA quality; names fix, float, sbas,
        # dgps, single, ppp, estimated, unknown): "drop" leaves them out, a number multiplies their
        # stated sigmas, e.g. quality = { single = "drop", float = 3.0 }. Empty: every fix is kept
        # with its stated sigmas.
        "quality": {},
        # NMEA fixes without a GST sentence get sigmas from HDOP, an assumption: north and east
        # HDOP x UERE / sqrt(2), down nmea_vertical_factor x HDOP x UERE, with this UERE [m] per fix
        # quality (keys as for quality; a key not given keeps its default here).
        "nmea_uere_m": {
            "fix": 0.02,
            "float": 0.3,
            "sbas": 1.0,
            "dgps": 0.7,
            "single": 3.0,
            "ppp": 0.2,
            "estimated": 10.0,
            "unknown": 5.0,
        },
        # VDOP / HDOP assumed for those fixes (open-sky geometries give about 1.5 to 2).
        "nmea_vertical_factor": 1.7,
    },
    "accel": {
        # Number m of fixes in the least-squares acceleration window (>= 3).
        "window": 3,
        # The window is reset when two consecutive fixes are further apart than this [s].
        "max_gap_s": 2.5,
        # Fixed 1-sigma N, E, D [m/s^2] for the GNSS-derived acceleration. Empty: propagate the
        # fix covariances through B (the default), Sigma_a = sum_j B_j^2 Sigma_p_j.
        "sigma_mps2": [],
        # Average the specific force over this many seconds before the epoch (0 = the paper's
        # choice: the sample at the epoch). ekf-acc and smoother-acc only: the window-consistent
        # methods (-accw) weight the specific force over the fixes' whole window instead.
        "specific_force_avg_s": 0.0,
    },
    "init": {
        # Initial 1-sigma overrides; empty = use the source's init.json or the self-initialiser's
        # own (data-derived) sigmas. Position N/E/D [m], velocity N/E/D [m/s], roll/pitch and
        # yaw [deg].
        "pos_sigma_m": [],
        "vel_sigma_mps": [],
        "roll_pitch_sigma_deg": [],
        "yaw_sigma_deg": [],
        # Self-initialisation (used when the source gives no initial state): the filter starts
        # at the first IMU sample; yaw comes from a bank of this many hypotheses, each run
        # through the EKF and scored by its innovation likelihood ...
        "yaw_hypotheses": 12,
        # ... from the start until this long after the vehicle starts to move [s] (doubled until
        # the yaw is found or the run ends) ...
        "yaw_horizon_s": 60.0,
        # ... and found once the hypotheses agreeing with the best one hold this posterior mass.
        "yaw_confidence": 0.99,
        # Position/velocity of a moving start from a straight-line fit over this many seconds.
        "course_fit_s": 4.0,
        # Floors on the self-initialised sigmas (roll/pitch [deg], velocity [m/s]).
        "roll_pitch_sigma_min_deg": 1.0,
        "vel_sigma_min_mps": 0.3,
    },
    "ekf": {
        # Order of the transition-matrix series Phi = I + F dt (+ (F dt)^2 / 2 for 2).
        "phi_order": 1,
        # Reject a position fix whose normalised innovation squared exceeds this (0 = never).
        # The noise tuner identifies the noise from every fix (a gate would steer it).
        "position_gate_nis": 0.0,
    },
    "zupt": {
        # Zero-velocity and zero-angular-rate updates (EKF) and factors (smoother) while IMU and
        # GNSS agree that the vehicle stands still. false: paper-pure comparisons.
        "enabled": True,
        # One update every this many seconds inside a stationary span; the zero-rate update
        # compares the mean gyro over the same interval [s].
        "interval_s": 1.0,
        # 1-sigma of the zero-velocity pseudo-measurement [m/s] (a parked vehicle's body sway).
        "velocity_sigma_mps": 0.02,
        # Reject a stationary update whose normalised innovation squared exceeds this (0 = never):
        # a safety net against a wrong detection (chi-square, 3 dof: 30 has p ~ 1e-6).
        "gate_nis": 30.0,
    },
    "nhc": {
        # Non-holonomic constraint: while the vehicle rolls, its velocity at the reference point
        # below has no lateral and no vertical component in the body frame (EKF updates, smoother
        # factors; gnssacc.estimators.aids.nhc says when it is applied). false: IMU-only bridging of outages.
        "enabled": True,
        # One constraint every this many seconds while rolling [s] (EKF update, smoother factor
        # on the node nearest each epoch).
        "interval_s": 1.0,
        # 1-sigma of the lateral and the vertical velocity at the reference point [m/s] (tyre
        # slip, suspension, a residual mounting yaw or pitch times the speed); identified by
        # the noise tuner unless set here.
        "sigma_lateral_mps": 0.1,
        "sigma_vertical_mps": 0.1,
        # The point of the vehicle that does not slip sideways (rear axle centre of a car,
        # centre of a skid-steer vehicle) from the IMU, body frame FRD [m].
        "lever_arm_b_m": [0.0, 0.0, 0.0],
        # The vehicle's forward axis relative to the body's (the IMU after [mounting]): pitch and
        # yaw [deg] of a residual misalignment, a fraction of a degree that the mounting check
        # cannot resolve but that makes the constraint see speed x angle of side or vertical
        # velocity; identified by the noise tuner unless set here.
        "pitch_offset_deg": 0.0,
        "yaw_offset_deg": 0.0,
        # How far along the vehicle the centre of a turn on the spot may lie from that point [m]:
        # a turn whose yaw rate times this exceeds the forward speed is not rolling, and gets
        # no constraint (see gnssacc.estimators.aids.nhc).
        "pivot_offset_m": 0.5,
    },
    "odometry": {
        # Wheel odometry (forward speed) when the recording has it: EKF updates with a
        # scale-factor state, smoother factors with a scale variable. false: ignore it.
        "enabled": True,
        # At most one odometry sample every this many seconds is used [s].
        "interval_s": 0.2,
        # 1-sigma of the forward speed [m/s] (wheel slip, quantisation; a sample's own stated
        # sigma is used when larger); identified by the noise tuner unless set here.
        "speed_sigma_mps": 0.1,
        # The odometry's reference point (the rear axle centre of a car) from the IMU, body FRD [m].
        "lever_arm_b_m": [0.0, 0.0, 0.0],
        # The wheel-radius scale factor error: 1-sigma at the start and its correlation time [s]
        # (a first-order Gauss-Markov state: tyre pressure and load change slowly).
        "scale_sigma": 0.03,
        "scale_tau_s": 3600.0,
    },
    "velocity": {
        # GNSS (Doppler) velocity of the antenna when the recording has it: EKF updates and
        # smoother factors beside the fixes (also --velocity on|off). false: positions only.
        "enabled": True,
        # Every velocity's 1-sigma is multiplied by this (a receiver's stated speed accuracy, or
        # a reader's documented default where the format states none); identified from the
        # innovations by the noise tuner unless set here.
        "sigma_scale": 1.0,
        # Reject a velocity whose normalised innovation squared exceeds this (0 = never).
        "gate_nis": 0.0,
        # 1-sigma N, E, D [m/s] of velocities whose format states none (NMEA speed and course,
        # comma2k19's u-blox speed, gnss.csv without sigma columns, a bare twist topic): the order
        # of a consumer receiver's Doppler velocity; sigma_scale (tuned) multiplies it.
        "default_sigma_mps": [0.1, 0.1, 0.2],
    },
    # Stationary detection thresholds: the fields of gnssacc.prepare.stationary.StationaryParams, whose
    # docstring gives each one's unit and physical reason (windowed IMU statistics + GNSS agreement).
    "stationary": {f.name: f.default for f in dataclass_fields(StationaryParams)},
    "tune": {
        # "auto": identify every IMU noise key (and gnss.sigma_scale) the configuration does not
        # set, from stationary stretches and the innovation likelihood of the EKF; "none": use
        # the configuration as given.
        "mode": "auto",
        # Budget of EKF passes of each maximum-likelihood search (the white-noise one and, when the
        # innovations show time-correlated GNSS errors, the one with the Gauss-Markov model).
        "max_evaluations": 50,
        # Innovations scored: "position" (and stationary updates), or "position+accel" (the
        # acceleration updates too, with the method ekf-acc).
        "likelihood": "position",
        # Width of the weak log-normal prior around the starting values [decades]: keeps the
        # parameters the data barely inform from wandering.
        "prior_decades": 1.0,
        # ... and around a white-noise density measured on stationary stretches [decades]: that
        # measurement is direct, while 1 Hz metre-level fixes hardly inform the white noise.
        "stationary_prior_decades": 0.3,
        # The covariance is propagated every this many IMU samples while tuning (speed; the
        # likelihood changes by far less than its sampling noise).
        "cov_every": 10,
    },
    "smoother": {
        # Fixed-lag window of the iSAM2 smoother [s]: the future a node's estimate sees before it
        # leaves. An offline run has no latency to keep short; 20 s against 10 s is 5-16 % more
        # accurate at 1-2 Hz fixes at about the same NEES (bench/diag_smoother_lag.py).
        "lag_s": 20.0,
        # Largest spacing of nodes [s]; during GNSS outages nodes are added at this spacing so
        # IMU-only segments stay short.
        "max_node_spacing_s": 1.0,
        # Shortest spacing of the fixes taken as nodes [s]: faster fixes are folded into the node
        # before them as factors through the preintegrated IMU (the smoother's time per second
        # of data stays that of this node rate; 0: a node per fix). Fixes at up to 1 / this rate
        # are all nodes.
        "min_node_spacing_s": 0.5,
        # iSAM2 factorization: "QR" (robust to the stiff bias random walk of good IMUs) or
        # "CHOLESKY" (faster, but ill-conditioned problems raise and are recovered from).
        "factorization": "QR",
        # iSAM2 relinearization threshold (tangent-space norm) and skip (updates; GTSAM's
        # default 10: 1 costs ~20 % more time for < 0.01 m PRMSE on KITTI).
        "relinearize_threshold": 0.1,
        "relinearize_skip": 10,
        # 1-sigma of the preintegration (position) integration error [m/s/sqrt(s)].
        "integration_sigma": 1e-4,
    },
    "quality": {
        # Flag straight-line (interpolated) IMU stretches lasting at least this long [s].
        "interp_min_s": 0.2,
        # ... where every channel's second difference stays below this (absolute, SI units).
        "interp_tol": 1e-6,
        # A gap is an IMU interval longer than this many median intervals.
        "gap_factor": 3.0,
        # Frozen or saturated channels must last this many samples to be flagged.
        "stuck_min_samples": 5,
        # Over flagged spans the estimators add process noise, per IMU channel, as if the rate /
        # specific force were wrong by an unknown constant of 1-sigma s for the whole span.
        # "local": s = the channel's standard deviation over the clean samples within
        # suspect_local_window_s before and after the span (how much that channel really varies
        # there), capped by the sigmas below. "fixed": s = the sigmas below on every channel.
        "suspect_sigma_mode": "local",
        "suspect_local_window_s": 2.0,
        "suspect_gyro_sigma_dps": 20.0,
        "suspect_accel_sigma_mps2": 2.0,
    },
    "bag": {
        # Custom GNSS fix message types, by type name, e.g.
        #   [bag.fix_mappings."mypkg/msg/MyFix"]
        #   lat = "position.latitude"; lon = "position.longitude"; height = "position.altitude"
        #   latlon_scale_deg = 1e-7; height_scale_m = 1e-3; sigma_n = "acc.h"; sigma_d = "acc.v"
        # Keys: lat, lon, height (field paths), latlon_scale_deg, height_scale_m, sigma_n, sigma_e,
        # sigma_d, sigma_scale_m, stamp, status, no_fix_values. The ROOAD layout
        # (ubxtranslator/msg/hpposllh) is built in.
        "fix_mappings": {},
    },
    "data": {
        # Largest fraction of NaN/inf rows a table may have before it is an error (0..1).
        "max_bad_fraction": 0.01,
    },
}

#: Packaged presets: IMU grades (documented starting points for the noise tuner) and KITTI.
PRESETS = ("consumer", "industrial", "tactical", "kitti")


def vec3(value, key: str, where: str) -> np.ndarray:
    """A configuration value as a 3-vector: a scalar (the same for every axis) or three numbers;
    :class:`InputError` naming ``key`` and ``where`` otherwise."""
    try:
        arr = np.atleast_1d(np.asarray(value, float))
    except (TypeError, ValueError):
        raise InputError(
            where, f"{key} must be a number or a list of three numbers, got {value!r}"
        ) from None
    if arr.size == 1:
        arr = np.repeat(arr, 3)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InputError(where, f"{key} must be a number or a list of three numbers, got {value!r}")
    return arr


def _merge(base: dict, update: dict, where: str) -> None:
    for section, values in update.items():
        if section not in base:
            raise InputError(
                where, f"unknown config section [{section}] (known: {', '.join(base)})"
            )
        if not isinstance(values, dict):
            raise InputError(
                where,
                f"{section} = {show(values)}: [{section}] must be a table (a [{section}] "
                f"header followed by key = value lines), not a single value",
            )
        for key, value in values.items():
            if key not in base[section]:
                raise InputError(
                    where,
                    f"unknown config key [{section}] {key} (known: {', '.join(base[section])})",
                )
            base[section][key] = value


def _keys(tree: dict) -> set:
    return {(sec, key) for sec, vals in tree.items() if isinstance(vals, dict) for key in vals}


def _read_toml(path: Path, where: str) -> dict:
    if path.is_dir():
        raise InputError(where, "is a directory, expected a TOML configuration file")
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(where, "config file not found") from None
    except OSError as exc:
        raise InputError(where, f"cannot read the config file: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(
            where,
            f"not a UTF-8 text file (byte 0x{data[exc.start]:02x} on line {line}); a TOML "
            f"file must be UTF-8: save it again with UTF-8 encoding",
        ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(where, f"not valid TOML: {exc}") from None


@dataclass
class RunConfig:
    """A fully resolved configuration (raw values plus SI-unit accessors).

    Attributes
    ----------
    values : dict
        Section -> key -> value, as in the TOML files.
    sources : list of str
        Where the values came from, in order of precedence.
    explicit : frozenset of (str, str)
        Keys the user set (file or overrides), as opposed to defaults and presets.
    """

    values: dict
    sources: list
    #: ``(section, key)`` pairs set by the user's file or overrides (never by a preset): the noise
    #: tuner leaves these alone.
    explicit: frozenset = frozenset()
    #: ``(section, key)`` -> the preset, file or ``"overrides"`` that set it (defaults: absent).
    origin: dict = field(default_factory=dict)

    def __getitem__(self, section: str) -> dict:
        return self.values[section]

    # --- IMU noise in SI units -------------------------------------------------------------
    @property
    def gyro_psd(self) -> np.ndarray:
        """White gyro noise PSD per axis [rad^2/s]."""
        return (
            vec3(self["imu"]["gyro_arw_deg_rth"], "gyro_arw_deg_rth", "config") * DEG / 60.0
        ) ** 2

    @property
    def gyro_turn_psd(self) -> float:
        """Gyro noise per unit rotation rate for the constant scale-factor and cross-axis errors
        [rad^2/s per rad/s = rad]: ``(gyro_turn_error_ppm 1e-6)^2`` times one radian
        (:data:`TURN_DECORRELATION_RAD`), see :class:`gnssacc.estimators.settings.ImuNoise`;
        ``"auto"`` not yet set from the recording: :data:`FALLBACK_TURN_ERROR_PPM`."""
        value = self["imu"]["gyro_turn_error_ppm"]
        ppm = FALLBACK_TURN_ERROR_PPM if value == "auto" else float(value)
        return (ppm * 1e-6) ** 2 * TURN_DECORRELATION_RAD

    @property
    def accel_psd(self) -> np.ndarray:
        """White accelerometer noise PSD per axis [(m/s^2)^2/s]."""
        return (vec3(self["imu"]["accel_vrw_mps_rth"], "accel_vrw_mps_rth", "config") / 60.0) ** 2

    @property
    def gyro_bias_rw_psd(self) -> np.ndarray:
        """Gyro bias random-walk PSD per axis [(rad/s)^2/s]."""
        s = vec3(
            self["imu"]["gyro_bias_instability_deg_h"], "gyro_bias_instability_deg_h", "config"
        )
        return 2.0 * (s * DEG / 3600.0) ** 2 / float(self["imu"]["bias_correlation_time_s"])

    @property
    def accel_bias_rw_psd(self) -> np.ndarray:
        """Accelerometer bias random-walk PSD per axis [(m/s^2)^2/s]."""
        s = vec3(self["imu"]["accel_bias_instability_mg"], "accel_bias_instability_mg", "config")
        return 2.0 * (s * 1e-3 * G0) ** 2 / float(self["imu"]["bias_correlation_time_s"])

    @property
    def gyro_bias_sigma0(self) -> np.ndarray:
        """Initial gyro bias 1-sigma per axis [rad/s]."""
        return (
            vec3(self["imu"]["gyro_bias_sigma0_deg_h"], "gyro_bias_sigma0_deg_h", "config")
            * DEG
            / 3600.0
        )

    @property
    def accel_bias_sigma0(self) -> np.ndarray:
        """Initial accelerometer bias 1-sigma per axis [m/s^2]."""
        return (
            vec3(self["imu"]["accel_bias_sigma0_mg"], "accel_bias_sigma0_mg", "config") * 1e-3 * G0
        )

    # --- geometry ------------------------------------------------------------------------------
    @property
    def R_bi(self) -> np.ndarray:
        """Rotation from IMU axes to body axes (``f_b = R_bi @ f_imu``); the identity for
        ``"auto"`` (the sources load the IMU axes as they are and the input checks apply the
        measured mounting)."""
        return euler_to_dcm(*(self.imu_to_body_rpy_deg * DEG))

    @property
    def imu_to_body_rpy_deg(self) -> np.ndarray:
        """``[mounting] imu_to_body_rpy_deg`` as roll, pitch, yaw [deg]; zeros for ``"auto"``."""
        value = self["mounting"]["imu_to_body_rpy_deg"]
        if value == "auto":
            return np.zeros(3)
        return vec3(value, "imu_to_body_rpy_deg", "config")

    @property
    def default_sigma_ned(self) -> np.ndarray:
        """1-sigma N, E, D [m] of fixes that carry no uncertainty of their own."""
        return vec3(self["gnss"]["default_sigma_m"], "gnss.default_sigma_m", "config")

    @property
    def default_velocity_sigma(self) -> np.ndarray:
        """1-sigma N, E, D [m/s] of GNSS velocities that carry no uncertainty of their own."""
        return vec3(self["velocity"]["default_sigma_mps"], "velocity.default_sigma_mps", "config")

    @property
    def lever_arm_b(self) -> np.ndarray:
        """GNSS antenna position relative to the IMU in the body frame [m]."""
        return vec3(self["gnss"]["lever_arm_b_m"], "lever_arm_b_m", "config")

    @property
    def gnss_gm_sigma(self) -> np.ndarray:
        """1-sigma of the GNSS Gauss-Markov error per N, E, D axis [m] (zeros: not modelled)."""
        return vec3(self["gnss"]["gm_sigma_m"], "gm_sigma_m", "config")

    @property
    def gnss_gm_tau(self) -> np.ndarray:
        """Correlation time of the GNSS Gauss-Markov error per axis [s]."""
        return vec3(self["gnss"]["gm_tau_s"], "gm_tau_s", "config")

    @property
    def accel_sigma_override(self) -> np.ndarray | None:
        """Fixed acceleration-measurement 1-sigma N, E, D [m/s^2], or ``None`` to propagate."""
        v = self["accel"]["sigma_mps2"]
        if v is None or (isinstance(v, list) and len(v) == 0):
            return None
        return vec3(v, "accel.sigma_mps2", "config")

    def initial_sigma_overrides(self) -> dict:
        """Configured initial sigmas in SI units: keys ``pos``, ``vel`` (3,), ``roll_pitch``, ``yaw`` [rad]."""
        c, out = self["init"], {}
        for key, name, scale in (("pos_sigma_m", "pos", 1.0), ("vel_sigma_mps", "vel", 1.0)):
            if c[key] not in ([], None):
                out[name] = vec3(c[key], f"[init] {key}", "config") * scale
        for key, name in (("roll_pitch_sigma_deg", "roll_pitch"), ("yaw_sigma_deg", "yaw")):
            if c[key] not in ([], None):
                v = float(c[key])
                if not v > 0:
                    raise InputError("config", f"[init] {key} must be a positive number of degrees")
                out[name] = v * DEG
        return out

    def with_values(self, updates: dict, source: str) -> "RunConfig":
        """A copy with ``updates`` (section -> key -> value) applied, recorded as ``source``.

        The updated keys do not become explicit: they were not set by the user.
        """
        values = copy.deepcopy(self.values)
        _merge(values, updates, source)
        origin = {**self.origin, **dict.fromkeys(_keys(updates), source)}
        return RunConfig(values, self.sources + [source], self.explicit, origin)


def toml_value(value) -> str:
    if isinstance(value, dict):
        return "{" + ", ".join(f'"{k}" = {toml_value(v)}' for k, v in value.items()) + "}"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value + '"'
    return repr(value)


def preset_path(name: str):
    """Path-like of a packaged preset TOML file."""
    if name not in PRESETS:
        raise InputError(f"--preset {name}", f"unknown preset (known: {', '.join(PRESETS)})")
    return resources.files("gnssacc") / "presets" / f"{name}.toml"


def load_config(
    preset: str | None = None, path: str | Path | None = None, overrides: dict | None = None
) -> RunConfig:
    """Resolve the run configuration.

    Parameters
    ----------
    preset : str, optional
        A packaged preset name (e.g. ``"kitti"``).
    path : str or Path, optional
        A user TOML file; its keys override the preset's.
    overrides : dict, optional
        Section -> key -> value applied last (used by tests and the API); like the file's keys
        they count as set explicitly (:attr:`RunConfig.explicit`).

    Returns
    -------
    RunConfig

    Raises
    ------
    InputError
        Unknown preset, missing or malformed file, unknown section or key.
    """
    values = copy.deepcopy(DEFAULTS)
    sources = ["defaults"]
    origin: dict = {}  # (section, key) -> the preset or file that set it, named in messages
    if preset:
        layer = tomllib.loads(preset_path(preset).read_text())
        _merge(values, layer, f"preset {preset}")
        sources.append(f"preset {preset}")
        origin.update(dict.fromkeys(_keys(layer), f"preset {preset}"))
    explicit = set()
    if path:
        user = _read_toml(Path(path), str(path))
        _merge(values, user, str(path))
        sources.append(str(path))
        explicit |= _keys(user)
        origin.update(dict.fromkeys(_keys(user), str(path)))
    if overrides:
        _merge(values, overrides, "overrides")
        sources.append("overrides")
        explicit |= _keys(overrides)
        origin.update(dict.fromkeys(_keys(overrides), "overrides"))
    cfg = RunConfig(values, sources, frozenset(explicit), origin)
    _validate(cfg, sources[-1], origin)
    return cfg


def _validate(cfg: RunConfig, where: str, origin: dict | None = None) -> None:
    """Raise :class:`InputError` for the first key of the wrong type or out of range.

    Types and ranges are those of :mod:`gnssacc.core.config_check`. ``origin`` maps ``(section, key)``
    to the file (or preset) that set the key, named in the message; other keys are named ``where``.
    """
    origin = origin or {}
    for section, values in cfg.values.items():
        for key, value in values.items():
            problem = check_value(section, key, value, DEFAULTS.get(section, {}).get(key))
            if problem:
                raise InputError(origin.get((section, key), where), problem)
    # Touch every derived quantity so malformed values fail now, naming the file.
    for name in (
        "gyro_psd",
        "gyro_turn_psd",
        "accel_psd",
        "gyro_bias_rw_psd",
        "accel_bias_rw_psd",
        "gyro_bias_sigma0",
        "accel_bias_sigma0",
        "R_bi",
        "lever_arm_b",
        "accel_sigma_override",
        "initial_sigma_overrides",
    ):
        try:
            value = getattr(cfg, name)
            if callable(value):
                value()
        except InputError as exc:
            raise InputError(where, exc.problem) from None
