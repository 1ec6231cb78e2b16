"""The estimator's verdict on a proposed correction: the data as given against the data as corrected.

One mechanism for every input check (units, clocks, coordinates, mounting, a given start): the
EKF (position and stationary updates, the configured noise) runs on the run as given and on the
run as corrected, each from its own start (:mod:`gnssacc.prepare.start`), and the Gaussian
log-likelihood of the position innovations is summed over the fixes both passes score (those
:data:`BURN_IN_S` after the later start, inside both IMU spans), and with it that of the GNSS
velocity innovations both passes score in the same span, when the run has velocities (the
likelihood of all the data: a correction of the velocities themselves, their frame or time tags,
is seen there first; a correction of their time tags compares the same velocities by their tags
as given). The correction is *decisive*
when it raises that log-likelihood by at least :data:`LR_MIN` and by :data:`RATE_MIN` per minute
of scored data, and the corrected pass is consistent: its position NIS per dof (and velocity NIS)
within :data:`NIS_MAX`, or no worse than the data's as given (the noise model is not tuned yet: with
centimetre fixes and a default IMU noise both can read several).

:data:`LR_MIN` = 12 is the likelihood-ratio bound of one fitted parameter at a false-alarm
probability of about 1e-6 (2 x 12 = 24 exceeds the chi-square quantile with one degree of freedom,
23.9): a clock offset or a mounting fitted to noise almost never gains that much. A discrete
alternative (a unit) fits nothing and would need less; the same bound keeps one rule. The rate
bound keeps a long recording, whose small modelling errors add up, from turning a small
difference into a verdict. When a correction changes the measurements themselves (the fixes'
coordinates), the log-likelihoods are of different numbers; the Jacobian of the reinterpretation
puts them on one footing (``log_jacobian``: the log-determinant of d(corrected)/d(given) per fix,
added for every scored fix).

A pass that cannot run (no IMU where the fixes are) has no likelihood: ``-inf``.

The position likelihood cannot see the body axes: the EKF navigates as well in the IMU's own axes
as in the vehicle's, so an upside-down or sideways IMU explains the fixes exactly as well as the
same IMU turned back. For a correction of the axes (the mounting) the evidence is the
ground-vehicle model the axes are for: the vehicle frame is nearly level (roll and pitch within
:data:`TILT_SIGMA_DEG`) and, while the vehicle rolls faster than :data:`MOVING_MPS`, moves along its
forward axis (lateral and vertical body velocity within :data:`SLIP_SIGMA_MPS`, the non-holonomic
constraint). Its Gaussian log-likelihood at every scored fix joins the innovations'
(``vehicle=True``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..core.config import RunConfig
from ..core.parallel import side_by_side
from ..core.recording import RecordedRun
from .filter_pass import FilterPass
from .start import StartPieces
from .tuning import ungated, without_aids

#: Position innovations this soon after a pass's start are not scored: the start's own errors
#: settle there [s].
BURN_IN_S = 10.0
#: Least log-likelihood gain of a decisive correction (module notes).
LR_MIN = 12.0
#: ... and per minute of scored data.
RATE_MIN = 1.0
#: Largest mean position NIS per dof of a corrected pass that may be decisive (a noise model not
#: yet tuned to the recording can be several times off; tenfold is a model that does not fit).
NIS_MAX = 10.0
#: Fewest scored fixes for a verdict.
MIN_FIXES = 12
#: The ground-vehicle model of a correction of the axes (module notes): 1-sigma of the vehicle
#: frame's roll and pitch [deg] (road grades and banking stay below 10 deg) and of its lateral and
#: vertical velocity while moving [m/s] (side slip of a car in a turn, a skid-steer vehicle's slip).
TILT_SIGMA_DEG = 15.0
SLIP_SIGMA_MPS = 0.5
MOVING_MPS = 1.0
#: A correction that gains less than this is refuted, not merely unconfirmed: the data as given
#: are as likely or more (2 nats: what an offset 2 sigma from the truth loses); nothing to warn of.
REFUTE_GAIN = 2.0


_NONE = np.zeros(0)


@dataclass(frozen=True)
class Innovations:
    """One pass's position innovations: fix times [s], log-likelihood (with the ground-vehicle
    model's when asked) and NIS per dof of each; and its GNSS velocity innovations' (``*_vel``:
    velocity time tags [s], log-likelihood, NIS per dof; empty without velocities)."""

    t: np.ndarray
    loglik: np.ndarray
    nis: np.ndarray
    t_start: float
    t_end: float
    t_vel: np.ndarray = field(default_factory=lambda: _NONE)
    loglik_vel: np.ndarray = field(default_factory=lambda: _NONE)
    nis_vel: np.ndarray = field(default_factory=lambda: _NONE)


def vehicle_loglik(sol) -> np.ndarray:
    """The ground-vehicle model's log-likelihood at each output epoch of a solution (module notes)."""
    R_bn = np.swapaxes(_dcm(sol.rpy), 1, 2)
    v_b = np.einsum("kij,kj->ki", R_bn, sol.v_n)
    moving = np.linalg.norm(sol.v_n[:, :2], axis=1) > MOVING_MPS
    tilt = np.radians(TILT_SIGMA_DEG)
    ll = -0.5 * (sol.rpy[:, 0] ** 2 + sol.rpy[:, 1] ** 2) / tilt**2
    return ll - 0.5 * moving * (v_b[:, 1] ** 2 + v_b[:, 2] ** 2) / SLIP_SIGMA_MPS**2


def _dcm(rpy: np.ndarray) -> np.ndarray:
    from ..core.rotations import euler_to_dcm

    return np.stack([euler_to_dcm(*r) for r in rpy]) if len(rpy) else np.zeros((0, 3, 3))


def innovations(
    run: RecordedRun,
    cfg: RunConfig,
    pieces: StartPieces,
    filter_pass: FilterPass,
    init=None,
    stationary: bool = True,
    vehicle: bool = False,
) -> Innovations | None:
    """The position innovations of one EKF pass from ``init`` (default ``pieces.init``) with the
    configuration's noise (gates off: a gate hides what it rejects from the likelihood), with the
    stationary updates of ``pieces`` or without; with ``vehicle`` the ground-vehicle model's
    log-likelihood is added at each fix. ``None`` when the pass cannot run."""
    init = pieces.init if init is None else init
    try:
        # The IMU and GNSS model alone: the ground-vehicle aids' noise and axes are identified only
        # after the checks (gnssacc.prepare.tuning, step 5), and a constraint with untuned axes biases
        # a verdict (KITTI's IMU is pitched 0.4 deg against the car: with the constraint, 3 of 40 KITTI
        # runs with outages measured a -0.13..-0.16 s clock offset, decisively, and were refused).
        sol = filter_pass(
            run,
            ungated(without_aids(cfg)),
            "ekf",
            init=init,
            quality=pieces.quality,
            stationary=pieces.stationary if stationary else None,
            output_times=run.gnss.t if vehicle else np.zeros(0),
            record_innovations=True,
        )
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        return None
    st = sol.stats
    t, ll = np.asarray(st["nis_pos_t"], float), np.asarray(st["loglik_pos_series"], float)
    if vehicle and len(sol.t):
        ll = ll + np.interp(t, sol.t, vehicle_loglik(sol))  # outputs at the fixes' epochs
    return Innovations(
        t,
        ll,
        np.asarray(st["nis_pos"], float),
        float(init.t),
        float(run.t_end),
        np.asarray(st.get("nis_vel_t", _NONE), float),
        np.asarray(st.get("loglik_vel_series", _NONE), float),
        np.asarray(st.get("nis_vel", _NONE), float),
    )


@dataclass(frozen=True)
class Verdict:
    """The estimator's verdict on one correction.

    Attributes
    ----------
    gain : float
        Log-likelihood as corrected minus as given over the scored fixes (``inf`` when the data as
        given cannot be estimated, ``-inf`` when the corrected cannot).
    n_fixes : int
    minutes : float
        Span of the scored fixes [min].
    nis : float or None
        Mean position NIS per dof of the corrected pass over them.
    nis_given : float or None
        The same of the pass on the data as given.
    loglik_given : float or None
        The log-likelihood of the data as given over the scored fixes (the corrected's is it plus
        ``gain``).
    n_vel : int
        GNSS velocities scored beside the fixes (their log-likelihood is in ``gain`` and
        ``loglik_given``; 0 without velocities).
    nis_vel, nis_vel_given : float or None
        Mean velocity NIS per dof of the corrected pass and of the pass as given over them.
    """

    gain: float
    n_fixes: int
    minutes: float
    nis: float | None
    vehicle: bool = False
    nis_given: float | None = None
    loglik_given: float | None = None
    n_vel: int = 0
    nis_vel: float | None = None
    nis_vel_given: float | None = None

    @property
    def needed(self) -> float:
        """The gain a decisive verdict needs here."""
        return max(LR_MIN, RATE_MIN * self.minutes)

    @property
    def decisive(self) -> bool:
        consistent = _consistent(self.nis, self.nis_given) and _consistent(
            self.nis_vel, self.nis_vel_given
        )
        return self.n_fixes >= MIN_FIXES and self.gain >= self.needed and consistent

    @property
    def refuted(self) -> bool:
        """The data as given are as likely as corrected, or more (:data:`REFUTE_GAIN`)."""
        return self.n_fixes >= MIN_FIXES and self.gain < REFUTE_GAIN

    def text(self) -> str:
        """The evidence, for messages: e.g. "log-likelihood +215 as corrected over 190 fixes
        (+68 per minute; decisive needs +12)"."""
        if self.n_fixes < MIN_FIXES:
            return f"too few fixes to tell ({self.n_fixes} scored, {MIN_FIXES} needed)"
        if not math.isfinite(self.gain):
            side = "as given" if self.gain > 0 else "as corrected"
            return f"the data {side} cannot be estimated at all ({self.n_fixes} fixes)"
        rate = self.gain / self.minutes if self.minutes > 0 else float("nan")
        nis = f", NIS {self.nis:.2f} as corrected" if self.nis is not None else ""
        what = "position" + (" and velocity" if self.n_vel else "")
        what += " and ground-vehicle-model" if self.vehicle else ""
        fixes = f"{self.n_fixes} fixes" + (f" and {self.n_vel} velocities" if self.n_vel else "")
        both = (
            f"{self.loglik_given:.0f} as given, {self.loglik_given + self.gain:.0f} as corrected: "
            if self.loglik_given is not None
            else ""
        )
        return (
            f"EKF {what} log-likelihood {both}{self.gain:+.0f} over {fixes} "
            f"({rate:+.1f} per minute{nis}; decisive needs {self.needed:+.0f})"
        )

    def to_dict(self) -> dict:
        return {
            "loglik_gain": self.gain if math.isfinite(self.gain) else str(self.gain),
            "n_fixes": self.n_fixes,
            "minutes": round(self.minutes, 3),
            "nis_corrected": self.nis,
            "nis_given": self.nis_given,
            "decisive": self.decisive,
            "refuted": self.refuted,
            "needed": self.needed,
            "loglik_given": self.loglik_given,
            "n_vel": self.n_vel,
            "nis_vel_corrected": self.nis_vel,
            "nis_vel_given": self.nis_vel_given,
        }


def _consistent(nis: float | None, nis_given: float | None) -> bool:
    """A corrected pass's mean NIS per dof within :data:`NIS_MAX`, or no worse than as given."""
    return nis is None or nis <= NIS_MAX or (nis_given is not None and nis <= nis_given)


def compare(
    given: Innovations | None,
    corrected: Innovations | None,
    log_jacobian: float = 0.0,
    t_from: float | None = None,
    t_to: float | None = None,
    vehicle: bool = False,
    vel_shift: float = 0.0,
) -> Verdict:
    """The verdict over the fixes both passes score (module notes), and over the GNSS velocities
    both score; ``t_from``, ``t_to``: score no earlier, no later [s]; ``vel_shift``: the
    corrected velocities' time tags minus the given's [s] (a correction of their time tags; the
    same measurements are compared)."""
    if corrected is None or given is None:
        ref = corrected if given is None else given
        n = 0 if ref is None else len(ref.t)
        gain = -math.inf if corrected is None else math.inf
        return Verdict(gain if ref is not None else 0.0, n, 0.0, None)
    t_lo = max(given.t_start, corrected.t_start) + BURN_IN_S
    if t_from is not None:
        t_lo = max(t_lo, t_from)
    t_hi = min(given.t_end, corrected.t_end, math.inf if t_to is None else t_to)
    scored_g = given.t[(given.t >= t_lo) & (given.t <= t_hi)]
    scored_c = corrected.t[(corrected.t >= t_lo) & (corrected.t <= t_hi)]
    common = np.intersect1d(scored_g, scored_c)
    if len(common) == 0:  # as given, the fixes meet no IMU data: nothing to estimate
        n = len(scored_c) if len(scored_g) == 0 else 0
        return Verdict(math.inf if n else 0.0, n, 0.0, None, vehicle)
    ig, ic = np.isin(given.t, common), np.isin(corrected.t, common)
    vg, vc = _common_velocities(given, corrected, t_lo, t_hi, vel_shift)
    ll_given = float(given.loglik[ig].sum()) + float(given.loglik_vel[vg].sum())
    ll_corrected = float(corrected.loglik[ic].sum()) + float(corrected.loglik_vel[vc].sum())
    gain = ll_corrected - ll_given + float(log_jacobian) * len(common)
    n_vel = int(vg.sum())
    return Verdict(
        gain,
        len(common),
        float(common[-1] - common[0]) / 60.0,
        float(np.mean(corrected.nis[ic])),
        vehicle,
        float(np.mean(given.nis[ig])),
        ll_given,
        n_vel,
        float(np.mean(corrected.nis_vel[vc])) if n_vel else None,
        float(np.mean(given.nis_vel[vg])) if n_vel else None,
    )


def _common_velocities(
    given: Innovations, corrected: Innovations, t_lo: float, t_hi: float, shift: float
) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the velocity innovations both passes score within ``[t_lo, t_hi]`` (the given's
    time tags; the corrected's less ``shift``), matched to the microsecond."""
    tg = np.round(given.t_vel * 1e6)
    tc = np.round((corrected.t_vel - shift) * 1e6)
    both = np.intersect1d(tg, tc)
    both = both[(both >= np.round(t_lo * 1e6)) & (both <= np.round(t_hi * 1e6))]
    both = both[(both + np.round(shift * 1e6) >= np.round(t_lo * 1e6))]
    both = both[(both + np.round(shift * 1e6) <= np.round(t_hi * 1e6))]
    return np.isin(tg, both), np.isin(tc, both)


def judge(
    given: RecordedRun,
    corrected: RecordedRun,
    cfg: RunConfig,
    given_pieces: StartPieces,
    corrected_pieces: StartPieces,
    filter_pass: FilterPass,
    log_jacobian: float = 0.0,
    vehicle: bool = False,
    vel_shift: float = 0.0,
) -> Verdict:
    """The verdict on ``corrected`` against ``given``, each from its own start (module notes;
    ``vehicle``: with the ground-vehicle model, for a correction of the axes; ``vel_shift``:
    :func:`compare`)."""
    pairs = ((given, given_pieces), (corrected, corrected_pieces))
    # the two passes side by side (forked: each process holds both runs; only the innovations
    # travel), the same as one after the other
    as_given, as_corrected = side_by_side(
        lambda k: innovations(pairs[k][0], cfg, pairs[k][1], filter_pass, vehicle=vehicle),
        [(0,), (1,)],
    )
    return compare(as_given, as_corrected, log_jacobian, vehicle=vehicle, vel_shift=vel_shift)
