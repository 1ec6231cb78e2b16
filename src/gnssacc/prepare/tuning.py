r"""Noise identification from the recording itself (``--tune auto``, the default).

Every IMU noise key the user's configuration does not set (and ``gnss.sigma_scale``; on a
recording with GNSS velocities ``velocity.sigma_scale``, with the velocities' innovations in the
likelihood, :func:`measurement_stage`; and the ground-vehicle aids' noise when they are in use:
``nhc.sigma_lateral_mps``, ``nhc.sigma_vertical_mps``, ``odometry.speed_sigma_mps``,
:func:`aids`) is identified
without truth, in five steps:

1. **Stationary stretches** (:mod:`gnssacc.prepare.stationary`): the white-noise densities of the
gyros
   and accelerometers per axis, read from the Allan deviation in its white-noise region (robust
   to engine vibration), become the starting values of ARW and VRW.
2. **Maximum likelihood of the EKF's innovations.** With ``theta`` the log10 scale factors of
   the seven parameters (gyro ARW, accelerometer VRW, gyro and accelerometer bias instability,
   gyro and accelerometer turn-on sigma, GNSS sigma scale) relative to their starting values,
   the objective is

       J(theta) = -sum_k log N(nu_k; 0, S_k(theta)) + sum_i theta_i^2 / (2 d_i^2)

   over every position and zero-rate update (acceleration updates too with ``[tune] likelihood =
   "position+accel"``) of one EKF pass from the start, the ground-vehicle aids off (step 5).
   The zero-velocity updates are left out:
   their noise is a chosen bound, not a sensor property, and their likelihood would pull the
   accelerometer noise down. The second term is a
   log-normal prior around the starting values, ``d_i = [tune] prior_decades`` (weak), or
   ``[tune] stationary_prior_decades`` for a density measured at standstill in step 1 (which is
   also a floor: the search stays above 1/1.25 of it, :data:`REST_FLOOR_DECADES`): it keeps the
   parameters the data barely inform from wandering (the one-step position innovations of 1 Hz
   metre-level fixes say little about the white noise, and will trade it for unmodelled errors
   such as scale factors) and costs a well-informed parameter nothing. ``J`` is minimised by
   Nelder-Mead (scipy's steps, :mod:`gnssacc.prepare.nelder_mead`) within
   ``[tune] max_evaluations`` EKF passes (after a probe of each parameter at +-1 decade,
   :func:`ml_search`), each bounded to +-2 decades; the passes propagate the covariance every
   ``[tune] cov_every`` samples for speed.

3. **Time-correlated GNSS errors.** A white-noise fix model misses the slowly varying part of
   real fix errors (multipath, atmosphere); its one-step innovations then stay correlated in
   time, and chasing NIS = 1 with a smaller sigma makes the stated position uncertainty far too
   small. When the lag-1 autocorrelation of the whitened position innovations at the step-2
   optimum exceeds :data:`ACF_CORRELATED` (and three standard errors of it), a first-order
   Gauss-Markov error is added to every fix (three more EKF states, ``gnss.gm_sigma_m`` and
   ``gnss.gm_tau_s``) and the search is run again over all parameters plus these two, from the
   step-1 starting values (the white-noise search has distorted the IMU values while chasing the
   correlated errors); the model is kept when it raises the log-likelihood by more than
   :data:`GM_MIN_GAIN` (a likelihood-ratio test).

4. **Turn-on sigmas: no larger than the data need.** The likelihood bounds a turn-on bias sigma
   from below only: once it is large enough for the filter to learn the bias from the first
   updates, a larger one only widens those few innovations, and the likelihood stays flat for
   decades. The search can then end anywhere up there, and an estimator that trusts such a value
   can suffer where the likelihood does not show it (on a simulated consumer IMU with a true
   30 mg accelerometer turn-on sigma the search ended at 526 mg, where the fixed-lag smoother
   drifted to 10.3 m against the EKF's 2.2 m). So a turn-on sigma that ended above its start is
   drawn back toward it by bisection (at most three passes) to the smallest value whose
   log-likelihood stays within :data:`SHRINK_TOLERANCE` of the search's best, shared by both
   sigmas (:func:`draw_back`). The noise densities and the GNSS scale are left at the optimum: a
   value too
   large widens every innovation, so the likelihood bounds them on both sides, and drawing them
   toward a default would trade accuracy for a prior that is no better informed.

5. **The ground-vehicle aids' noise**, when they are in use (:func:`aids`): the non-holonomic
   constraint's lateral and vertical sigma and the vehicle's axes relative to the body's (a
   residual pitch and yaw of the mounting, searched additively in steps of :data:`ADDITIVE`:
   on KITTI a 0.6 deg pitch between the IMU and the car made the constraint cost 0.8 m of
   PRMSE with GNSS up), and the wheel odometry's speed sigma, by the same maximum-likelihood
   search (:func:`ml_search`, :data:`AIDS_EVALUATIONS` passes) over the
   position, zero-rate and the aids' own updates, the IMU and GNSS noise of steps 2-4 held. They
   are properties of the vehicle, not of the IMU: searched jointly, a tight constraint turned the
   IMU errors the model misses into innovations the search answered with the IMU's noise (on a
   simulated consumer-IMU UGV the accelerometer turn-on sigma went to 576 mg, the truth being
   60 mg). The constraint's sigmas stay at or above ``[zupt] velocity_sigma_mps`` (a rolling
   vehicle sways at least as much as a parked one). The aids' errors are correlated in time
   (slip through a turn, the suspension's pitch under acceleration), which the one-step
   likelihood fits as white noise too small for what the filter averages (the filter follows
   their slow part, so the aid's own innovations do not show it): each aid's sigmas are then
   inflated by the factor of :func:`correlation_inflation`, the one that best predicts the
   updates the aid's errors do not enter (the fixes, the zero-rate updates), searched from the
   sigmas in use wherever the search left them, its floor included (:func:`_inflate`: a rule
   that skipped a sigma at a lower limit inflated 0.0201 m/s to 0.069 on a simulated car and
   left 0.0200 alone), and the vehicle's axes searched again under the final sigmas (inflated
   or not: the joint search's budget of :data:`AIDS_EVALUATIONS` can leave them short; on a
   simulated car turned 0.8 deg in pitch and -0.6 in yaw it stopped at 0.70 / -0.30, searched
   again 0.91 / -0.64). An angle of the vehicle's axes is kept only when it raises the
   log-likelihood by more than :data:`OFFSET_MIN_GAIN` (on a simulated UGV, exact axes and
   fixes with 2.3 m of correlated error, a fitted 0.33 deg of yaw made the EKF's position NEES
   12) (on KITTI, the white fit made the constraint cost the smoother 0.2 m of PRMSE
   with GNSS up; inflated, it gains 0.3 m).

On a run that never showed its yaw (the start's ``yaw_evidence`` ``"undetermined"``: it never
turned or accelerated enough) the accelerometers' turn-on sigma is searched from, and not below,
the IMU class's value from the gyro noise at rest: the tilt takes up the horizontal bias, so the
likelihood hardly tells it, and a search left free ended where its first steps went
(:func:`rest_floor`).

``[imu] gyro_turn_error_ppm`` (the gyro scale-factor and cross-axis errors, covered by noise that
grows with the angle turned) is not identified: the one-step likelihood cannot tell its size. On
a simulated consumer UGV (the tuned point, 0 to 7000 ppm) it falls by 56 with the errors in the data
and by 58 without them (the larger noise costs its log-determinant; the innovations hardly see
the error, which tilts the attitude along the combination ``g phi - R b_a`` the fixes cannot
separate): the value is the configuration's (a preset's datasheet-typical one, or the user's),
or with the default ``"auto"`` set before the tuning from the gyro noise measured at rest
(:mod:`gnssacc.prepare.turn_allowance`).

The result is a :class:`TuneResult`: the tuned values in configuration units (a reusable
``tuned.toml``), the NIS before and after, and the time it took.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..core.config import RunConfig, toml_value
from ..core.errors import InputError
from ..core.parallel import forks_held, side_by_side, usable_jobs
from ..estimators.aids import REGISTRY
from ..estimators.settings import GnssModel
from . import aid_inflation
from .attitude_axes import likelihood_sigma, needs_probe, probe_at
from .filter_pass import FilterPass
from .nelder_mead import nelder_mead

#: The IMU noise parameters: (section, key).
IMU_PARAMETERS = (
    ("imu", "gyro_arw_deg_rth"),
    ("imu", "accel_vrw_mps_rth"),
    ("imu", "gyro_bias_instability_deg_h"),
    ("imu", "accel_bias_instability_mg"),
    ("imu", "gyro_bias_sigma0_deg_h"),
    ("imu", "accel_bias_sigma0_mg"),
)
#: The parameters identified together (steps 2-4), in the order of the search vector: the IMU
#: noise, then the noise of the aids identified with it (the GNSS fixes' ``gnss.sigma_scale``).
PARAMETERS = IMU_PARAMETERS + tuple(
    key for spec in REGISTRY if spec.stage == "imu" for key in spec.noise_keys
)
#: The ground vehicle's aids (step 5), identified after :data:`PARAMETERS` when in use
#: (:func:`aids`; their innovations join the likelihood): the non-holonomic constraint's sigmas
#: and axes, the wheel odometry's speed sigma.
VEHICLE_AIDS = tuple(spec for spec in REGISTRY if spec.stage == "vehicle")
#: Parameters searched additively, ``start + theta * step`` (signed angles near zero), with their
#: step per unit of ``theta`` (the others: ``start * 10**theta``, ``theta`` in decades).
ADDITIVE = {key: step for spec in VEHICLE_AIDS for key, step in spec.additive_keys.items()}
#: Sigmas floored by another key's value: ``{key: floor key}`` (the constraint's sigmas by the
#: zero-velocity sigma).
FLOORED = {key: spec.floor_key for spec in VEHICLE_AIDS for key in spec.floored_keys}
#: The Gauss-Markov GNSS error model, identified in a second stage (see the module docstring).
GM_PARAMETERS = (("gnss", "sigma_scale"), ("gnss", "gm_sigma_m"), ("gnss", "gm_tau_s"))
#: Lag-1 autocorrelation of the whitened position innovations above which the fix errors are
#: taken as time-correlated (a correct model gives ~0; white fixes with a tuned IMU give < 0.1).
ACF_CORRELATED = 0.3
#: Log-likelihood gain the two extra Gauss-Markov parameters must bring: half the 1e-4 quantile of
#: chi-square with 2 dof (a likelihood-ratio test).
GM_MIN_GAIN = 9.2
#: Passes of the white-noise search after which the whiteness of the innovations is checked (the
#: coordinate probe of 7 parameters takes 15): a search that cannot fit correlated errors is
#: abandoned then for the Gauss-Markov one.
CHECK_AFTER = 20
# : Budget of EKF passes of the aids' search (step 5; its coordinate probe of four parameters takes
# 9).
AIDS_EVALUATIONS = 25
#: ... and of the search of the vehicle's axes again under the final (inflated) sigmas.
OFFSET_EVALUATIONS = 12
#: Log-likelihood gain an angle of the vehicle's axes must bring to be kept: half the 1e-4
#: quantile of chi-square with 1 dof (a likelihood-ratio test; zero is the model without it).
OFFSET_MIN_GAIN = 7.57
#: Smallest white part of a fix's 1-sigma the tuner accepts [m]: no receiver's fix output is
#: better than that (below it, the filter only becomes numerically stiff).
MIN_WHITE_SIGMA_M = 0.01
# The non-holonomic constraint's sigmas are kept at or above ``[zupt] velocity_sigma_mps``: a
# rolling vehicle's body sways at least as much as a parked one's, and a constraint tighter than
# that turns every error the IMU model misses (scale factors, misalignment, vibration) into
# velocity innovations the search then answers by inflating other noise (on a simulated
# consumer-IMU UGV the accelerometer turn-on sigma went to 576 mg with a 1 mm/s constraint).
#: The parameters whose likelihood is bounded from below only (step 4).
TURN_ON_SIGMAS = (("imu", "gyro_bias_sigma0_deg_h"), ("imu", "accel_bias_sigma0_mg"))
#: Log-likelihood the tuned point may give up, in all, when the turn-on sigmas are drawn back
#: toward their starting values (step 4): half the 95 % quantile of chi-square with 1 dof.
SHRINK_TOLERANCE = 1.92
# : A parameter closer than this to its starting value [decades] is not drawn back (not worth
# passes).
SHRINK_MIN_DECADES = 0.1
#: Each parameter stays within this many decades of its starting value.
_BOUND_DECADES = 2.0
#: A white-noise density measured at rest is a floor for the search: in motion, vibration only adds
#: to the sensor's noise. The floor sits this many decades below the measurement (1/1.25: the
#: at-rest estimates scatter by +-11 % on simulated runs with 95-110 s at rest).
REST_FLOOR_DECADES = float(np.log10(1.25))
_RAD_S_TO_DEG_RTH = 180.0 / np.pi * 60.0  # rad/sqrt(s) -> deg/sqrt(h)
_MPS2_RTHZ_TO_MPS_RTH = 60.0  # m/s^2/sqrt(Hz) -> m/s/sqrt(h)


@dataclass
class TuneResult:
    """Outcome of :func:`tune`.

    Attributes
    ----------
    values : dict
        Section -> key -> tuned value (configuration units), the keys that were identified.
    start : dict
        The same keys' starting values (configuration or stationary analysis).
    fixed : list of str
        ``section.key`` of the parameters the user set, left alone.
    from_stationary : dict
        What the stationary stretches gave (densities, seconds used), or empty.
    nis_before, nis_after : float or None
        Mean position NIS per dof of the EKF at the start and at the tuned values.
    loglik_before, loglik_after : float
        Innovation log-likelihood at the start and at the tuned values.
    n_evaluations : int
    seconds : float
    """

    values: dict
    start: dict
    fixed: list
    from_stationary: dict = field(default_factory=dict)
    nis_before: float | None = None
    nis_after: float | None = None
    loglik_before: float = 0.0
    loglik_after: float = 0.0
    n_evaluations: int = 0
    seconds: float = 0.0

    def line(self) -> str:
        """One line for the terminal."""
        keys = [key for sec in self.values.values() for key in sec]
        parts = [  # a key two sections share (sigma_scale) is named with its section
            f"{f'{s}.' if keys.count(key) > 1 else ''}{key}={_short(v)}"
            for s, sec in self.values.items()
            for key, v in sec.items()
        ]
        nis = (
            f"; position NIS/dof {self.nis_before:.2f} -> {self.nis_after:.2f}"
            if self.nis_before is not None and self.nis_after is not None
            else ""
        )
        back = [k.split(".")[-1] for k in self.from_stationary.get("drawn_back", [])]
        win = self.from_stationary.get("windows")
        where = (
            f", on windows of {win['imu_seconds_per_pass']:.0f} s of the run's "
            f"{win['run_seconds']:.0f} s, "
            + ("refined and " if win.get("refined_over_whole_run") else "")
            + "confirmed over the whole run"
            if win
            else ""
        )
        return (
            f"tuned noise ({self.n_evaluations} EKF passes, {self.seconds:.1f} s{where}): "
            + ", ".join(parts)
            + nis
            + (
                f"; drawn back toward the start, as far as the likelihood allows: {', '.join(back)}"
                if back
                else ""
            )
            + (f"; kept from config: {', '.join(self.fixed)}" if self.fixed else "")
            + "".join(
                f"; {k.split('.')[-1]} no lower than the IMU class's {v:g} "
                f"{k.rsplit('_', 1)[-1]} (the run never showed "
                "its yaw: its tilt hides the bias)"
                for k, v in self.from_stationary.get("class_floor", {}).items()
            )
        )

    def to_toml(self, cfg: RunConfig) -> str:
        """A reusable configuration file: every ``[imu]`` key and ``gnss.sigma_scale`` as tuned."""
        lines = [
            "# Noise identified by gnssacc --tune auto from this recording (no truth used).",
            "# Reuse it with: gnssacc run ... --config tuned.toml --tune none",
            "",
            "[imu]",
        ]
        lines += [f"{k} = {toml_value(_plain(v))}" for k, v in cfg["imu"].items()]
        lines += ["", "[gnss]"] + [
            f"{k} = {toml_value(_plain(cfg['gnss'][k]))}"
            for k in ("sigma_scale", "gm_sigma_m", "gm_tau_s")
        ]
        for sec, key in (k for spec in VEHICLE_AIDS for k in spec.noise_keys):  # where identified
            if key in self.values.get(sec, {}):
                lines += ["", f"[{sec}]"] if f"[{sec}]" not in lines else []
                lines.append(f"{key} = {toml_value(_plain(cfg[sec][key]))}")
        return "\n".join(lines) + "\n"

    def to_dict(self) -> dict:
        return {
            "values": self.values,
            "start": self.start,
            "fixed": self.fixed,
            "from_stationary": self.from_stationary,
            "nis_before": self.nis_before,
            "nis_after": self.nis_after,
            "loglik_before": self.loglik_before,
            "loglik_after": self.loglik_after,
            "n_evaluations": self.n_evaluations,
            "seconds": self.seconds,
        }


def _plain(v):
    if isinstance(v, str):  # "auto"
        return v
    if isinstance(v, (list, tuple, np.ndarray)):
        return [float(f"{float(x):.4g}") for x in v]
    return float(f"{float(v):.4g}")


def _short(v) -> str:
    v = _plain(v)
    if isinstance(v, list):
        return "[" + ",".join(f"{x:g}" for x in v) + "]" if len(set(v)) > 1 else f"{v[0]:g}"
    return f"{v:g}"


def _prior_widths(cfg: RunConfig, params: list, info: dict) -> np.ndarray:
    """Prior 1-sigma per parameter [decades]: tighter where the stationary stretches measured it."""
    wide, tight = (
        float(cfg["tune"]["prior_decades"]),
        float(cfg["tune"]["stationary_prior_decades"]),
    )
    return np.array([tight if key in info else wide for _, key in params])


def _lower_bounds(params: list, info: dict) -> np.ndarray:
    """Lower search bound per parameter [decades]: the at-rest floor where the stationary stretches
    measured the density (:data:`REST_FLOOR_DECADES`), the class's floor of a run that never
    showed its yaw (``info["class_floor_decades"]``, :func:`rest_floor`)."""
    floors = info.get("class_floor_decades", {})
    return np.array(
        [
            floors.get(key, -REST_FLOOR_DECADES if key in info else -_BOUND_DECADES)
            for _, key in params
        ]
    )


def _start_values(cfg: RunConfig, free: list, noise) -> tuple[dict, dict]:
    """Starting value per free parameter (numpy arrays), from the configuration or the stationary
    noise."""
    start = {p: np.atleast_1d(np.asarray(cfg[p[0]][p[1]], float)).copy() for p in free}
    info = {}
    if noise is not None:
        dens = {
            ("imu", "gyro_arw_deg_rth"): (noise.gyro_density, _RAD_S_TO_DEG_RTH),
            ("imu", "accel_vrw_mps_rth"): (noise.accel_density, _MPS2_RTHZ_TO_MPS_RTH),
        }
        for p, (d, scale) in dens.items():
            if (
                p in start
                and d is not None
                and np.all(np.isfinite(d))
                and np.all(np.asarray(d) > 0)
            ):
                start[p] = np.asarray(d, float) * scale
                info[p[1]] = _plain(start[p])
        info["stationary_s"] = float(noise.seconds)
    return start, info


def starting_config(run, cfg: RunConfig, noise) -> RunConfig:
    """``cfg`` with the free parameters of step 2 at :func:`tune`'s starting values (the white-noise
    densities measured at rest, where ``noise`` has them), e.g. for a pass before the search."""
    params, _ = measurement_stage(run, cfg)
    start, _ = _start_values(cfg, [p for p in params if p not in cfg.explicit], noise)
    upd: dict = {}
    for (sec, key), v in start.items():
        upd.setdefault(sec, {})[key] = v.tolist() if v.size > 1 else float(v[0])
    return cfg.with_values(upd, "the tuner's start") if upd else cfg


class _Objective:
    """Negative innovation log-likelihood of one EKF pass at log10 scale factors ``theta``."""

    def __init__(
        self,
        run,
        cfg,
        free,
        start,
        stationary,
        quality,
        init,
        method,
        kinds,
        filter_pass: FilterPass,
    ):
        self.run, self.cfg, self.free, self.start, self.filter_pass = (
            run,
            cfg,
            free,
            start,
            filter_pass,
        )
        self.stationary, self.quality, self.init, self.method, self.kinds = (
            stationary,
            quality,
            init,
            method,
            kinds,
        )
        self.cov_every = int(cfg["tune"]["cov_every"])
        self.init_scale = float(cfg["gnss"]["sigma_scale"])  # the scale the start was made with
        self.stats: dict = {}
        self.passes: dict = {}  # theta's bytes -> (negative log-likelihood, stats): passes made

    def config(self, theta) -> RunConfig:
        upd: dict = {}
        for p, th in zip(self.free, theta, strict=True):
            v = self.start[p] + th * ADDITIVE[p] if p in ADDITIVE else self.start[p] * 10.0**th
            if p == ("gnss", "sigma_scale"):
                v = np.maximum(v, MIN_WHITE_SIGMA_M / float(np.median(self.run.gnss.sigma_ned)))
            elif p in FLOORED:
                v = np.maximum(v, float(self.cfg[FLOORED[p][0]][FLOORED[p][1]]))
            upd.setdefault(p[0], {})[p[1]] = v.tolist() if v.size > 1 else float(v[0])
        return self.cfg.with_values(upd, "tuned")

    def __call__(self, theta) -> float:
        theta = np.asarray(theta, float)
        key = theta.tobytes()
        if key not in self.passes:
            self.passes[key] = self.evaluate(theta)
        value, stats = self.passes[key]
        self.stats[tuple(np.round(theta, 12))] = stats
        return value

    def ahead(self, thetas) -> None:
        """Evaluate the points ``thetas`` not yet evaluated side by side
        (:func:`gnssacc.core.parallel.side_by_side`; the workers kept for this objective), so
        that the calls that follow find them: the same values as evaluated one by one. A point
        whose pass raises is left to its call (which raises there, as without this)."""
        todo = {}
        for theta in thetas:
            theta = np.asarray(theta, float)
            if theta.tobytes() not in self.passes:
                todo.setdefault(theta.tobytes(), theta)
        if len(todo) < 2 or usable_jobs() < 2 or forks_held():  # guesses: not made one by one
            return
        for key, got in zip(
            todo, side_by_side(self.evaluate_safely, [(t,) for t in todo.values()], keep=True)
        ):
            if got is not None:
                self.passes[key] = got

    def evaluate_safely(self, theta: np.ndarray) -> tuple[float, dict] | None:
        """:meth:`evaluate`, ``None`` where it raises."""
        try:
            return self.evaluate(theta)
        except Exception:  # noqa: BLE001 (raised again when the point is called for)
            return None

    def evaluate(self, theta: np.ndarray) -> tuple[float, dict]:
        """One EKF pass at ``theta``: the negative log-likelihood and the pass's statistics."""
        cfg = self.config(theta)
        scale = float(cfg["gnss"]["sigma_scale"])
        # The start's position sigma is that of the fixes it came from: it scales with them.
        init = replace(self.init, sigma_pos_m=self.init.sigma_pos_m * scale / self.init_scale)
        sol = self.filter_pass(
            self.run,
            ungated(cfg),
            self.method,
            init=init,
            stationary=self.stationary,
            quality=self.quality,
            output_times=np.zeros(0),
            cov_every=self.cov_every,
        )
        return -_loglik(sol.stats, self.kinds), sol.stats


def ml_search(
    negloglik,
    n: int,
    budget: int,
    prior_decades: float,
    step_decades: float = 0.5,
    theta0: np.ndarray | None = None,
    probe_decades: float | None = 1.0,
    lower: np.ndarray | None = None,
):
    """Minimise ``negloglik(theta) + |theta|^2 / (2 d^2)`` over log10 scale factors ``theta``.

    The generic part of the tuner: first each coordinate in turn is probed at ``+-probe_decades``
    and moved there when that is better (the starting values can be decades off, e.g. industrial
    defaults for a tactical IMU, and a local simplex does not travel that far within a small
    budget); then Nelder-Mead (scipy's, :func:`gnssacc.prepare.nelder_mead.nelder_mead`) from
    there with an initial simplex of ``step_decades`` per axis; at most ``budget`` evaluations in
    all, each ``theta`` clipped to +-:data:`_BOUND_DECADES`. When ``negloglik`` has an
    ``ahead(points)`` method (:class:`_Objective`: the points evaluated side by side in forked
    processes), it is told the points the search will, or may, ask for next (both directions of
    a coordinate's probe, the simplex's vertices, a shrink's); the search asks for the same points
    in the same order either way, so it ends at the same point.

    Parameters
    ----------
    negloglik : callable
        ``theta (n,) -> float``, the negative log-likelihood (``inf`` where it cannot be evaluated).
    n : int
    budget : int
    prior_decades : float or ndarray (n,)
        ``d``, the 1-sigma of the log-normal prior around the starting values [decades].
    step_decades : float
    theta0 : ndarray (n,), optional
        Where the search starts (default: the starting values, ``theta = 0``).
    probe_decades : float or None
        Coordinate probe step; ``None`` skips the probe (e.g. to continue an earlier search).
    lower : ndarray (n,), optional
        Lower bound per parameter [decades] (default ``-_BOUND_DECADES``).

    Returns
    -------
    theta : ndarray (n,)
        The best point evaluated.
    value : float
        Its objective value.
    n_evaluations : int
    """
    best = [np.inf, np.zeros(n)]
    count = [0]
    lo = (
        np.full(n, -_BOUND_DECADES)
        if lower is None
        else np.maximum(np.asarray(lower, float), -_BOUND_DECADES)
    )

    def objective(theta):
        theta = np.clip(theta, lo, _BOUND_DECADES)
        count[0] += 1
        j = float(negloglik(theta)) + 0.5 * float(np.sum(np.square(theta / prior_decades)))
        if not np.isfinite(j):
            return 1e300
        if j < best[0]:
            best[:] = [j, np.array(theta)]
        return j

    def ahead(points, room=None):  # evaluated side by side where the objective can
        if hasattr(negloglik, "ahead"):
            room = budget - count[0] if room is None else room
            negloglik.ahead([np.clip(x, lo, _BOUND_DECADES) for x in points[: max(room, 0)]])

    x0 = np.zeros(n) if theta0 is None else np.asarray(theta0, float)
    f0 = objective(x0)
    for i in range(n if probe_decades else 0):
        ahead([x0 - probe_decades * np.eye(n)[i], x0 + probe_decades * np.eye(n)[i]])
        for d in (-probe_decades, probe_decades):
            if count[0] >= budget:
                break
            x = x0.copy()
            x[i] += d
            f = objective(x)
            if f < f0:
                f0, x0 = f, x
    left = budget - count[0]
    if left > 1:
        simplex = x0 + np.vstack([np.zeros(n), step_decades * np.eye(n)])
        nelder_mead(objective, simplex, left, 0.02, 0.5, ahead=ahead, width=usable_jobs())
    return best[1], best[0], count[0]


def draw_back(
    negloglik, theta, prior_decades, eligible=None, value: float | None = None
) -> tuple[np.ndarray, int, list]:
    """Step 4 of the module docstring: each eligible coordinate of ``theta`` drawn toward 0 (the
    starting values) while ``negloglik`` stays within :data:`SHRINK_TOLERANCE` of its value at
    ``theta`` (the tolerance is shared by all coordinates).

    Parameters
    ----------
    negloglik : callable
        ``theta (n,) -> float``, the negative log-likelihood (no prior term).
    theta : ndarray (n,)
        The search's best point [decades from the starting values].
    prior_decades : float or ndarray (n,)
        Prior widths: the coordinates are visited in decreasing ``|theta / prior_decades|``.
    eligible : ndarray of bool (n,), optional
        Which coordinates may be drawn back (default: all).
    value : float, optional
        ``negloglik(theta)``, when known (saves a pass).

    Returns
    -------
    theta : ndarray (n,)
        The drawn-back point (``theta`` itself when nothing moved).
    n_evaluations : int
        Passes made (at most three per coordinate).
    moved : list of int
        The coordinates that were drawn back.
    """
    theta = np.array(theta, float)
    n, moved = (1, []) if value is None else (0, [])
    worst = float(negloglik(theta) if value is None else value) + SHRINK_TOLERANCE
    order = np.argsort(-np.abs(theta / np.broadcast_to(prior_decades, theta.shape)), kind="stable")
    n_all = len(theta)
    for i in order:
        if abs(theta[i]) < SHRINK_MIN_DECADES or (eligible is not None and not eligible[i]):
            continue
        fails, keeps = 0.0, 1.0  # fractions of theta[i] kept: too little / enough for the data
        if hasattr(negloglik, "ahead"):  # the first two trials (and the third's two) side by side
            fracs = (0.0, 0.5, 0.25, 0.75)[: max(2, usable_jobs())]
            negloglik.ahead([theta * np.where(np.arange(n_all) == i, f, 1.0) for f in fracs])
        for step in range(3):  # all the way back, then bisection: 0, 0.5, 0.25 or 0.75
            frac = 0.5 * (fails + keeps) if step else 0.0
            trial = theta.copy()
            trial[i] *= frac
            n += 1
            if float(negloglik(trial)) <= worst:
                keeps = frac
            else:
                fails = frac
            if keeps == 0.0:
                break
        if keeps < 1.0:
            theta[i] *= keeps
            moved.append(int(i))
    return theta, n, moved


def _gauss_markov_stage(
    run, cfg, free, start, stats, stationary, quality, init, method, kinds, info, filter_pass
):
    """Step 3 of the module docstring; returns the configuration, its EKF stats, the passes made and
    whether the Gauss-Markov model was kept."""
    acf, n = stats.get("acf1_pos"), stats.get("n_pos_updates", 0)
    info["innovation_acf1"] = acf
    gm_free = [p for p in GM_PARAMETERS[1:] if p not in cfg.explicit]
    if acf is None or n < 10 or acf < max(ACF_CORRELATED, 3.0 / np.sqrt(3 * n)) or len(gm_free) < 2:
        return None, stats, 0, False
    # Start: the stated sigmas as the correlated part and a fifth of them as the white part.
    scale = float(cfg["gnss"]["sigma_scale"])
    start = dict(start)
    if ("gnss", "sigma_scale") in start:
        start[("gnss", "sigma_scale")] = np.atleast_1d(0.2 * scale)
    start[("gnss", "gm_sigma_m")] = np.median(run.gnss.sigma_ned, axis=0) * scale
    start[("gnss", "gm_tau_s")] = np.atleast_1d(cfg.gnss_gm_tau.mean())
    params = list(free) + gm_free
    obj = _Objective(run, cfg, params, start, stationary, quality, init, method, kinds, filter_pass)
    theta, j_best, n_eval = ml_search(
        obj,
        len(params),
        int(cfg["tune"]["max_evaluations"]),
        _prior_widths(cfg, params, info),
        lower=_lower_bounds(params, info),
    )
    gm_stats = obj.stats[tuple(np.round(theta, 12))]
    gain = _loglik(gm_stats, kinds) - _loglik(stats, kinds)
    info["gauss_markov_loglik_gain"] = float(gain)
    if gain <= GM_MIN_GAIN:
        return None, stats, n_eval, False
    theta, n_back = _draw_back(obj, theta, _prior_widths(cfg, params, info), kinds, info)
    return obj.config(theta), obj.stats[tuple(np.round(theta, 12))], n_eval + n_back, True


def _draw_back(obj, theta, prior, kinds, info) -> tuple[np.ndarray, int]:
    """:func:`draw_back` of the turn-on sigmas above their start, on an :class:`_Objective` at its
    best ``theta``; notes what moved in ``info``."""
    eligible = np.array([p in TURN_ON_SIGMAS for p in obj.free]) & (np.asarray(theta) > 0)
    if not eligible.any():
        info["drawn_back"] = []
        return np.asarray(theta), 0
    theta, n, moved = draw_back(
        obj, theta, prior, eligible, -_loglik(obj.stats[tuple(np.round(theta, 12))], kinds)
    )
    info["drawn_back"] = [f"{obj.free[i][0]}.{obj.free[i][1]}" for i in moved]
    return theta, n


def _loglik(stats: dict, kinds) -> float:
    return float(sum(stats[f"loglik_{k}"] for k in kinds))


def aids(run, cfg: RunConfig) -> tuple[tuple, tuple]:
    """The aid parameters :func:`tune` identifies on ``run`` with ``cfg`` (the user's explicit keys
    included: they are left alone) and the update kinds they add to the likelihood: those of the
    ground vehicle's aids (:data:`VEHICLE_AIDS`) enabled and in use."""
    params, kinds = (), ()
    for spec in VEHICLE_AIDS:
        section, key = spec.enabled_key
        if cfg[section][key] and spec.in_use(run, cfg):
            params += spec.noise_keys
            kinds += spec.kinds
    return params, kinds


def measurement_stage(run, cfg: RunConfig) -> tuple[list, tuple]:
    """The parameters identified with the IMU noise on ``run`` (:data:`PARAMETERS` less those of an
    aid of that stage that is off or has no data, e.g. the GNSS velocity's scale on a recording
    without velocities) and the update kinds those aids add to the likelihood (beside the
    positions' and the zero rate's)."""
    params, kinds = list(PARAMETERS), ()
    for spec in REGISTRY:
        if spec.stage != "imu" or spec.enabled_key is None:
            continue
        section, key = spec.enabled_key
        if cfg[section][key] and spec.in_use(run, cfg):
            kinds += spec.kinds
        else:
            params = [p for p in params if p not in spec.noise_keys]
    return params, kinds


def without_aids(cfg: RunConfig) -> RunConfig:
    """``cfg`` with the ground vehicle's aids off, for the IMU and GNSS noise's passes (step 5)
    and the yaw bank's (:func:`gnssacc.prepare.yawbank.select_yaw`)."""
    keys = [spec.enabled_key for spec in VEHICLE_AIDS]
    if not any(cfg[section][key] for section, key in keys):
        return cfg
    off: dict = {}
    for section, key in keys:
        off.setdefault(section, {})[key] = False
    return cfg.with_values(off, "tuning passes, aids off")


def ungated(cfg: RunConfig) -> RunConfig:
    """``cfg`` without the EKF's position gate, for the tuner's passes.

    A gate makes the likelihood blind to the innovations it rejects, so the search is rewarded
    for shrinking the noise until most fixes are rejected: with ``[ekf] position_gate_nis = 16.3``
    on a clean simulated run the tuned EKF ended 426 m off (1.4 m ungated). The noise is identified
    from every innovation; the gate applies to the estimates made with it.
    """
    if float(cfg["ekf"]["position_gate_nis"]) == 0.0:
        return cfg
    return cfg.with_values({"ekf": {"position_gate_nis": 0.0}}, "tuning passes, ungated")


#: The parameter whose search a run that never showed its yaw bounds below (:func:`rest_floor`).
FLOORED_AT_REST = ("imu", "accel_bias_sigma0_mg")


def rest_floor(cfg: RunConfig, init, noise) -> dict:
    """``{(section, key): value}``: on a run whose start left its yaw undetermined (it never turned
    or accelerated enough to tell it), the least accelerometer turn-on sigma the search may end at,
    the IMU class's (:func:`gnssacc.prepare.turn_allowance.accel_turn_on_mg` of the gyro noise at
    rest, ``noise``). There the fixes and stationary updates see the tilt and the horizontal bias
    as one sum, ``g phi - R_nb b_a``, and on a simulated IMU at rest the likelihood barely told the
    sigma: the search ended where its first steps went (an industrial IMU, true 5 mg, searched to
    2 mg: its tilt error 3 stated sigma) or stayed at the default (20 mg on a consumer IMU whose
    turn-on is 30). Empty when the yaw was told, the user set the value, or there is no gyro
    noise at rest to tell the class."""
    from .turn_allowance import accel_turn_on_mg, rest_density_deg_rth

    if init is None or getattr(init, "yaw_evidence", "") != "undetermined":
        return {}
    if FLOORED_AT_REST in cfg.explicit:
        return {}
    mg = accel_turn_on_mg(rest_density_deg_rth(noise))
    return {FLOORED_AT_REST: float(f"{mg:.3g}")} if np.isfinite(mg) else {}


def _floored(start: dict, info: dict, floor: dict) -> None:
    """Raise each floored parameter's start to its floor and bound its search there
    (``info["class_floor_decades"]``, which :func:`_lower_bounds` reads)."""
    for p, v in floor.items():
        if p in start:
            start[p] = np.maximum(start[p], v)
            info.setdefault("class_floor_decades", {})[p[1]] = float(np.log10(v / start[p].max()))
            info.setdefault("class_floor", {})[f"{p[0]}.{p[1]}"] = v


def tune(
    run,
    cfg: RunConfig,
    stationary=None,
    quality=None,
    init=None,
    noise=None,
    *,
    filter_pass: FilterPass,
) -> tuple[RunConfig, TuneResult]:
    """Identify the free noise parameters (see the module docstring).

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
        Starting values; keys in ``cfg.explicit`` are never changed.
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
    quality : gnssacc.checks.quality.QualityReport, optional
    init : InitialState
        Where the EKF passes start (e.g. from :func:`gnssacc.prepare.yawbank.select_yaw`).
    noise : gnssacc.prepare.stationary.StationaryNoise, optional
        White-noise densities from stationary stretches (starting values of ARW / VRW).
    filter_pass : gnssacc.prepare.filter_pass.FilterPass
        The EKF pass whose innovation likelihood is maximised.

    Returns
    -------
    cfg : RunConfig
        The configuration with the tuned values.
    result : TuneResult
    """
    t0 = time.perf_counter()
    aid_params, aid_kinds = aids(run, cfg)
    params, measured = measurement_stage(run, cfg)
    free = [p for p in params if p not in cfg.explicit]
    fixed = [f"{s}.{k}" for s, k in params + list(aid_params) if (s, k) in cfg.explicit]
    start, info = _start_values(cfg, free, noise)
    _floored(start, info, rest_floor(cfg, init, noise))
    kinds = ("pos", "zaru") + measured
    kinds += ("acc",) if cfg["tune"]["likelihood"] == "position+accel" else ()
    method = "ekf-acc" if "acc" in kinds else "ekf"
    raw, n_eval, before, after = {}, 0, {}, {}
    if free:
        raw, n_eval, before, after = _imu_stage(
            run,
            without_aids(cfg),
            free,
            start,
            stationary,
            quality,
            init,
            method,
            kinds,
            info,
            filter_pass,
        )
    tuned = cfg.with_values(raw, "tuned") if raw else cfg
    aid_raw, n_aid = _aids_stage(
        run,
        tuned,
        cfg,
        aid_params,
        aid_kinds,
        stationary,
        quality,
        init,
        method,
        kinds,
        filter_pass,
        start,
        info,
    )
    for sec, vals in aid_raw.items():
        raw.setdefault(sec, {}).update(vals)
    if not raw:
        return cfg, TuneResult({}, {}, fixed, info, seconds=time.perf_counter() - t0)
    tuned = cfg.with_values(raw, "tuned")
    values = {sec: {key: _plain(v) for key, v in vals.items()} for sec, vals in raw.items()}
    result = TuneResult(
        values,
        {f"{s}.{k}": _plain(v) for (s, k), v in start.items()},
        fixed,
        info,
        before.get("nis_pos_mean"),
        after.get("nis_pos_mean"),
        _loglik(before, kinds) if before else 0.0,
        _loglik(after, kinds) if after else 0.0,
        n_eval + n_aid,
        time.perf_counter() - t0,
    )
    return tuned, result


def _imu_stage(run, cfg, free, start, stationary, quality, init, method, kinds, info, filter_pass):
    """Steps 2-4 of the module docstring on ``cfg`` (the aids off): the tuned values (section ->
    key -> value, configuration units, as the search set them), the passes made, and the EKF's
    stats at the start and at the tuned point."""
    obj = _Objective(run, cfg, free, start, stationary, quality, init, method, kinds, filter_pass)
    budget, prior = int(cfg["tune"]["max_evaluations"]), _prior_widths(cfg, free, info)
    lower = _lower_bounds(free, info)
    theta, j_best, n_eval = ml_search(obj, len(free), min(CHECK_AFTER, budget), prior, lower=lower)
    if not np.isfinite(j_best):
        raise InputError(
            run.where,
            "noise identification failed: the EKF diverged for every candidate; "
            "set the IMU noise in a config file and use --tune none",
        )
    before, after = obj.stats[tuple(np.zeros(len(free)))], obj.stats[tuple(np.round(theta, 12))]
    tuned, after_gm, n_gm, gm_kept = _gauss_markov_stage(
        run, cfg, free, start, after, stationary, quality, init, method, kinds, info, filter_pass
    )
    if gm_kept:
        tuned, after = tuned, after_gm
    else:  # white fixes: finish the white-noise search where it stood
        more = budget - n_eval
        if more > 1:
            theta, _, n_more = ml_search(
                obj, len(free), more, prior, theta0=theta, probe_decades=None, lower=lower
            )
            n_eval += n_more
        theta, n_back = _draw_back(obj, theta, prior, kinds, info)
        n_eval += n_back
        tuned, after = obj.config(theta), obj.stats[tuple(np.round(theta, 12))]
    raw: dict = {}
    for sec, key in free + (list(GM_PARAMETERS[1:]) if gm_kept else []):
        raw.setdefault(sec, {})[key] = tuned[sec][key]
    return raw, n_eval + n_gm, before, after


def _aids_stage(
    run,
    tuned,
    cfg,
    aid_params,
    aid_kinds,
    stationary,
    quality,
    init,
    method,
    kinds,
    filter_pass,
    start: dict,
    info: dict,
) -> tuple[dict, int]:
    """Step 5 of the module docstring: the free aid parameters by maximum likelihood with the
    tuned IMU and GNSS noise held (``tuned``); ``cfg`` the configuration the start was made with.
    Returns the values (section -> key -> value) and the passes made; adds the starting values
    to ``start``, and to ``info`` what the likelihood tells of the vehicle's axes
    (``vehicle_axes``: :func:`_settle_offsets`)."""
    free = [p for p in aid_params if p not in cfg.explicit]
    if not free:
        return {}, 0
    aid_start = {p: np.atleast_1d(np.asarray(cfg[p[0]][p[1]], float)) for p in free}
    start.update(aid_start)
    obj = _Objective(
        run,
        tuned,
        free,
        aid_start,
        stationary,
        quality,
        init,
        method,
        kinds + aid_kinds,
        filter_pass,
    )
    obj.init_scale = float(
        cfg["gnss"]["sigma_scale"]
    )  # the start was made with the fixes at this scale
    theta, j_best, n_eval = ml_search(
        obj, len(free), AIDS_EVALUATIONS, _prior_widths(cfg, free, {})
    )
    if not np.isfinite(j_best):
        return {}, n_eval
    best = obj.config(theta)
    raw: dict = {}
    for sec, key in free:
        raw.setdefault(sec, {})[key] = best[sec][key]
    n_eval += _inflate(raw, obj, theta)
    offsets = [p for p in free if p in ADDITIVE]
    n_again = _settle_offsets(obj, raw, offsets, cfg, info) if offsets else 0
    return raw, n_eval + n_again


def _with_angle(obj: "_Objective", theta, i: int, angle: float) -> np.ndarray:
    """``theta`` with ``obj``'s additive parameter ``i`` (an angle of the vehicle's axes) at
    ``angle`` [deg]; zero by one formula, so that the points the offsets' test and their record
    read are the same passes of ``obj``."""
    p = obj.free[i]
    start, step = float(obj.start[p][0]), ADDITIVE[p]
    out = np.array(theta, float)
    out[i] = -start / step if angle == 0.0 else (angle - start) / step
    return out


def _significant_offsets(obj: "_Objective", theta: np.ndarray) -> tuple[np.ndarray, int, list]:
    """``theta`` with each additive parameter (the vehicle's axes) at zero unless it raises the
    log-likelihood by more than :data:`OFFSET_MIN_GAIN` (a likelihood-ratio test per angle, in
    turn); the passes made and the indices set to zero."""
    theta = np.array(theta, float)
    best = -float(obj(theta))
    n, dropped = 1, []
    for i, p in enumerate(obj.free):
        if p not in ADDITIVE:
            continue
        trial = _with_angle(obj, theta, i, 0.0)
        if trial[i] == theta[i]:
            continue
        n += 1
        if best - (-float(obj(trial))) <= OFFSET_MIN_GAIN:
            theta, dropped = trial, dropped + [i]
            best = -float(obj(theta))
    return theta, n, dropped


def _inflate(raw: dict, obj: "_Objective", theta: np.ndarray) -> int:
    """Each aid's sigmas in ``raw`` (the values ``obj`` takes at its tuned point ``theta``) times
    :func:`correlation_inflation`, one aid after the other, in place; returns the passes made.

    The factor multiplies the sigmas in use, wherever the search left them (at the floor of the
    constraint's, at two decades below the start, or anywhere between): the likelihood of the
    updates the aid's errors do not enter decides, so two searches that end a hair apart end with
    nearly equal sigmas (a rule that skipped the sigmas at a lower limit inflated 0.0201 m/s to
    0.069 and left 0.0200 alone)."""
    keys = [p for spec in VEHICLE_AIDS for p in spec.inflated_keys if p in obj.free]
    if not keys:
        return 0
    at = _objective_at(obj, raw, keys)
    here = np.zeros(len(keys))  # the sigmas of ``raw``
    tuned_stats = obj.stats.get(tuple(np.round(np.asarray(theta, float), 12)))
    if tuned_stats is not None:  # the same configuration: its pass is made
        at.stats[tuple(here)] = tuned_stats
    others = tuple(k for k in obj.kinds if k not in {k for s in VEHICLE_AIDS for k in s.kinds})
    for spec in VEHICLE_AIDS:
        idx = [keys.index(p) for p in spec.inflated_keys if p in keys]
        if not idx:
            continue

        def loglik(d: float, idx=idx) -> float:  # the other updates', the aid's sigmas d up
            th = here.copy()
            th[idx] += d
            key = tuple(np.round(th, 12))
            if key not in at.stats:
                at(th)
            return _loglik(at.stats[key], others)

        factor = correlation_inflation(loglik)
        if factor <= 1.0:
            continue
        here[idx] += np.log10(factor)
        for i in idx:
            sec, key = keys[i]
            raw[sec][key] = float(raw[sec][key]) * factor
    return len(at.passes)


def _objective_at(obj: "_Objective", raw: dict, keys: list) -> "_Objective":
    """An :class:`_Objective` like ``obj`` over ``keys`` alone, started at their values in
    ``raw`` (``theta = 0``), the other values of ``raw`` held (on ``obj``'s configuration)."""
    held = obj.cfg.with_values(
        {sec: {k: v for k, v in vals.items() if (sec, k) not in keys} for sec, vals in raw.items()},
        "tuned",
    )
    at = _Objective(
        obj.run,
        held,
        keys,
        {p: np.atleast_1d(np.asarray(raw[p[0]][p[1]], float)) for p in keys},
        obj.stationary,
        obj.quality,
        obj.init,
        obj.method,
        obj.kinds,
        obj.filter_pass,
    )
    at.init_scale = obj.init_scale
    return at


def _settle_offsets(obj: "_Objective", raw: dict, offsets: list, cfg, info: dict) -> int:
    """The vehicle's axes ``offsets`` under the final sigmas (in ``raw``, held): searched again
    from their values in ``raw`` (inflated or not: the joint search's budget can leave them short,
    and a search only after an inflation would switch the axes with the inflation's decision),
    then each kept only on :func:`_significant_offsets`' test; ``raw`` updated in place, and
    ``info["vehicle_axes"]`` told what the likelihood says of each angle
    (:func:`_axes_resolution`); returns the passes made."""
    obj2 = _objective_at(obj, raw, offsets)
    prior = _prior_widths(cfg, offsets, {})
    found, j, n = ml_search(
        obj2, len(offsets), OFFSET_EVALUATIONS, prior, step_decades=0.2, probe_decades=None
    )
    found = found if np.isfinite(j) else np.zeros(len(offsets))
    theta, n_test, dropped = _significant_offsets(obj2, found)
    settled = obj2.config(theta)
    for i, (sec, key) in enumerate(offsets):
        raw[sec][key] = 0.0 if i in dropped else settled[sec][key]
    n_res, info["vehicle_axes"] = _axes_resolution(obj2, found, dropped)
    return n + n_test + n_res


def _axes_resolution(obj: "_Objective", found, dropped: list) -> tuple[int, dict]:
    """Each angle of ``obj`` (the vehicle's axes alone) as the likelihood tells it around the
    search's maximum ``found``: ``{key: {"found_deg", "sigma_deg", "kept"}}``
    (:func:`gnssacc.prepare.attitude_axes.likelihood_sigma`; ``kept``: the angle is in use, not
    zero and not ``dropped``), and the passes made (the points zero and beyond are read side by
    side)."""
    made, found = len(obj.passes), np.asarray(found, float)

    def at(i: int, angle: float) -> np.ndarray:
        return _with_angle(obj, found, i, angle)

    found_deg = [float(obj.start[p][0]) + found[i] * ADDITIVE[p] for i, p in enumerate(obj.free)]
    obj.ahead([at(i, 0.0) for i in range(len(found))])
    best = -float(obj(found))
    drops = [best + float(obj(at(i, 0.0))) for i in range(len(found))]
    obj.ahead([at(i, probe_at(a)) for i, a in enumerate(found_deg) if needs_probe(a, drops[i])])
    out = {}
    for i, (_, key) in enumerate(obj.free):
        sigma = likelihood_sigma(
            lambda a, i=i: best if a == found_deg[i] else -float(obj(at(i, a))), found_deg[i]
        )
        out[key] = {
            "found_deg": float(found_deg[i]),
            "sigma_deg": float(sigma) if np.isfinite(sigma) else None,  # None: a flat likelihood
            "kept": bool(i not in dropped and found_deg[i] != 0.0),  # zero found: none proven
        }
    return len(obj.passes) - made, out


def correlation_inflation(loglik) -> float:
    """The factor on an aid's white sigma that makes it stand for errors correlated in time,
    identified by the predictive likelihood ``loglik`` (``d`` [decades] -> the log-likelihood of
    the updates the aid's errors do not enter with the aid's sigmas times ``10**d``):
    :func:`gnssacc.prepare.aid_inflation.correlation_inflation`, which says why the aid's own
    innovations cannot tell it."""
    return aid_inflation.correlation_inflation(loglik)[0]


def tune_gauss_markov(
    run, cfg: RunConfig, stationary=None, quality=None, init=None, *, filter_pass: FilterPass
) -> tuple[RunConfig, dict]:
    """Fit the Gauss-Markov fix-error model alone, the IMU noise of ``cfg`` held (the ``-gm``
    methods
    on a run where :func:`tune` kept white fixes).

    The free keys of :data:`GM_PARAMETERS` (not in ``cfg.explicit``) are searched by maximum
    likelihood of one EKF pass's position and zero-rate innovations, from the start of step 3 of
    the module docstring: the stated sigmas as the correlated part, a fifth of them as the white
    part.

    Parameters
    ----------
    run : RecordedRun
        As the estimators read it (the fixes' sigmas as stated; ``cfg``'s ``gnss.sigma_scale``
        is their noise model).
    cfg : RunConfig
    stationary, quality, init, filter_pass
        As for :func:`tune`.

    Returns
    -------
    cfg : RunConfig
        With ``gnss.gm_sigma_m``, ``gnss.gm_tau_s`` and ``gnss.sigma_scale`` (relative to the
        fixes as read, as :func:`tune` gives it) as fitted.
    info : dict
        ``loglik_gain`` over the white model, ``n_evaluations``, ``seconds``, ``run_scale`` (the
        white part of the fitted model relative to ``cfg``'s: the new ``gnss.sigma_scale`` over
        the old).

    Raises
    ------
    InputError
        ``gnss.gm_sigma_m`` is set explicitly (to zero: the user asked for white fixes).
    """
    t0 = time.perf_counter()
    if ("gnss", "gm_sigma_m") in cfg.explicit:
        raise InputError(
            "gnss.gm_sigma_m", "is set to 0 (white fixes); a -gm method needs it > 0 or unset"
        )
    free_scale = ("gnss", "sigma_scale") not in cfg.explicit
    fixes = GnssModel.from_config(cfg).fixes(run.gnss)  # the fixes' noise under cfg
    # A free scale is searched relative to that noise: on the fixes with it, from 1.
    searched, base = (
        (
            run.with_gnss(fixes),
            cfg.with_values({"gnss": {"sigma_scale": 1.0}}, "sigma scale of the run"),
        )
        if free_scale
        else (run, cfg)
    )
    params = [p for p in GM_PARAMETERS if p not in cfg.explicit]
    start = {
        ("gnss", "sigma_scale"): np.atleast_1d(0.2),
        ("gnss", "gm_sigma_m"): np.median(fixes.sigma_ned, axis=0),
        ("gnss", "gm_tau_s"): np.atleast_1d(cfg.gnss_gm_tau.mean()),
    }
    start = {p: start[p] for p in params}
    kinds = ("pos", "zaru")
    obj = _Objective(
        searched, base, params, start, stationary, quality, init, "ekf", kinds, filter_pass
    )
    theta, _, n_eval = ml_search(
        obj,
        len(params),
        int(cfg["tune"]["max_evaluations"]),
        _prior_widths(cfg, params, {}),
        lower=_lower_bounds(params, {}),
    )
    white_stats = run_white_stats(run, cfg, stationary, quality, init, filter_pass=filter_pass)
    gain = _loglik(obj.stats[tuple(np.round(theta, 12))], kinds) - _loglik(white_stats, kinds)
    fitted = obj.config(theta)
    rel = float(fitted["gnss"]["sigma_scale"]) if free_scale else 1.0
    out = (
        fitted.with_values(
            {"gnss": {"sigma_scale": rel * float(cfg["gnss"]["sigma_scale"])}}, "tuned"
        )
        if free_scale
        else fitted
    )
    return out, {
        "loglik_gain": float(gain),
        "n_evaluations": n_eval + 1,
        "run_scale": rel,
        "seconds": time.perf_counter() - t0,
    }


def refined_whole(
    run,
    cfg: RunConfig,
    key: tuple,
    start: float,
    offsets,
    stationary=None,
    quality=None,
    init=None,
    *,
    init_scale: float,
    filter_pass: FilterPass,
    at_rest: dict | None = None,
) -> tuple[float, int, dict]:
    """One noise parameter ``key`` of ``cfg`` (the others held) by a short line search over the
    whole run: the objective of step 2 of the module docstring (the EKF's innovation
    log-likelihood, the ground vehicle's aids off, plus the log-normal prior around the tuner's
    starting value ``start``) at ``cfg``'s value times ``10**d`` for each ``d`` in ``offsets``
    [decades] (the passes side by side), then the vertex of the parabola through them (within
    their span) or, where they show no maximum, the best of them.

    Parameters
    ----------
    run, cfg, stationary, quality, init
        As :func:`tune` takes them; ``cfg`` the tuned configuration (``key`` at the value the
        line starts from).
    key : tuple
        ``(section, key)``, a positive scalar parameter of :data:`PARAMETERS`.
    start : float
        The tuner's starting value of ``key`` (the centre of its prior).
    offsets : sequence of float
        Offsets [decades] from ``cfg``'s value (three or more, for a parabola).
    init_scale : float
        ``gnss.sigma_scale`` the start ``init`` was made with.
    filter_pass : FilterPass
    at_rest : dict, optional
        What the stationary stretches measured (:attr:`TuneResult.from_stationary`): a density
        measured there has the tighter prior and its floor (:data:`REST_FLOOR_DECADES`), as in
        the search; the points below the floor, or more than two decades from ``start``, are
        moved to it.

    Returns
    -------
    value : float
        The refined value (configuration units).
    passes : int
    profile : dict
        ``offsets`` and the objective at each (the negative log-likelihood plus the prior, less
        its smallest), and the chosen offset ``d`` [decades].
    """
    _, measured = measurement_stage(run, cfg)
    kinds = ("pos", "zaru") + measured
    kinds += ("acc",) if cfg["tune"]["likelihood"] == "position+accel" else ()
    value = float(cfg[key[0]][key[1]])
    obj = _Objective(
        run,
        without_aids(cfg),
        [key],
        {key: np.atleast_1d(value)},
        stationary,
        quality,
        init,
        "ekf-acc" if "acc" in kinds else "ekf",
        kinds,
        filter_pass,
    )
    obj.init_scale = init_scale
    info = at_rest or {}
    width = float(_prior_widths(cfg, [key], info)[0])
    theta0 = np.log10(value / start)
    lo = float(_lower_bounds([key], info)[0])
    d = np.unique(np.clip(np.asarray(offsets, float) + theta0, lo, _BOUND_DECADES) - theta0)
    obj.ahead([np.array([x]) for x in d])
    j = np.array([obj(np.array([x])) + 0.5 * ((theta0 + x) / width) ** 2 for x in d])
    a, b, _ = np.polyfit(d, j, 2) if np.all(np.isfinite(j)) and len(d) > 2 else (0, 0, 0)
    best = float(d[int(np.argmin(j))])
    if a > 0.0:
        best = float(np.clip(-b / (2.0 * a), d.min(), d.max()))
    profile = {"offsets": d.tolist(), "objective": (j - np.nanmin(j)).tolist(), "d": best}
    return value * 10.0**best, len(d), profile


def run_white_stats(
    run,
    cfg: RunConfig,
    stationary=None,
    quality=None,
    init=None,
    *,
    filter_pass: FilterPass,
    method: str = "ekf",
) -> dict:
    """The innovation statistics of one (ungated) EKF pass of ``method`` with ``cfg`` as it is on
    ``run`` (already scaled)."""
    return filter_pass(
        run,
        ungated(cfg),
        method,
        init=init,
        stationary=stationary,
        quality=quality,
        output_times=np.zeros(0),
        cov_every=int(cfg["tune"]["cov_every"]),
    ).stats
