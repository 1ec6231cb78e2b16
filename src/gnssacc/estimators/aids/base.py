r"""What an aid is: one measurement, the EKF's update and the smoother's factors of it.

An aid module (:mod:`gnssacc.estimators.aids`) says, for a run and the estimator's settings:

* its epochs and, for the EKF, its linearised measurements there (:class:`Measurement`:
  ``dz, H, R``, gate) with the rule that decides whether one is applied (:class:`EkfAid`);
* for the smoother, where it wants nodes and the factors it puts on them (:class:`SmootherAid`);
* the states it adds (:class:`gnssacc.estimators.layout.MarkovBlock`), its update kinds (the
  NIS and log-likelihood it is scored by), its counters in the estimators' ``stats``, and the
  noise keys the tuner identifies (:class:`AidSpec`).

The EKF and the smoother loop over the aids they are handed and never name one.

Error convention (both estimators)
----------------------------------
The EKF's error state is estimate minus truth (:mod:`gnssacc.estimators.layout`), with
``R_nb_est = (I + [phi x]) R_nb``, ``f_est = f + b_a``, ``omega_est = omega + b_g``. Every
innovation is *predicted minus measured*, ``dz = H dx - noise``, so the closed-loop correction
subtracts ``K dz`` (:func:`gnssacc.estimators.state.correct`). A smoother factor's error is
predicted minus measured on GTSAM's variables (right perturbations of the pose, NED velocity,
bias vector, the Gauss-Markov states as vectors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Iterator

import numpy as np

from ...core.distributions import chi2_isf
from ..layout import MarkovBlock

if TYPE_CHECKING:
    from ..state import FilterState

#: Tail probability of the chi-square bound an innovation's NIS is counted beyond (one in 1000).
TAIL_P = 1e-3
_TAIL_BOUNDS: dict = {}


def tail_bound(dof: int) -> float:
    """The NIS exceeded with probability :data:`TAIL_P` by Gaussian innovations of ``dof``."""
    if dof not in _TAIL_BOUNDS:
        _TAIL_BOUNDS[dof] = chi2_isf(TAIL_P, dof)
    return _TAIL_BOUNDS[dof]


@dataclass
class Measurement:
    """One linearised measurement at the current state.

    Attributes
    ----------
    kind : str
        Its update kind (an aid's :attr:`AidSpec.kinds`).
    dz : ndarray, shape (m,)
        Innovation, predicted minus measured.
    H : ndarray, shape (m, n)
        Jacobian of the prediction w.r.t. the error state (n states).
    R : ndarray, shape (m, m)
        Measurement noise covariance.
    gate : float
        Reject the update when its normalised innovation squared exceeds this (0: never).
    """

    kind: str
    dz: np.ndarray
    H: np.ndarray
    R: np.ndarray
    gate: float = 0.0


def zero_jacobian(s: "FilterState", m: int) -> np.ndarray:
    """A zero ``H`` of ``m`` rows with as many columns as the filter has states."""
    return np.zeros((m, s.P.shape[0]))


def row_sigma(P: np.ndarray, h: np.ndarray) -> float:
    """1-sigma of ``h dx`` for the error covariance ``P``."""
    return math.sqrt(max(float(h @ P @ h), 0.0))


class EkfAid:
    """One aid's side of an EKF pass (subclasses set the attributes and :meth:`models`).

    Attributes
    ----------
    name : str
        Its spec's name (set by :func:`gnssacc.estimators.aids.ekf_aids`).
    order : int
        Its place among the events at equal times (lower first; the outputs come last).
    epoch : str
        The kind of epoch an :class:`gnssacc.estimators.ekf.EkfObserver` is told (updates of
        aids with the same ``epoch`` at the same time and index are one epoch to it).
    t : ndarray (K,)
        Its epochs [s], in time order.
    states : tuple of MarkovBlock
        The states it adds to the filter.
    """

    name: str = ""
    order: int = 0
    epoch: str = ""
    t: np.ndarray = np.zeros(0)
    states: tuple[MarkovBlock, ...] = ()

    def see(self, j: int) -> None:
        """Epoch ``j`` comes (every epoch up to the pass's end in time order, those before the
        filter starts too): what the aid keeps across epochs, whatever the state."""

    def models(self, s: "FilterState", j: int) -> list[Measurement]:
        """Its measurements at epoch ``j`` linearised at ``s``, whatever its decision rule."""
        raise NotImplementedError

    def updates(self, s: "FilterState", j: int, stats: dict) -> Iterator[tuple[Measurement, bool]]:
        """Its updates at epoch ``j``, each built at the state the previous one left, with whether
        it is applied (``False``: evaluated for an observer only); what it decides not to use it
        counts in ``stats``. Default: every model, applied."""
        for m in self.models(s, j):
            yield m, True

    def final_stats(self, s: "FilterState", stats: dict) -> None:
        """What it adds to the pass's ``stats`` at the end (``s``: the final state)."""

    def compiled(self) -> tuple[str, tuple] | None:
        """Its step in the EKF's compiled event loop (:mod:`gnssacc.estimators.event_loop`), when
        it has one: the step's name and the arrays it takes there; ``None``: its epochs are the
        Python loop's. An aid with a compiled step keeps nothing across epochs (:meth:`see`)."""
        return None


@dataclass
class NodePrediction:
    """What the smoother predicts for a node before its factors are added.

    Attributes
    ----------
    R_nb : ndarray (3, 3)
        Predicted attitude.
    v_n : ndarray (3,)
        Predicted NED velocity [m/s].
    bias : gtsam.imuBias.ConstantBias
        The bias the node was predicted with (the previous node's estimate).
    markov : dict
        The previous node's Gauss-Markov states, by block name.
    start : bool
        The first node: the prediction is the start itself.
    velocity_cov : callable
        ``() -> (3, 3)`` covariance of the predicted velocity [m^2/s^2] (computed when asked).
    """

    R_nb: np.ndarray
    v_n: np.ndarray
    bias: Any
    markov: dict
    start: bool
    velocity_cov: Callable[[], np.ndarray] = field(repr=False, default=lambda: np.zeros((3, 3)))


def nearest(t: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the entry of sorted ``t`` nearest each time of ``at``."""
    i = np.clip(np.searchsorted(t, at), 1, len(t) - 1) if len(t) > 1 else np.zeros(len(at), int)
    return np.where((i > 0) & (np.abs(t[i - 1] - at) < np.abs(t[i] - at)), i - 1, i)


def nearest_nodes(times: np.ndarray, epochs: np.ndarray, interval_s: float) -> np.ndarray:
    """The nodes given an epoch each: every epoch's nearest node within half ``interval_s`` [s],
    each node once, the start node (index 0, which has no prediction) left out."""
    if len(epochs) == 0 or len(times) < 2:
        return np.zeros(0, int)
    i = nearest(times, epochs)
    near = np.abs(times[i] - epochs) <= 0.5 * interval_s + 1e-9
    return np.unique(i[near & (i > 0)])


class SmootherAid:
    """One aid's side of a smoother run (subclasses override what they use).

    Attributes
    ----------
    name : str
        Its spec's name (set by :func:`gnssacc.estimators.aids.smoother_aids`).
    order : int
        The order its factors are added at a node (lower first).
    states : tuple of MarkovBlock
        The variables it adds to every node.
    bandwidth : int
        How many nodes apart its factors reach (1: consecutive nodes at most).
    """

    name: str = ""
    order: int = 0
    states: tuple[MarkovBlock, ...] = ()
    bandwidth: int = 1

    def node_epochs(self, existing: np.ndarray) -> np.ndarray:
        """The epochs [s] it wants nodes at, given those asked for by the aids before it."""
        return np.zeros(0)

    def attach(self, ctx) -> None:
        """The nodes are known (``ctx``: the smoother loop, :class:`gnssacc.estimators.smoother.
        NodeContext`): map the aid's epochs to them."""

    def interval(self, graph, ctx, i: int) -> None:
        """Factors on the interval before node ``i`` (added before node ``i``'s own)."""

    def node(self, graph, ctx, i: int, t: float, pred: NodePrediction) -> None:
        """Factors at node ``i`` (time ``t`` [s]) given its prediction ``pred``."""

    def score(self, ctx, rec) -> dict:
        """Its consistency figures for one estimate (``rec``: the smoother's record of it)."""
        return {}

    def final_stats(self, ctx, stats: dict) -> None:
        """What it adds to the run's ``stats`` at the end."""


@dataclass(frozen=True)
class AidSpec:
    """A registered aid (:data:`gnssacc.estimators.aids.REGISTRY`).

    Attributes
    ----------
    name : str
        Its id.
    kinds : tuple of str
        Its update kinds, in the order they are reported (EKF ``stats``: ``n_<kind>_updates``,
        ``nis_<kind>_mean``, ``loglik_<kind>``, ...; the tuner's likelihood terms).
    ekf : callable
        ``(EkfContext) -> EkfAid or None`` (``None``: not in this pass).
    smoother : callable
        ``(SmootherContext) -> SmootherAid or None``.
    counts, smoother_counts : dict
        Its counters in an EKF pass's and a smoother run's ``stats``, at their zero (present
        whether or not it ran).
    noise_keys : tuple of (section, key)
        The configuration keys of its noise the tuner identifies.
    stage : {None, "imu", "vehicle"}
        When the tuner identifies them: with the IMU noise (``imu``), or after it, the IMU and
        GNSS noise held (``vehicle``: the ground vehicle's own aids; the tuner's and the yaw
        bank's passes of the IMU and GNSS model run without them, :attr:`enabled_key` off).
    enabled_key : (section, key) or None
        The key that turns it off.
    floored_keys : tuple of (section, key)
        Its sigmas the tuner keeps at or above the value of :attr:`floor_key`.
    floor_key : (section, key) or None
    inflated_keys : tuple of (section, key)
        Its sigmas the tuner inflates for errors correlated in time (by the lag-1 autocorrelation
        of its update kind's whitened innovations).
    additive_keys : dict
        Its keys searched additively (angles near zero): ``(section, key) -> step`` per unit of
        the search.
    in_use : callable
        ``(run, cfg) -> bool``: whether a pass on ``run`` with ``cfg`` has it (when enabled).
    """

    name: str
    kinds: tuple[str, ...]
    ekf: Callable
    smoother: Callable
    counts: dict = field(default_factory=dict)
    smoother_counts: dict = field(default_factory=dict)
    noise_keys: tuple = ()
    stage: str | None = None
    enabled_key: tuple | None = None
    floored_keys: tuple = ()
    floor_key: tuple | None = None
    inflated_keys: tuple = ()
    additive_keys: dict = field(default_factory=dict)
    in_use: Callable = lambda run, cfg: True


@dataclass
class EkfContext:
    """What an EKF aid is built from: the run (fixes as read), the filter's settings, the start,
    the stationary spans (or ``None``), the method's variant of the aids (the acceleration form
    it applies, :data:`gnssacc.estimators.aids.EKF_METHODS`; ``None``: none), whether an
    observer watches (then a form not applied is evaluated for it), the inflation segments
    of the suspect IMU spans, and where the pass stops (``t_stop`` [s]; ``None``: at the run's
    end)."""

    run: Any
    settings: Any
    init: Any
    stationary: Any
    variant: str | None
    observed: bool
    segments: Any
    t_stop: float | None = None

    @property
    def t0(self) -> float:
        return float(self.init.t)


@dataclass
class SmootherContext:
    """What a smoother aid is built from: the run (fixes as read), the smoother's settings, the
    start, the stationary spans (or ``None``), the method's variant of the aids (the acceleration
    form, :data:`gnssacc.estimators.aids.SMOOTHER_METHODS`; ``None``: none) and the run's
    ``stats`` (an aid adds its counters to them)."""

    run: Any
    settings: Any
    init: Any
    stationary: Any
    variant: str | None
    stats: dict
