"""The estimators' state layouts, named once: the EKF's error state and the smoother's node.

EKF error state (estimate minus truth)
--------------------------------------
The paper's fifteen navigation states first (:mod:`gnssacc.core.states`: position, velocity,
attitude, accelerometer bias, gyro bias; ``POS``, ``VEL``, ``ATT``, ``BA``, ``BG``), then the
optional states a run needs, each a first-order Gauss-Markov process decoupled from the
navigation states in ``F`` (:class:`MarkovBlock`), in the order of :data:`MARKOV_ORDER`:

* ``gnss_error`` (3, NED [m]): the time-correlated part of the GNSS fix error (``[gnss]
  gm_sigma_m > 0``);
* ``odometry_scale`` (1, [-]): the wheel odometry's scale-factor error (a run with odometry).

:class:`StateLayout` is built per run from the blocks in use. IMU error states coupled to the
navigation states (scale factors, misalignments) would be navigation blocks of their own after
``BG``, with their ``F`` and ``G`` blocks in :mod:`gnssacc.estimators.mechanization`; the Markov
states then follow them (``StateLayout.nav``).

Smoother node
-------------
Each node's variables, in the order of their joint marginal covariance (the smoother's record,
its window marginals, iSAM2's joint query and the start's prior all use it): the pose ``X``
(GTSAM's Pose3 tangent, rotation then translation, body axes), the velocity ``V`` (NED), the
IMU bias ``B`` (accelerometer, then gyro), then when modelled the GNSS error ``G`` and the
odometry scale factor ``K`` (always the last row): :class:`NodeLayout`. The integer offsets are
module constants so that numba kernels can use them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.states import (  # noqa: F401 (the navigation blocks, re-exported)
    ATT,
    BA,
    BG,
    BIASES,
    BLOCK,
    I_ATT,
    I_BA,
    I_BG,
    I_POS,
    I_VEL,
    N_NAV,
    NAV,
    POS,
    VEL,
)

#: The optional (Gauss-Markov) states after the navigation states, in the order they take.
GNSS_ERROR, ODOMETRY_SCALE = "gnss_error", "odometry_scale"
MARKOV_ORDER = (GNSS_ERROR, ODOMETRY_SCALE)


@dataclass(frozen=True, eq=False)
class MarkovBlock:
    """A block of first-order Gauss-Markov states after the navigation states.

    Attributes
    ----------
    name : str
        One of :data:`MARKOV_ORDER`.
    tau_s : ndarray (dim,)
        Correlation time per entry [s].
    sigma : ndarray (dim,)
        Stationary 1-sigma per entry (the state's unit), also its 1-sigma at the start.
    """

    name: str
    tau_s: np.ndarray
    sigma: np.ndarray

    @property
    def dim(self) -> int:
        return len(self.sigma)


@dataclass(frozen=True, eq=False)
class StateLayout:
    """The EKF error state of one run: the navigation states, then :attr:`markov` in the order of
    :data:`MARKOV_ORDER` (module notes)."""

    markov: tuple[MarkovBlock, ...] = ()
    nav: int = N_NAV

    @classmethod
    def build(cls, blocks) -> "StateLayout":
        """The layout with ``blocks`` (:class:`MarkovBlock`, any order, each name once)."""
        blocks = sorted(blocks, key=lambda b: MARKOV_ORDER.index(b.name))
        names = [b.name for b in blocks]
        if len(set(names)) != len(names):
            raise ValueError(f"a state block is asked for twice: {names}")
        return cls(tuple(blocks))

    @property
    def n(self) -> int:
        """Number of states."""
        return self.nav + sum(b.dim for b in self.markov)

    @property
    def extra(self) -> slice:
        """The states after the navigation states."""
        return slice(self.nav, self.n)

    def offset(self, name: str) -> int:
        """Index of the first state of block ``name``, -1 when the run does not have it."""
        i = self.nav
        for b in self.markov:
            if b.name == name:
                return i
            i += b.dim
        return -1

    def has(self, name: str) -> bool:
        return self.offset(name) >= 0

    def block(self, name: str) -> slice:
        """The states of block ``name`` (an empty slice when the run does not have it)."""
        i = self.offset(name)
        dim = next((b.dim for b in self.markov if b.name == name), 0)
        return slice(i, i + dim) if i >= 0 else slice(0, 0)

    def extra_block(self, name: str) -> slice:
        """Block ``name`` within the states after the navigation ones (``FilterState.x_e``)."""
        sl = self.block(name)
        return slice(sl.start - self.nav, sl.stop - self.nav) if self.has(name) else sl

    @property
    def markov_tau(self) -> np.ndarray:
        """Correlation time of every state after the navigation ones, in order [s]."""
        return np.array([t for b in self.markov for t in np.atleast_1d(b.tau_s)], float)

    @property
    def markov_var(self) -> np.ndarray:
        """Stationary variance of every state after the navigation ones, in order."""
        return np.array([s for b in self.markov for s in np.atleast_1d(b.sigma)], float) ** 2


# The smoother's node (module notes): offsets and sizes of its variables.
I_X, D_X = 0, 6
I_V, D_V = 6, 3
I_B, D_B = 9, 6
I_G, D_G = 15, 3
D_K = 1
#: GTSAM symbol characters of the node variables.
SYM_X, SYM_V, SYM_B, SYM_G, SYM_K = "x", "v", "b", "g", "k"
NODE_X = slice(I_X, I_X + D_X)
NODE_V = slice(I_V, I_V + D_V)
NODE_B = slice(I_B, I_B + D_B)
NODE_G = slice(I_G, I_G + D_G)
#: Within the pose tangent: rotation, translation (body axes).
X_ROT, X_TRANS = slice(0, 3), slice(3, 6)
#: Within the bias: accelerometer, gyro.
B_ACC, B_GYRO = slice(0, 3), slice(3, 6)
#: The start's joint prior (:func:`gnssacc.factors.joint_prior_factor`): pose tangent, bias, then
#: the GNSS error when modelled.
PRIOR_POSE, PRIOR_BIAS, PRIOR_G = slice(0, 6), slice(6, 12), slice(12, 15)
#: GTSAM's NavState tangent (rotation, position, velocity; the preintegration's covariance and
#: Jacobians): its pose part and its velocity, and the whole of it.
NAVSTATE_POSE, NAVSTATE_VEL = slice(0, 6), slice(6, 9)
NAVSTATE = slice(0, 9)


#: The node variable of each Gauss-Markov block (its GTSAM symbol character).
NODE_SYMBOL = {GNSS_ERROR: SYM_G, ODOMETRY_SCALE: SYM_K}


def node_size(gm: bool, scale: bool) -> int:
    """Rows of a node's joint marginal with (``gm``) the GNSS error and (``scale``) the odometry
    scale factor."""
    return I_B + D_B + (D_G if gm else 0) + (D_K if scale else 0)


@dataclass(frozen=True, eq=False)
class NodeLayout:
    """The variables of every node of one smoother run (module notes): pose, velocity, bias, then
    the Gauss-Markov blocks :attr:`markov` in the order of :data:`MARKOV_ORDER` (the GNSS error
    ``G``, the odometry scale factor ``K``)."""

    markov: tuple[MarkovBlock, ...] = ()

    @classmethod
    def build(cls, blocks) -> "NodeLayout":
        return cls(StateLayout.build(blocks).markov)

    def has(self, name: str) -> bool:
        return any(b.name == name for b in self.markov)

    @property
    def gm(self) -> bool:
        return self.has(GNSS_ERROR)

    @property
    def scale(self) -> bool:
        return self.has(ODOMETRY_SCALE)

    @property
    def b(self) -> int:
        """Rows of a node's joint marginal."""
        return node_size(self.gm, self.scale)

    def markov_blocks(self) -> list[tuple[str, slice, MarkovBlock]]:
        """``(symbol character, rows, block)`` of each Gauss-Markov variable, in order."""
        out, i = [], I_B + D_B
        for blk in self.markov:
            out.append((NODE_SYMBOL[blk.name], slice(i, i + blk.dim), blk))
            i += blk.dim
        return out

    def blocks(self) -> list[tuple[str, slice]]:
        """``(symbol character, rows)`` of each variable, in order."""
        out = [(SYM_X, NODE_X), (SYM_V, NODE_V), (SYM_B, NODE_B)]
        return out + [(c, sl) for c, sl, _ in self.markov_blocks()]

    @property
    def symbols(self) -> str:
        """The symbol characters of a node's variables, in order."""
        return "".join(c for c, _ in self.blocks())
