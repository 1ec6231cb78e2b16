"""Ground-vehicle simulator: scenarios with known truth, WGS-84-consistent IMU, GNSS fixes.

The simulator produces :class:`gnssacc.core.recording.RecordedRun` objects for tests of the estimators.
Its parts: :mod:`.sim_scenarios` (speed / yaw / pitch profiles), :mod:`.sim_path` (the path on
the ellipsoid, the error-free IMU), :mod:`.sim_imu_errors` (grades and IMU errors),
:mod:`.sim_vibration` (engine and road vibration) and this module (the run). Their public names
are re-exported here.

Memory: a run is made in one sweep over its time span in blocks (:mod:`.sim_path`), each block's
IMU samples finished (errors added) as it passes, so beside the run's own arrays (the IMU, 7
floats per sample) the simulator holds a few blocks and, for the road vibration's FFT synthesis,
about three floats per sample at a time; every number is the one a single pass over whole-run
arrays gives, bit for bit. The true biases are not kept per sample: :class:`.sim_true_bias.TrueBias`
draws them again from the run's streams when they are scored.

Conventions
-----------
* Body frame b is Front-Right-Down, navigation frame n is North-East-Down, ``R_nb`` maps body
  vectors into n, Euler angles are Z-Y-X roll/pitch/yaw [rad], SI units throughout.
* The vehicle has no side slip: body x points along the velocity (against it when reversing,
  at negative speed), pitch follows the slope of the path, roll is zero, yaw is the heading of
  body x. ``v_n = R_nb @ [speed, 0, 0]`` with a signed speed.
* The truth point (``lat, lon, h``, ``v_n``) is the IMU / body origin. GNSS fixes are of the
  antenna at ``lever_arm_b`` (body frame) from it.
* IMU sample ``k`` at time ``t[k]`` is the AVERAGE over the interval ``(t[k-1], t[k]]`` of
  length ``dt = 1 / imu_rate_hz`` (an integrating IMU, ``dv / dt`` and ``dtheta / dt``):

  - ``omega_ib_b[k] = rotvec(C_{b(k-1)}^{b(k)}) / dt`` where ``C_{b(k-1)}^{b(k)}`` is the exact
    inertial attitude increment of the body over the interval,
    ``R_nb(k-1)^T  C_{n(k-1)}^{n(k)}  R_nb(k)``, and ``C_{n(k-1)}^{n(k)}`` the rotation of the
    navigation frame w.r.t. inertial space (earth rotation plus transport) over the interval.
    A strapdown update ``R_nb(k) = exp(-[omega_in^n dt x]) R_nb(k-1) exp([omega_ib_b[k] dt x])``
    therefore reproduces the truth.
  - ``f_b[k] = R_nb(t_mid)^T (1/dt) integral of (dv_n/dt - g_n + (2 omega_ie^n + omega_en^n) x v_n) dt``
    with ``R_nb(t_mid)`` the true attitude at the interval midpoint: rotating the sample with the
    average (mid-interval) attitude reproduces the true velocity change.

  The first IMU sample is at the truth start ``t_start_s`` and averages the interval just
  before it (the trajectory is extended backwards at its initial speed and heading).
* The measured IMU adds the errors of the grade to these averages, per sensor triad
  ``(I + S + M) true + bias + white noise + vibration`` (:mod:`.sim_imu_errors`); the vibration
  is itself averaged over each interval (:mod:`.sim_vibration`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.earth import LocalTangentFrame
from ..core.errors import InputError
from ..core.memory import release_free_memory
from ..core.recording import GnssFixes, ImuData, InitialState, RecordedRun, SimTruth
from ..core.units import DEG
from .gnss_noise import (
    PROFILE_QUALITY,
    PROFILES,
    antenna_velocity,
    fixes_from_truth,
    velocities_from_truth,
)
from .sim_imu_errors import (  # noqa: F401 (re-exported)
    GRADE_KEYS,
    IMU_EXTRA_ERRORS,
    IMU_GRADES,
    MODEL_KEYS,
    UNMODELLED_KEYS,
    VIBRATION_ENVIRONMENT,
    BiasDrift,
    ImuErrorStream,
    bias_drift,
    gauss_markov,
    grade_config,
    imu_error_model,
    imu_errors,
    imu_sigmas_si,
    per_axis,
    sensor_matrices,
)
from .sim_odometry import KINDS as ODOMETRY_KINDS
from .sim_odometry import odometry_kind, simulate_odometry
from .sim_path import (  # noqa: F401 (re-exported)
    IMU_BLOCK,
    GridBlock,
    Trajectory,
    TruthSamples,
    build_trajectory,
    dense_truth,
    perfect_imu,
    sample_times,
    sweep_imu,
)
from .sim_scenarios import (  # noqa: F401 (re-exported)
    SCENARIOS,
    Kinematics,
    Pulse,
    R_nb_batch,
    Scenario,
    make_scenario,
    reversing_spans,
)
from .sim_true_bias import TrueBias  # noqa: F401 (re-exported)
from .sim_vibration import (  # noqa: F401
    EngineVibration,
    band_limited_columns,
    engine_vibration,
    road_scale,
    road_vibration,
)

WHERE = "simulator"


def _initial_state(truth0: TruthSamples) -> InitialState:
    return InitialState(
        t=float(truth0.t[0]),
        lat=float(truth0.lat[0]),
        lon=float(truth0.lon[0]),
        h=float(truth0.h[0]),
        v_n=truth0.v_n[0].copy(),
        rpy=truth0.rpy[0].copy(),
        sigma_pos_m=np.array([1.0, 1.0, 1.5]),
        sigma_vel_mps=np.array([0.1, 0.1, 0.1]),
        sigma_att_rad=np.array([1.0, 1.0, 2.0]) * DEG,
        how="simulator truth (sigmas 1 m, 0.1 m/s, 1-2 deg)",
    )


def _nonzero(model: dict, *keys: str) -> bool:
    return any(np.any(np.asarray(model[k], float) != 0.0) for k in keys)


@dataclass
class UnmodelledErrors:
    """The errors a filter does not model, drawn for one run: scale factor and cross-axis, bias
    drift, vibration (made by :func:`unmodelled_errors`, evaluated as the run's samples are made).

    Attributes
    ----------
    K_a, K_g : ndarray, shape (3, 3), or None
        ``I + S + M`` of the accelerometers and the gyros (None: the identity).
    drift : BiasDrift or None
        The slow bias drift (None: zero).
    engine : EngineVibration or None
        The engine vibration (None: zero).
    road : numpy.random.Generator or None
        The road vibration's stream, untouched (None: zero).
    draws : dict
        The per-run constants (see :func:`sensor_matrices`, :func:`bias_drift`,
        :func:`gnssacc.sources.sim_vibration.engine_vibration`; zeros for skipped sources).
    """

    K_a: np.ndarray | None
    K_g: np.ndarray | None
    drift: BiasDrift | None
    engine: EngineVibration | None
    road: np.random.Generator | None
    draws: dict


def unmodelled_errors(model: dict, n: int, dt: float, t_span: float, seed: int) -> UnmodelledErrors:
    """Draw the errors a filter does not model: scale factor and cross-axis, bias drift, vibration.

    Each source draws from its own stream ``numpy.random.default_rng([seed, 3, i])`` (i = 0
    sensor matrices, 1 drift, 2 engine vibration, 3 road vibration), independent of the stream
    ``[seed, 1]`` of :func:`imu_errors`, so adding or changing one source leaves the others and
    the basic errors unchanged. A source whose magnitudes are all zero is skipped.

    Parameters
    ----------
    model : dict
        :func:`imu_error_model`.
    n : int
        Number of IMU samples.
    dt : float
        IMU interval [s].
    t_span : float
        Time from the first to the last IMU sample [s].
    seed : int

    Returns
    -------
    UnmodelledErrors
    """
    draws = {
        "accel_scale_factor": np.zeros(3),
        "gyro_scale_factor": np.zeros(3),
        "accel_cross_axis": np.zeros((3, 3)),
        "gyro_cross_axis": np.zeros((3, 3)),
        "accel_warmup": np.zeros(3),
        "gyro_warmup": np.zeros(3),
    }
    stream = [np.random.default_rng([seed, 3, i]) for i in range(4)]
    out = UnmodelledErrors(None, None, None, None, None, draws)
    if _nonzero(
        model,
        "accel_scale_factor_ppm",
        "gyro_scale_factor_ppm",
        "accel_cross_axis_ppm",
        "gyro_cross_axis_ppm",
    ):
        m = sensor_matrices(model, stream[0])
        out.K_a, out.K_g = m.pop("K_a"), m.pop("K_g")
        draws.update(m)
    if _nonzero(
        model,
        "accel_warmup_mg",
        "gyro_warmup_deg_h",
        "accel_bias_rw_mg_rth",
        "gyro_bias_rw_deg_h_rth",
    ):
        out.drift = BiasDrift(t_span, model, stream[1])
        draws.update(accel_warmup=out.drift.warm_a, gyro_warmup=out.drift.warm_g)
    if _nonzero(model, "vib_engine_accel_mps2", "vib_engine_gyro_dps") and _nonzero(
        model, "vib_engine_harmonics"
    ):
        out.engine = EngineVibration(n, dt, model, stream[2])
        draws.update(out.engine.draws)
    if _nonzero(model, "vib_road_accel_mps2", "vib_road_gyro_dps"):
        out.road = stream[3]
    return out


def _measure(true: np.ndarray, K, bias: np.ndarray, noise: np.ndarray, vib) -> np.ndarray:
    """``K true + bias + noise + vib`` (the basic grades' ``true + bias + noise``, bit for bit)."""
    out = (true if K is None else true @ K.T) + bias + noise
    if vib is not None:
        out += vib
    return out


def simulate_imu(
    traj: Trajectory, t: np.ndarray, model: dict, seed: int, truth_times=()
) -> tuple[ImuData, dict, list]:
    """The measured IMU of a run: perfect interval averages plus every error of ``model``, in one sweep.

    Parameters
    ----------
    traj : Trajectory
        As from :func:`build_trajectory` for the IMU rate.
    t : ndarray, shape (n,)
        IMU times [s].
    model : dict
        :func:`imu_error_model`.
    seed : int
        The filter-visible errors (:func:`imu_errors`) draw from ``default_rng([seed, 1])`` as
        they always have; the others as in :func:`unmodelled_errors`.
    truth_times : sequence of ndarray
        Times [s] at which the same sweep interpolates the true position.

    Returns
    -------
    ImuData
    dict
        ``true_bias`` (:class:`TrueBias`: turn-on + Gauss-Markov + drift per sample, drawn again
        when asked) and ``imu_error_draws`` (per-run constants: ``accel_turn_on_bias`` [m/s^2],
        ``gyro_turn_on_bias`` [rad/s] and those of :func:`unmodelled_errors`).
    list of (lat, lon, h)
        True positions at ``truth_times`` [rad, rad, m].
    """
    n, dt = len(t), 2.0 * traj.step
    f_b, omega_ib_b = np.empty((n, 3)), np.empty((n, 3))
    basic = ImuErrorStream(n, dt, model, np.random.default_rng([seed, 1]))
    extra = unmodelled_errors(model, n, dt, float(t[-1] - t[0]), seed)
    true_bias = TrueBias(t, basic.bias_seed, extra.drift)
    if extra.road is not None:
        # The road vibration's unit-RMS columns (an FFT synthesis over the whole run) wait in the
        # output arrays until the sweep reaches their samples.
        for c, z in band_limited_columns(n, dt, model["vib_road_band_hz"], extra.road, 6):
            (f_b if c < 3 else omega_ib_b)[:, c % 3] = z
        release_free_memory()

    def finish(k0, k1, f_true, omega_true, speed_mid):
        err = basic.take(k1 - k0)
        ba, bg = true_bias.with_drift(err["bias_a"], err["bias_g"], slice(k0, k1))
        vib = []
        if extra.engine is not None:
            engine = extra.engine.take(speed_mid)
            vib.append((engine[:, :3], engine[:, 3:]))
        if extra.road is not None:
            scale = road_scale(speed_mid, model)
            vib.append((f_b[k0:k1] * scale[:, :3], omega_ib_b[k0:k1] * scale[:, 3:]))
        vib_a, vib_g = (sum(v[0] for v in vib), sum(v[1] for v in vib)) if vib else (None, None)
        f_b[k0:k1] = _measure(f_true, extra.K_a, ba, err["noise_a"], vib_a)
        omega_ib_b[k0:k1] = _measure(omega_true, extra.K_g, bg, err["noise_g"], vib_g)

    positions = sweep_imu(traj, n, finish, truth_times)
    draws = {
        "accel_turn_on_bias": basic.turn_on_a,
        "gyro_turn_on_bias": basic.turn_on_g,
        **extra.draws,
    }
    return (
        ImuData(t, f_b, omega_ib_b),
        {"true_bias": true_bias, "imu_error_draws": draws},
        positions,
    )


#: Highest rate of a simulated truth written to a run folder or made for a ``sim:`` source [Hz].
TRUTH_RATE_HZ = 100.0


def dense_truth_rate(imu_rate_hz: float) -> float:
    """The truth rate [Hz] of a simulated run written or scored as a recording: the IMU rate, at
    most :data:`TRUTH_RATE_HZ` (never coarser than 50 Hz unless the IMU is)."""
    return min(float(imu_rate_hz), TRUTH_RATE_HZ)


def simulate(
    scenario: str | Scenario = "car",
    duration_s: float = 300.0,
    imu_grade: str = "industrial",
    imu_rate_hz: float = 100.0,
    gnss_rate_hz: float = 1.0,
    noise: str = "white",
    seed: int = 0,
    origin_llh_deg=(32.0, 34.8, 50.0),
    initial_yaw_deg: float = 30.0,
    lever_arm_b=(0.0, 0.0, 0.0),
    give_init: bool = False,
    imu_overrides: dict | None = None,
    truth_rate_hz: float | None = None,
    t_start_s: float = 0.0,
    odom_hz: float | None = None,
    odom_kind: str | None = None,
    velocity: bool = False,
) -> RecordedRun:
    """Simulate a ground-vehicle run with known truth.

    Parameters
    ----------
    scenario : str or Scenario
        A name in :data:`SCENARIOS` ("static", "ugv", "car", "straight", "turns", "ugv-slow",
        "car-city", "rover") or a custom :class:`Scenario`.
    duration_s : float
        Run length [s]; the IMU covers ``[t_start_s, t_start_s + duration_s]``.
    imu_grade : str
        IMU error grade, a key of :data:`IMU_GRADES`: "perfect", the realistic "consumer",
        "industrial", "tactical" (with vibration, scale-factor, cross-axis and drift errors), or
        the original "consumer-basic", "industrial-basic", "tactical-basic". See
        :func:`imu_error_model`.
    imu_rate_hz : float
        IMU rate [Hz]. Sample k is the average over ``(t[k-1], t[k]]``.
    gnss_rate_hz : float
        GNSS fix rate [Hz], at most the IMU rate; fixes at ``t_start_s + k / gnss_rate_hz``.
    noise : {"white", "gm", "none"}
        GNSS noise profile of :mod:`gnssacc.sources.gnss_noise`.
    seed : int
        Seeds the IMU errors and (through an independent stream) the GNSS noise.
    origin_llh_deg : (float, float, float)
        Start latitude, longitude [deg] and ellipsoidal height [m] of the IMU.
    initial_yaw_deg : float
        Initial heading [deg].
    lever_arm_b : (float, float, float)
        GNSS antenna position relative to the IMU, body frame FRD [m]; fixes are of the antenna.
    give_init : bool
        Attach the true initial state (with 1 m / 0.1 m/s / 1-2 deg sigmas) as ``run.init``;
        otherwise the estimators self-initialise.
    imu_overrides : dict, optional
        Error parameters to replace: keys of ``gnssacc.core.config.DEFAULTS["imu"]`` or any other key
        of :func:`imu_error_model` (e.g. ``{"vib_road_gyro_dps": 0.0}``).
    truth_rate_hz : float, optional
        Rate of ``run.truth`` [Hz]; by default the truth is at the GNSS epochs. ``gnssacc sim``
        and ``sim:`` sources ask for :func:`dense_truth_rate` (the IMU rate, at most
        :data:`TRUTH_RATE_HZ`): a truth at the fixes' 1 Hz is interpolated across a 23 deg/s turn
        when an estimate between whole seconds is scored.
    t_start_s : float
        Absolute time of the first IMU sample [s] (e.g. a UNIX time, for fixes written with
        absolute times: :mod:`gnssacc.sources.rtklib`, :mod:`gnssacc.sources.nmea`).
    odom_hz : float, optional
        Also simulate wheel odometry at this rate [Hz] (:mod:`gnssacc.sources.sim_odometry`:
        scale-factor error, noise, slip), as ``run.odometry``; its draws in ``run.sim.odometry``.
    odom_kind : {"car", "skid"}, optional
        The odometry's vehicle: skid steer (large slip in turns) or car; default skid for the
        UGV scenarios, car otherwise.
    velocity : bool
        Also simulate the receiver's Doppler velocities of the antenna at the fix times
        (``run.gnss_vel``; :func:`gnssacc.sources.gnss_noise.velocities_from_truth`: white plus a
        small Gauss-Markov error, from their own stream: the fixes and the IMU keep their draws).
        The ``sim:`` sources and ``gnssacc sim`` have them; off by default here, so that a run
        made in Python is the position-only run it always was unless asked.

    Returns
    -------
    RecordedRun
        ``name = "sim-<scenario>"``, ``where = "simulator(<scenario>, seed=<seed>)"``. ``meta``
        records every argument and the GNSS seed; ``sim`` (:class:`gnssacc.core.recording.SimTruth`) the
        filter-visible IMU parameters (``imu_params``, as :func:`grade_config`), the full error
        description (``imu_error_model``), the per-run error draws (``imu_error_draws``, small
        arrays), the true biases per IMU sample (``bias``, a :class:`TrueBias`; also as arrays
        ``true_bias_a`` [m/s^2] and ``true_bias_g`` [rad/s], shape (N, 3), drawn on each access)
        and the scenario ``segments`` (times absolute; ``reverse`` marks reversing).
    """
    args = dict(
        scenario=scenario,
        duration_s=duration_s,
        imu_grade=imu_grade,
        imu_rate_hz=imu_rate_hz,
        gnss_rate_hz=gnss_rate_hz,
        noise=noise,
        seed=seed,
        origin_llh_deg=list(origin_llh_deg),
        initial_yaw_deg=initial_yaw_deg,
        lever_arm_b=list(lever_arm_b),
        give_init=give_init,
        imu_overrides=dict(imu_overrides or {}),
        truth_rate_hz=truth_rate_hz,
        t_start_s=t_start_s,
    )
    if odom_hz is not None:
        args.update(odom_hz=odom_hz, odom_kind=odom_kind)
    if velocity:
        args.update(velocity=True)
    name = scenario if isinstance(scenario, str) else scenario.name
    args["scenario"] = name
    where = f"simulator({name}, seed={seed})"
    model = imu_error_model(imu_grade, imu_overrides)
    _check_arguments(where, noise, gnss_rate_hz, imu_rate_hz, odom_hz, odom_kind)
    lever_b = np.asarray(lever_arm_b, float).reshape(3)

    traj = build_trajectory(
        scenario, duration_s, imu_rate_hz, origin_llh_deg, initial_yaw_deg, t_start_s
    )
    t_gnss = sample_times(t_start_s, duration_s, gnss_rate_hz)
    t_truth = None if truth_rate_hz is None else sample_times(t_start_s, duration_s, truth_rate_hz)
    imu, imu_info, positions = simulate_imu(
        traj,
        sample_times(t_start_s, duration_s, imu_rate_hz),
        model,
        seed,
        [t_gnss] + ([] if t_truth is None else [t_truth]),
    )
    release_free_memory()  # the sweep's temporaries

    truth_gnss = traj.at(t_gnss, positions[0])
    truth = truth_gnss if t_truth is None else traj.at(t_truth, positions[1])
    origin = LocalTangentFrame(
        *(np.array(origin_llh_deg[:2], float) * DEG), float(origin_llh_deg[2])
    )
    gnss_seed = int(np.random.SeedSequence([seed, 2]).generate_state(1)[0])
    meta = {
        **args,
        "source": "simulator",
        "imu_sample_convention": "sample k = average over (t[k-1], t[k]]",
        "gnss_seed": gnss_seed,
    }
    truths = _sim_truth(traj, imu_info, model, duration_s, t_start_s)
    empty = GnssFixes(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3)))
    run = RecordedRun(
        name=f"sim-{name}",
        where=where,
        imu=imu,
        gnss=empty,
        origin=origin,
        truth=truth.to_truth(),
        init=_initial_state(truth) if give_init else None,
        sim=truths,
        meta=meta,
    )
    run = _with_receiver(run, truth_gnss, lever_b, noise, gnss_seed, seed, velocity)
    if odom_hz is None:
        return run
    return _with_odometry(
        run, traj, t_start_s, duration_s, odom_hz, odom_kind or odometry_kind(name), seed
    )


def _check_arguments(where: str, noise: str, gnss_rate_hz, imu_rate_hz, odom_hz, odom_kind) -> None:
    """:class:`InputError` naming the simulator for a noise profile, fix rate [Hz], odometry rate
    [Hz] or odometry kind it cannot make."""
    if noise not in PROFILES:
        raise InputError(
            where, f"unknown GNSS noise profile {noise!r} (known: {', '.join(PROFILES)})"
        )
    if not 0 < gnss_rate_hz <= imu_rate_hz:
        raise InputError(
            where, f"gnss_rate_hz must be positive and at most the IMU rate, got {gnss_rate_hz}"
        )
    if odom_hz is not None and not 0 < odom_hz <= imu_rate_hz:
        raise InputError(where, f"odom_hz must be positive and at most the IMU rate, got {odom_hz}")
    if odom_kind is not None and odom_kind not in ODOMETRY_KINDS:
        raise InputError(
            where, f"unknown odometry kind {odom_kind!r} (known: {', '.join(ODOMETRY_KINDS)})"
        )


def _with_receiver(
    run: RecordedRun,
    truth_gnss,
    lever_b: np.ndarray,
    noise: str,
    gnss_seed: int,
    seed: int,
    velocity: bool,
) -> RecordedRun:
    """``run`` with the antenna's fixes (``noise`` drawn from ``gnss_seed``) at the epochs of
    ``truth_gnss`` (the IMU's truth there) and, with ``velocity``, its Doppler velocities (their
    own stream of ``seed``); ``lever_b``: the antenna from the IMU, body FRD [m]."""
    p_antenna_n = truth_gnss.R_nb @ lever_b
    fixes = fixes_from_truth(run, truth_gnss.to_truth(), noise, gnss_seed, p_antenna_n)
    fixes.quality = np.full(len(fixes), PROFILE_QUALITY[noise])
    run = replace(run, gnss=fixes)
    if velocity:
        v_ant = antenna_velocity(
            truth_gnss.v_n, truth_gnss.R_nb, truth_gnss.omega_ib_b, truth_gnss.lat, lever_b
        )
        run = replace(run, gnss_vel=velocities_from_truth(truth_gnss.t, v_ant, noise, seed))
    return run


def _with_odometry(
    run: RecordedRun,
    traj: Trajectory,
    t_start_s: float,
    duration_s: float,
    odom_hz: float,
    kind: str,
    seed: int,
) -> RecordedRun:
    """``run`` with wheel odometry of the vehicle ``kind`` at ``odom_hz`` [Hz] along ``traj``, its
    draws in ``run.sim.odometry``."""
    t_odo = sample_times(t_start_s, duration_s, odom_hz)
    kin = traj.kinematics(t_odo)
    odo, draws = simulate_odometry(t_odo, kin.speed, kin.accel, kin.omega_nb_b[:, 2], kind, seed)
    return replace(run, odometry=odo, sim=replace(run.sim, odometry=draws))


def _sim_truth(
    traj: Trajectory, imu_info: dict, model: dict, duration_s: float, t_start_s: float
) -> SimTruth:
    """The run's :class:`SimTruth`: true biases and draws (:func:`simulate_imu`), the scenario log
    with absolute times, the grade's filter-visible parameters and the full error model."""
    segments = [
        {**s, "t0": s["t0"] + t_start_s, "t1": s["t1"] + t_start_s}
        for s in traj.scenario.segments_until(duration_s)
    ]
    return SimTruth(
        imu_info["true_bias"],
        segments,
        imu_info["imu_error_draws"],
        {k: model[k] for k in GRADE_KEYS},
        model,
    )
