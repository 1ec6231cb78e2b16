"""Motion context: label each epoch stationary, straight (constant speed), accelerating or turning.

The labels explain *when* states become observable (heading needs horizontal acceleration,
tilt and accelerometer biases separate only when the specific force changes direction), so the
observability analysis and the notebooks shade their plots with them.

Inputs are the data an estimator has: the IMU samples and an estimated navigation solution
(speed and attitude). The fixed-lag smoother's solution gives the most reliable speed: after a
1-2 deg initial tilt error the EKF's velocity error can reach ~1 m/s while standing (3 m GNSS
noise), which the speed test below would read as moving. Truth is never read; for simulated runs
:func:`labels_from_segments` turns the simulator's scenario log (``run.sim.segments``) into
reference labels to check the classifier against.

Classification, per IMU sample, in this order of precedence (thresholds in
:class:`MotionThresholds`, applied to quantities smoothed with a centred moving average of
``smooth_s`` seconds):

1. ``turning``: ``|yaw rate| > yaw_rate_dps``. The yaw rate is the gyro rate rotated into NED
   with the estimated attitude, down component (earth rate, < 0.005 deg/s, is left in). A pivot
   turn on the spot is turning.
2. ``stationary``: inside a stationary span of :func:`gnssacc.prepare.stationary.detect_stationary`
   (windowed IMU statistics robust to vibration, confirmed by the GNSS fixes) -- *and* the
   horizontal acceleration ``|R_nb f_b + g_n|_h`` is at most ``accel_mps2`` -- *and* the
   estimated horizontal speed is below ``speed_mps``. The estimators' zero-velocity updates use
   the same spans, so the analysis and the filter agree on when the vehicle stands.
3. ``accelerating``: ``|along-track acceleration| > accel_mps2``. The acceleration is
   ``R_nb f_b + g_n`` (IMU specific force rotated with the estimated attitude, plus normal
   gravity), projected on the horizontal direction of travel, so a slope does not look like
   acceleration.
4. ``straight``: everything else (moving at about constant speed without turning, hills
   included).

The defaults suit ground vehicles: a 3 deg/s yaw-rate threshold is 10x the turn-on gyro bias of
a 0.3 deg/s consumer sensor, and 0.25 m/s^2 is well above the gravity leak of a 0.5 deg tilt
error (0.09 m/s^2) plus a 5 mg accelerometer bias; the rates and accelerations are averaged over
``smooth_s``, many periods of engine vibration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.earth import gravity_n
from ..core.recording import RecordedRun
from ..core.rotations import euler_to_dcm
from ..core.solution import NavSolution
from ..prepare.stationary import StationaryReport, detect_stationary

#: Label codes: ``LABELS[code]`` is the name.
LABELS = ("stationary", "straight", "accelerating", "turning")
STATIONARY, STRAIGHT, ACCELERATING, TURNING = range(4)
#: Plot colours per label (for :func:`shade`).
COLOURS = {
    "stationary": "0.75",
    "straight": "tab:green",
    "accelerating": "tab:orange",
    "turning": "tab:purple",
}

#: Simulator segment kind -> label (``gnssacc.sources.sim.Scenario``).
SEGMENT_LABELS = {
    "hold": STATIONARY,
    "cruise": STRAIGHT,
    "hill": STRAIGHT,
    "speed": ACCELERATING,
    "turn": TURNING,
}


@dataclass(frozen=True)
class MotionThresholds:
    """Thresholds of :func:`classify_motion`.

    Attributes
    ----------
    speed_mps : float
        Horizontal speed below which a still vehicle is stationary [m/s].
    yaw_rate_dps : float
        Absolute yaw rate above which it is turning [deg/s].
    accel_mps2 : float
        Absolute along-track acceleration above which it is accelerating [m/s^2].
    smooth_s : float
        Length of the centred moving average applied to the rates and accelerations [s].
    """

    speed_mps: float = 0.75
    yaw_rate_dps: float = 3.0
    accel_mps2: float = 0.25
    smooth_s: float = 0.5


@dataclass
class MotionContext:
    """Motion labels and the quantities they were derived from, per epoch.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Epochs [s].
    label : ndarray of int, shape (K,)
        Codes into :data:`LABELS`.
    speed_mps : ndarray, shape (K,)
        Estimated horizontal speed [m/s].
    yaw_rate_dps : ndarray, shape (K,)
        Smoothed yaw rate [deg/s].
    accel_along_mps2, accel_cross_mps2 : ndarray, shape (K,)
        Smoothed along-track and cross-track (centripetal) horizontal acceleration [m/s^2].
    thresholds : MotionThresholds
    """

    t: np.ndarray
    label: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_dps: np.ndarray
    accel_along_mps2: np.ndarray
    accel_cross_mps2: np.ndarray
    thresholds: MotionThresholds

    @property
    def names(self) -> np.ndarray:
        """Label names per epoch."""
        return np.asarray(LABELS)[self.label]

    def at(self, t: np.ndarray) -> np.ndarray:
        """Label codes at times ``t`` [s] (the label of the latest epoch at or before each time)."""
        i = np.clip(
            np.searchsorted(self.t, np.asarray(t, float), side="right") - 1, 0, len(self.t) - 1
        )
        return self.label[i]

    def fractions(self) -> dict[str, float]:
        """Share of epochs per label."""
        return {name: float(np.mean(self.label == i)) for i, name in enumerate(LABELS)}

    def spans(self) -> list[tuple[float, float, str]]:
        """Runs of equal labels as ``(t0, t1, name)``."""
        return label_spans(self.t, self.label)


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over ``n`` samples along axis 0 (shrinking at the ends)."""
    if n <= 1:
        return x
    kernel = np.ones(n)
    num = np.apply_along_axis(lambda c: np.convolve(c, kernel, mode="same"), 0, x)
    den = np.convolve(np.ones(len(x)), kernel, mode="same")
    return num / (den[:, None] if x.ndim > 1 else den)


def classify_motion(
    run: RecordedRun,
    sol: NavSolution,
    thresholds: MotionThresholds | None = None,
    t: np.ndarray | None = None,
    stationary: StationaryReport | None = None,
) -> MotionContext:
    """Classify the motion of a run from its IMU and an estimated navigation solution.

    Parameters
    ----------
    run : RecordedRun
        Supplies the IMU samples (body frame, after mounting).
    sol : NavSolution
        Estimated velocity and attitude (any estimator; interpolated to the IMU times).
    thresholds : MotionThresholds, optional
    t : ndarray, optional
        Epochs [s] to report; default: the IMU sample times within the solution's span.
    stationary : StationaryReport, optional
        Stationary spans (:func:`gnssacc.prepare.stationary.detect_stationary` on the run when omitted).

    Returns
    -------
    MotionContext
    """
    th = thresholds or MotionThresholds()
    imu = run.imu
    keep = (imu.t >= sol.t[0]) & (imu.t <= sol.t[-1])
    ti, f_b, w_b = imu.t[keep], imu.f_b[keep], imu.omega_ib_b[keep]
    if len(ti) < 2:
        raise ValueError("the solution does not overlap the IMU data")
    body = sol.body_rpy()  # the IMU's axes, in which f_b and w_b are
    rpy = np.column_stack([np.interp(ti, sol.t, np.unwrap(body[:, i])) for i in range(3)])
    v_n = np.column_stack([np.interp(ti, sol.t, sol.v_n[:, i]) for i in range(3)])
    R = np.moveaxis(euler_to_dcm(rpy[:, 0], rpy[:, 1], rpy[:, 2]), -1, 0)  # (K, 3, 3)
    # Gravity varies by < 1e-3 m/s^2 over a ground-vehicle run: take it at the mean position.
    g_n = gravity_n(float(np.mean(sol.lat)), float(np.mean(sol.h)))
    a_n = np.einsum("kij,kj->ki", R, f_b - sol_bias_at(sol, ti)) + g_n
    yaw_rate = np.einsum("kj,kj->k", R[:, 2, :], w_b)  # down component of R_nb omega_ib_b

    dt = float(np.median(np.diff(ti)))
    n = max(1, int(round(th.smooth_s / dt)))
    yaw_rate = _moving_average(yaw_rate, n)
    a_n = _moving_average(a_n, n)
    speed = np.hypot(v_n[:, 0], v_n[:, 1])
    if stationary is None:
        stationary = detect_stationary(run.imu, run.gnss, run.origin)
    still = stationary.mask(ti)
    # Direction of travel; while (nearly) stationary use the heading instead.
    course = np.where(speed > 0.2, np.arctan2(v_n[:, 1], v_n[:, 0]), rpy[:, 2])
    u = np.column_stack([np.cos(course), np.sin(course)])
    along = a_n[:, 0] * u[:, 0] + a_n[:, 1] * u[:, 1]
    cross = -a_n[:, 0] * u[:, 1] + a_n[:, 1] * u[:, 0]

    label = np.full(len(ti), STRAIGHT, int)
    label[np.abs(along) > th.accel_mps2] = ACCELERATING
    # A smooth pull-away barely changes |f| and starts below the speed threshold: a vehicle is
    # only stationary if its horizontal acceleration is small too.
    level = np.hypot(a_n[:, 0], a_n[:, 1]) <= th.accel_mps2
    label[still & level & (speed < th.speed_mps)] = STATIONARY
    label[np.abs(np.degrees(yaw_rate)) > th.yaw_rate_dps] = TURNING
    ctx = MotionContext(ti, label, speed, np.degrees(yaw_rate), along, cross, th)
    if t is None:
        return ctx
    t = np.asarray(t, float)
    j = np.clip(np.searchsorted(ti, t), 0, len(ti) - 1)
    return MotionContext(t, label[j], speed[j], ctx.yaw_rate_dps[j], along[j], cross[j], th)


def sol_bias_at(sol: NavSolution, t: np.ndarray) -> np.ndarray:
    """The solution's accelerometer-bias estimate interpolated to ``t`` [m/s^2]."""
    return np.column_stack([np.interp(t, sol.t, sol.b_a[:, i]) for i in range(3)])


def labels_from_segments(segments: list[dict], t: np.ndarray) -> np.ndarray:
    """Reference labels at times ``t`` from a simulator scenario log (``run.sim.segments``).

    ``hold`` -> stationary, ``cruise`` and ``hill`` -> straight, ``speed`` -> accelerating,
    ``turn`` -> turning. Times outside every segment get -1.
    """
    t = np.asarray(t, float)
    out = np.full(len(t), -1, int)
    for s in segments:
        out[(t >= s["t0"]) & (t < s["t1"])] = SEGMENT_LABELS[s["kind"]]
    return out


def segment_interior(segments: list[dict], t: np.ndarray, margin_s: float) -> np.ndarray:
    """Mask of times at least ``margin_s`` [s] inside a segment (away from the ramps at its ends)."""
    t = np.asarray(t, float)
    m = np.zeros(len(t), bool)
    for s in segments:
        m |= (t >= s["t0"] + margin_s) & (t < s["t1"] - margin_s)
    return m


def label_spans(t: np.ndarray, label: np.ndarray) -> list[tuple[float, float, str]]:
    """Runs of equal labels as ``(t_start, t_end, name)``; a run ends where the next begins."""
    if len(t) == 0:
        return []
    change = np.flatnonzero(np.diff(label)) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(t) - 1]])
    return [(float(t[a]), float(t[b]), LABELS[int(label[a])]) for a, b in zip(starts, ends)]


def shade(
    ax, spans: list[tuple[float, float, str]], t_ref: float = 0.0, alpha: float = 0.15
) -> list:
    """Shade a matplotlib axis with motion spans (times relative to ``t_ref``).

    Returns one legend handle per label (``ax.legend(handles=...)``)."""
    import matplotlib.patches as mpatches

    for t0, t1, name in spans:
        ax.axvspan(t0 - t_ref, t1 - t_ref, color=COLOURS[name], alpha=alpha, lw=0)
    handles = [mpatches.Patch(color=COLOURS[n], alpha=0.4, label=n) for n in LABELS]
    return handles
