r"""A fixed-lag smoother on iSAM2 whose Bayes tree stays in time order, newest node at the root.

GTSAM's ``IncrementalFixedLagSmoother`` orders the variables it re-eliminates in two groups:
those to marginalise, then all others in whatever order COLAMD picks. On a chain of navigation
nodes COLAMD takes the chain's ends first, so the newest node often lands deep in the Bayes
tree, and the next update, which attaches the next node to it, re-eliminates the whole path from
it to the root. Measured on a 10 Hz recording with a 10 s lag and Gauss-Markov GNSS-error
states: 225 of the window's ~390 variables re-eliminated at every update.

:class:`FixedLagISAM2` keeps the elimination order chronological by node (a *node* here: the
variables stamped with one time), so the Bayes tree is a path from the oldest node (a leaf) to
the newest (the root):

* an ordinary update re-eliminates the nodes its new factors touch and those above them; their
  ordering groups follow time, counted from the oldest node touched (CCOLAMD's groups must not
  outnumber the variables re-eliminated, so a group per node of the whole window is not
  possible here);
* an update in which iSAM2 may relinearise (every ``relinearizeSkip``-th, when a variable's
  update reaches the threshold) re-eliminates the whole window, in time order: iSAM2 would
  re-eliminate the paths from the relinearised variables and their factors' other variables to
  the root anyway (far back: the factors reach further than the variables), in COLAMD's order;
* should iSAM2 re-eliminate more old variables than had groups of their own (a Bayes-tree clique
  holding several older nodes), the next update re-eliminates the whole window in time order and
  the marginalisation waits for it (never seen on KITTI, comma2k19 or the simulated runs);
* the variables older than the lag are marginalised after every update, as by
  ``IncrementalFixedLagSmoother``: in a path ordered in time they are leaves, as iSAM2's
  ``marginalizeLeaves`` requires (GTSAM's release build does not check it; the wrapper does not
  expose the Bayes tree to check it here);
* with ``guard`` (the smoother guards its bias variables), an update whose leaving nodes hold a
  guarded variable with a pending update at the threshold relinearises, whatever the turn: a
  marginal factor keeps its linearisation point for good (:meth:`FixedLagISAM2._stale_leaving`).

Factors, linearisation points and marginalisation are those of ``IncrementalFixedLagSmoother``,
and so is relinearisation without ``guard``; only the elimination order differs, so the estimates
agree up to iSAM2's own approximation, its wildfire threshold on solution updates (1e-9 m on KITTI
and on the simulated runs of the tests, with every kind of factor; 2.6 mm on the 10 Hz comma2k19
drive).
"""

from __future__ import annotations

from collections import deque

import gtsam
import numpy as np


class FixedLagISAM2:
    """Fixed-lag smoothing over ``lag`` [s] with iSAM2 (``params``: ``gtsam.ISAM2Params``;
    ``relinearize_threshold``: the threshold set in it). Every node (time stamp) must hold at
    least two variables (the ordering groups' bound, :func:`_older_groups`).

    Offers the part of ``IncrementalFixedLagSmoother``'s interface
    :mod:`gnssacc.estimators.smoother` uses.
    """

    def __init__(
        self, lag: float, params: gtsam.ISAM2Params, relinearize_threshold: float, guard: str = ""
    ):
        self.lag = float(lag)
        #: Symbol characters of the variables relinearised before they are marginalised when their
        #: pending update reaches the threshold (:meth:`_stale_leaving`).
        self.guard = {ord(c) for c in guard}
        params.enableAdaptiveReorder = False  # a batch reorder would not keep the time order
        self.isam = gtsam.ISAM2(params)
        self._skip = max(int(params.relinearizeSkip), 1) if params.enableRelinearization else 0
        self._threshold = float(relinearize_threshold)
        self._count = 0  # updates so far (iSAM2's own count)
        self._nodes: deque = deque()  # (t, [keys]) per node, oldest first
        self._result: gtsam.ISAM2Result | None = None
        self._unordered = False  # the last update may have broken the time order
        self.unordered_updates = 0  # how often (diagnostics)

    def update(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, stamps) -> None:
        """Add ``graph``'s factors and the new variables ``values`` with their time stamps
        ``stamps`` (pairs ``(key, t)`` [s], not earlier than the newest so far), then
        marginalise the variables older than the newest stamp less the lag."""
        new = _by_time(stamps)
        if self._nodes and new and new[0][0] < self._nodes[-1][0]:
            raise ValueError("time stamps must not go back in time")
        self._count += 1
        nodes, touched = list(self._nodes), set(graph.keyVector())
        up, lo = gtsam.ISAM2UpdateParams(), 0  # lo: the oldest node with a group of its own
        if nodes:  # (the first update: iSAM2 puts new variables last)
            first = _oldest_touched(nodes, touched)
            lo = max(first - _older_groups(nodes, first, new, touched), 0)
            relinearize = self._relinearizes() or self._stale_leaving(
                (new or nodes)[-1][0] - self.lag
            )
            up.force_relinearize = relinearize
            if self._unordered or relinearize:
                lo = 0  # all in time order (see the module notes)
                up.extraReelimKeys = _key_list(nodes)
            up.constrainedKeys = _groups(nodes + new, lo)
        self._result = self.isam.update(graph, values, up)
        # iSAM2 counts the re-eliminated variables of the old tree plus the new factors' variables.
        reordered = self._result.getVariablesReeliminated() - len(touched)
        ordered = sum(len(keys) for _, keys in nodes[lo:])
        self._nodes.extend(new)
        # More old variables re-eliminated than had groups in time order: older nodes shared
        # group 0 (a clique held several). Re-eliminate all in order in the next update and
        # marginalise after it (an update of its own would shift iSAM2's relinearisation turns).
        self._unordered = reordered > ordered
        self.unordered_updates += self._unordered
        if not self._unordered:
            self._marginalize(self._nodes[-1][0] - self.lag)

    def _relinearizes(self) -> bool:
        """Whether iSAM2 may relinearise in this update: its relinearisation turn, and a
        variable's pending update at the threshold (a superset of what it relinearises)."""
        if not self._skip or self._count % self._skip:
            return False
        delta = self.isam.getDelta().vector()
        return delta.size > 0 and float(np.max(np.abs(delta))) >= self._threshold

    def _stale_leaving(self, t_cut: float) -> bool:
        """Whether a guarded variable (:attr:`guard`) of a node that leaves the window in this
        update (stamped before ``t_cut`` [s]) has a pending update at the threshold.

        Marginalising it would freeze its factors' linearisation at a point that far off, for
        good: IMU factors hold their preintegration's bias correction to first order about the
        bias's linearisation point (docs/estimators.md: what it cost without this guard).
        """
        if not self.guard or not self._skip or not self._nodes or self._nodes[0][0] >= t_cut:
            return False
        keys = [k for t, ks in self._nodes if t < t_cut for k in ks if k >> 56 in self.guard]
        if not keys:
            return False
        delta = self.isam.getDelta()
        return any(float(np.max(np.abs(delta.at(k)))) >= self._threshold for k in keys)

    def _marginalize(self, t_cut: float) -> None:
        """Marginalise the nodes stamped before ``t_cut`` [s] (leaves of the Bayes tree)."""
        leaves = gtsam.KeyList()
        while self._nodes and self._nodes[0][0] < t_cut:
            for key in self._nodes.popleft()[1]:
                leaves.push_back(key)
        if leaves.size():
            self.isam.marginalizeLeaves(leaves)

    def getISAM2(self) -> gtsam.ISAM2:  # noqa: N802 (gtsam's names)
        return self.isam

    def getISAM2Result(self):  # noqa: N802
        """The last update's ``gtsam.ISAM2Result``."""
        return self._result

    def getFactors(self) -> gtsam.NonlinearFactorGraph:  # noqa: N802
        return self.isam.getFactorsUnsafe()

    def getLinearizationPoint(self) -> gtsam.Values:  # noqa: N802
        return self.isam.getLinearizationPoint()

    def calculateEstimatePose3(self, key: int) -> gtsam.Pose3:  # noqa: N802
        return self.isam.calculateEstimatePose3(key)

    def calculateEstimateVector(self, key: int) -> np.ndarray:  # noqa: N802
        return self.isam.calculateEstimateVector(key)

    def calculateEstimateConstantBias(self, key: int):  # noqa: N802
        return self.isam.calculateEstimateConstantBias(key)


class GtsamFixedLag:
    """GTSAM's own ``IncrementalFixedLagSmoother`` behind :class:`FixedLagISAM2`'s interface: the
    reference the tests and ``bench/bench_fixed_lag.py`` compare with."""

    def __init__(
        self, lag: float, params: gtsam.ISAM2Params, relinearize_threshold: float, guard: str = ""
    ):
        # ``guard`` is accepted and ignored: GTSAM's smoother relinearises on its turns only.
        self.smoother = gtsam.IncrementalFixedLagSmoother(float(lag), params)

    def update(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, stamps) -> None:
        ts = gtsam.FixedLagSmootherKeyTimestampMap()
        for key, t in stamps:
            ts.insert((key, float(t)))
        self.smoother.update(graph, values, ts)

    def __getattr__(self, name: str):
        return getattr(self.smoother, name)


def _by_time(stamps) -> list:
    """``(t, [keys])`` per distinct time stamp of ``stamps`` (pairs ``(key, t)``), in time order."""
    nodes: dict = {}
    for key, t in stamps:
        nodes.setdefault(float(t), []).append(key)
    return sorted(nodes.items())


def _oldest_touched(nodes: list, touched: set) -> int:
    """Index in ``nodes`` (``(t, [keys])``, oldest first) of the oldest node holding a key of
    ``touched`` (the new factors' keys); ``len(nodes)`` when they touch only new variables."""
    for j, (_, keys) in enumerate(nodes):
        if touched.intersection(keys):
            return j
    return len(nodes)


def _groups(nodes: list, lo: int) -> gtsam.KeyGroupMap:
    """Ordering groups in time order from node ``lo`` of ``nodes`` on (older nodes: 0). Every
    variable is listed: iSAM2 puts unlisted ones in group 0."""
    groups = gtsam.KeyGroupMap()
    keys = [key for _, ks in nodes for key in ks]
    numbers = [max(0, j - lo) for j, (_, ks) in enumerate(nodes) for _ in ks]
    deque(map(groups.insert2, keys, numbers), maxlen=0)  # (no Python loop body per key)
    return groups


def _key_list(nodes: list) -> gtsam.KeyList:
    """The variables of ``nodes``."""
    out = gtsam.KeyList()
    for _, keys in nodes:
        for key in keys:
            out.push_back(key)
    return out


def _older_groups(nodes: list, first: int, new: list, touched: set) -> int:
    """How many nodes older than node ``first`` (the oldest an update's factors touch; its keys
    among ``touched``) can have groups of their own: CCOLAMD takes no group number above the
    number of variables it orders (a larger one corrupts memory), and iSAM2 re-eliminates at
    least the touched variables of node ``first``, every variable of the later nodes (above them
    in the time-ordered path) and the new ones. Not all of node ``first``'s: those eliminated
    before its touched ones may sit in cliques below them (a window-consistent acceleration
    factor touches only the poses of its oldest node)."""
    n_vars = sum(len(keys) for _, keys in nodes[first + 1 :] + new)
    if first < len(nodes):
        n_vars += len(touched.intersection(nodes[first][1]))
    return max(n_vars - (len(nodes) - first + len(new)), 0)
