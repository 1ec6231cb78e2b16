r"""Exact marginal covariances of a fixed-lag smoother's window, kept in step with iSAM2.

iSAM2's own marginal queries (``marginalCovariance``, ``jointMarginalCovariance``, ``joint``)
go through the Bayes tree's generic shortcut machinery: about 0.2 ms for a node in the root
clique and 0.5 ms for the node about to leave a 10 s window of 1 Hz nodes, more than the update
itself. This module computes the same numbers from the same linear system.

The linear system iSAM2 holds is every factor of the smoother linearised at its linearisation
point ``theta`` (``getFactors()``, ``getLinearizationPoint()``; marginalised nodes live on as
linear factors on their neighbours). Between relinearisations ``theta`` only grows by the new
nodes, so the information matrix ``H`` changes by

* the new factors, linearised at ``theta`` (a few small blocks), and
* the Schur complement of each node that leaves the window onto the next one (what iSAM2's
  ``marginalizeLeaves`` leaves behind as a linear factor).

When iSAM2 relinearises (``getVariablesRelinearized() > 0``, at most every
``relinearize_skip`` updates) or the smoother restarts, ``H`` is rebuilt from all factors.

The nodes form a chain (IMU and Gauss-Markov factors link consecutive nodes only), so ``H``
ordered by node is block-tridiagonal: diagonal blocks ``D_k`` and couplings ``O_k = H[k, k+1]``.
A node's marginal information is ``D_k`` less the Schur complements of the older and of the
newer nodes onto it, computed by a forward sweep ``F_{k+1} = D_{k+1} - O_k^T F_k^-1 O_k`` and a
backward sweep ``G_k = D_k - O_k G_{k+1}^-1 O_k^T`` (block Cholesky; each pivot is scaled to
unit diagonal first, since the variables span twelve orders of magnitude). The forward sweep is
kept from update to update: neither new factors at the newest end nor the Schur complement of the
oldest node change ``F`` of the nodes in between. One query after each update gives the newest
node and every node about to leave the window (one backward sweep serves them all).

Factors on several nodes (``smoother-accw``'s window factors) make ``H`` block-banded: couplings
``H[k, k+d]`` up to the band's width. A node's marginal is then what is left of its block after
eliminating, on a copy, the older nodes oldest first and the newer nodes newest first (each
elimination a Schur complement onto the node's neighbours in the band). A copy with the older
rows already eliminated is kept between updates, as the forward sweep is for a chain.

New factors come in as one dense Hessian of the update's graph; a rebuild goes factor by factor
(a whole window's dense Hessian grows with the square of its nodes). Kernels are compiled with
numba, which also keeps these small dense operations off the BLAS thread pool.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from .layout import D_B, D_G, D_K, D_V, D_X, I_B, I_G, I_V, I_X, SYM_B, SYM_G, SYM_K, SYM_V, SYM_X
from .layout import node_size

if TYPE_CHECKING:  # the kernels compile without gtsam (at install time, kernels.compile_groups)
    import gtsam

_INDEX_MASK = (1 << 56) - 1
#: Rows of a node without the optional variables (pose, velocity, bias).
N_NODE = I_B + D_B


def symbol_key(char: str, index: int) -> int:
    """The key of GTSAM's symbol ``char`` ``index`` (``gtsam.symbol_shorthand.X(i)`` for "x")."""
    return (ord(char) << 56) | index


def key_name(key: int) -> str:
    """A symbol key as GTSAM's ``DefaultKeyFormatter`` writes it (``x12``)."""
    return f"{chr(key >> 56)}{key & _INDEX_MASK}"


class NotAChain(RuntimeError):
    """A factor links nodes further apart than the band (the block-banded form does not hold)."""


@njit(cache=True)
def _gram(W, scale):
    """``W^T W`` scaled by ``scale_i scale_j`` (explicit loops: numba's ``@`` would call BLAS)."""
    r, m = W.shape
    out = np.zeros((m, m))
    for k in range(r):  # row by row, contiguous inner loops
        for i in range(m):
            w = W[k, i]
            for j in range(i, m):
                out[i, j] += w * W[k, j]
    for i in range(m):
        for j in range(i, m):
            out[i, j] *= scale[i] * scale[j]
            out[j, i] = out[i, j]
    return out


@njit(cache=True)
def _chol(A):
    """Lower Cholesky factor of ``S A S`` and ``s`` (``S = diag(s)``, unit diagonal), or a NaN
    factor."""
    b = A.shape[0]
    s = np.empty(b)
    for i in range(b):
        s[i] = 1.0 / np.sqrt(A[i, i]) if A[i, i] > 0.0 else np.nan
    L = np.zeros((b, b))
    for j in range(b):
        d = A[j, j] * s[j] * s[j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:  # not positive definite: all NaN, so that what
            for i in range(b):  # divides by it gives NaN (numba raises on / 0.0)
                for k in range(b):
                    L[i, k] = np.nan
            return L, s
        L[j, j] = np.sqrt(d)
        for i in range(j + 1, b):
            v = A[i, j] * s[i] * s[j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / L[j, j]
    return L, s


@njit(cache=True)
def _schur(A, C, transpose):
    """``C^T A^-1 C`` (or ``C A^-1 C^T`` if ``transpose``) for symmetric positive definite ``A``."""
    b = A.shape[0]
    L, s = _chol(A)
    W = np.empty((b, b))
    for i in range(b):  # W = L^-1 S C, row by row
        for j in range(b):
            W[i, j] = (C[j, i] if transpose else C[i, j]) * s[i]
        for k in range(i):
            l_ik = L[i, k]
            for j in range(b):
                W[i, j] -= l_ik * W[k, j]
        d = 1.0 / L[i, i]
        for j in range(b):
            W[i, j] *= d
    return _gram(W, np.ones(b))


@njit(cache=True)
def _inverse(A):
    """``A^-1`` for symmetric positive definite ``A`` (through the scaled Cholesky factor)."""
    b = A.shape[0]
    L, s = _chol(A)
    Li = np.zeros((b, b))
    for j in range(b):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, b):
            v = 0.0
            for k in range(j, i):
                v -= L[i, k] * Li[k, j]
            Li[i, j] = v / L[i, i]
    return _gram(Li, s)


_CHAR_X, _CHAR_V, _CHAR_B, _CHAR_G, _CHAR_K = (ord(c) for c in (SYM_X, SYM_V, SYM_B, SYM_G, SYM_K))


@njit(cache=True)
def _layout(key, b=N_NODE):
    """Offset and dimension of a variable in its node's block of ``b`` rows, from the GTSAM symbol
    character (:class:`gnssacc.estimators.layout.NodeLayout`: the odometry scale factor ``k``,
    when nodes carry one, is the block's last row)."""
    c = key >> 56
    if c == _CHAR_X:
        return I_X, D_X
    if c == _CHAR_V:
        return I_V, D_V
    if c == _CHAR_B:
        return I_B, D_B
    if c == _CHAR_G:
        return I_G, D_G
    if c == _CHAR_K and b in (N_NODE + D_K, N_NODE + D_G + D_K):
        return b - D_K, D_K
    return -1, 0


@njit(cache=True)
def _scatter(D, Od, Ox, info, keys, first, start):
    """Add the information ``info`` of linear factors over ``keys`` (in that order) to the blocks.

    ``info`` may be the joint information of several factors (a graph's dense Hessian): blocks
    between nodes further apart than the band (``1 + Ox.shape[1]`` nodes) must then be zero.
    Returns the lowest storage row touched, -1 for an unknown variable, -2 for a coupling wider
    than the band or a node older than the window.
    """
    w = Ox.shape[1] + 1
    nk = len(keys)
    rows = np.empty(nk, np.int64)
    offs = np.empty(nk, np.int64)
    dims = np.empty(nk, np.int64)
    pos = np.empty(nk, np.int64)  # first row of each key in ``info``
    low = 1 << 62
    p0 = 0
    for p in range(nk):
        offs[p], dims[p] = _layout(keys[p], D.shape[1])
        if dims[p] == 0:
            return -1
        rows[p] = start + (keys[p] & _INDEX_MASK) - first
        if rows[p] < start:
            return -2
        low = min(low, rows[p])
        pos[p] = p0
        p0 += dims[p]
    for p in range(nk):
        for q in range(nk):
            a, c = rows[p], rows[q]
            if a <= c <= a + w:
                T = D[a] if a == c else _coupling(Od, Ox, a, c - a)
                for r in range(dims[p]):
                    for t in range(dims[q]):
                        T[offs[p] + r, offs[q] + t] += info[pos[p] + r, pos[q] + t]
            elif not c < a <= c + w:
                for r in range(dims[p]):
                    for t in range(dims[q]):
                        if info[pos[p] + r, pos[q] + t] != 0.0:
                            return -2
    return low


@njit(cache=True)
def _scatter_all(D, Od, Ox, flat, sizes, keys, bounds, first, start):
    """:func:`_scatter` of many factors in turn: factor ``f``'s information is ``sizes[f]``
    square, column by column in ``flat`` after the previous factors', its keys are
    ``keys[bounds[f]:bounds[f + 1]]``. Returns each factor's lowest storage row touched, up to
    and with the first that does not fit (a negative one, :func:`_scatter`'s codes)."""
    n = len(sizes)
    lows = np.empty(n, np.int64)
    o = 0
    for f in range(n):
        d = sizes[f]
        info = flat[o : o + d * d].reshape((d, d)).T  # column-major, as gtsam gives it
        o += d * d
        lows[f] = _scatter(D, Od, Ox, info, keys[bounds[f] : bounds[f + 1]], first, start)
        if lows[f] < 0:
            return lows[: f + 1]
    return lows


@njit(cache=True)
def _diff_into(out, A, B):
    """``out[:] = A - B`` for square blocks (explicit loops: numba's array expressions cost about
    a second of compilation each, on a first run's critical path)."""
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[i, j] = A[i, j] - B[i, j]


@njit(cache=True)
def _copy_into(out, A):
    """``out[:] = A`` for square blocks (a slice assignment compiles numba's broadcast checks and
    their message formatting: seconds on a first run)."""
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[i, j] = A[i, j]


@njit(cache=True)
def _node_covariances(D, Od, F, start, f_valid, rows, last):
    """Covariances of storage ``rows`` (ascending); extends the forward sweep ``F`` (valid up to
    ``f_valid``) to ``last``, and one backward sweep serves every row.

    Returns the covariances (NaN where not positive definite) and the new ``f_valid``.
    """
    if f_valid < start:
        _copy_into(F[start], D[start])
        f_valid = start
    for k in range(f_valid, last):  # F_{k+1} = D_{k+1} - O_k^T F_k^-1 O_k
        _diff_into(F[k + 1], D[k + 1], _schur(F[k], Od[k], False))
    f_valid = max(f_valid, last)
    b = D.shape[1]
    out = np.empty((len(rows), b, b))
    G = np.empty((b, b))  # G_k: the information of nodes k.. newest on node k
    _copy_into(G, D[last])
    info = np.empty((b, b))
    k = last
    for m in range(len(rows) - 1, -1, -1):
        j = rows[m]
        while k > j + 1:  # G_k = D_k - O_k G_{k+1}^-1 O_k^T
            k -= 1
            _diff_into(G, D[k], _schur(G, Od[k], True))
        if j < last:  # less the newer nodes' Schur complement
            _diff_into(info, F[j], _schur(G, Od[j], True))
        else:
            _copy_into(info, F[j])
        _copy_into(out[m], _inverse(info))
    ok = True
    for m in range(len(rows)):
        ok = ok and np.isfinite(out[m, 0, 0])
    return out, f_valid, ok


@njit(cache=True)
def _marginalize(D, Od, F, start, count, f_valid):
    """Schur complements of the ``count`` oldest nodes onto their successors; drops them.

    Returns the new storage row of the oldest node and the new ``f_valid``.
    """
    for _ in range(count):
        k = start
        _diff_into(D[k + 1], D[k + 1], _schur(D[k], Od[k], False))
        D[k] = 0.0
        Od[k] = 0.0
        start += 1
        if f_valid < start:  # F of the oldest node is its D (kept if already valid)
            _copy_into(F[start], D[start])
            f_valid = start
    return start, f_valid


@njit(cache=True)
def _coupling(Od, Ox, a, d):
    """The block ``H[a, a + d]`` (``1 <= d``): ``Od`` (the ``O_k``) holds ``d = 1``, ``Ox`` ``d = 2
    ..``."""
    return Od[a] if d == 1 else Ox[a, d - 2]


@njit(cache=True)
def _nonzero(A):
    for x in A.ravel():
        if x != 0.0:
            return True
    return False


@njit(cache=True)
def _eliminate(D, Od, Ox, k, lo, hi):
    """Eliminate storage row ``k`` of a block-banded ``H``: subtract its Schur complement from the
    blocks of its neighbours among rows ``[lo, hi]`` (``k`` excluded; bandwidth ``1 +
    Ox.shape[1]``).
    Row ``k``'s own blocks are left as they were."""
    b, w = D.shape[1], Ox.shape[1] + 1
    nbr = np.empty(2 * w, np.int64)
    m = 0
    for r in range(max(lo, k - w), min(hi, k + w) + 1):
        if r != k and _nonzero(
            _coupling(Od, Ox, k, r - k) if r > k else _coupling(Od, Ox, r, k - r)
        ):
            nbr[m] = r  # (a wide band costs only where factors actually reach)
            m += 1
    C = np.empty((b, m * b))  # H[k, neighbours]
    for p in range(m):
        r = nbr[p]
        if r > k:
            blk = _coupling(Od, Ox, k, r - k)
            for i in range(b):
                for j in range(b):
                    C[i, p * b + j] = blk[i, j]
        else:
            blk = _coupling(Od, Ox, r, k - r)
            for i in range(b):
                for j in range(b):
                    C[i, p * b + j] = blk[j, i]
    L, s = _chol(D[k])
    for i in range(b):  # C <- L^-1 S C (scaled pivot, as in _schur)
        for j in range(m * b):
            C[i, j] *= s[i]
        for q in range(i):
            l_ik = L[i, q]
            for j in range(m * b):
                C[i, j] -= l_ik * C[q, j]
        d = 1.0 / L[i, i]
        for j in range(m * b):
            C[i, j] *= d
    S = _gram(C, np.ones(m * b))
    for p in range(m):
        for q in range(p, m):
            T = D[nbr[p]] if p == q else _coupling(Od, Ox, nbr[p], nbr[q] - nbr[p])
            for i in range(b):
                for j in range(b):
                    T[i, j] -= S[p * b + i, q * b + j]


@njit(cache=True)
def _band_covariances(D, Od, Ox, Dc, Oc, Oxc, start, fe, rows, last):
    """Covariances of storage ``rows`` of a block-banded ``H`` (rows ``start .. last``): per row,
    on a copy, eliminate the older rows oldest first and the newer rows newest first, and invert
    what is left of the row. ``Dc, Oc, Oxc`` hold ``H`` with rows ``start .. fe - 1`` already
    eliminated (kept between updates), the copy a row ``>= fe`` starts from. Returns the
    covariances and whether all were positive definite."""
    b = D.shape[1]
    out = np.empty((len(rows), b, b))
    ok = True
    for m in range(len(rows)):
        s = fe if rows[m] >= fe else start
        j, n = rows[m] - s, last - s
        if s == fe:
            D2, O2, Ox2 = Dc[s : last + 1].copy(), Oc[s : last + 1].copy(), Oxc[s : last + 1].copy()
        else:
            D2, O2, Ox2 = D[s : last + 1].copy(), Od[s : last + 1].copy(), Ox[s : last + 1].copy()
        for k in range(j):
            _eliminate(D2, O2, Ox2, k, k + 1, n)
        for k in range(n, j, -1):
            _eliminate(D2, O2, Ox2, k, j, k - 1)
        _copy_into(out[m], _inverse(D2[j]))
        ok = ok and np.isfinite(out[m, 0, 0])
    return out, ok


@njit(cache=True)
def _band_advance(Dc, Oc, Oxc, fe, target, last):
    """Eliminate rows ``fe .. target - 1`` of the kept copy (oldest first)."""
    for k in range(fe, target):
        _eliminate(Dc, Oc, Oxc, k, k + 1, last)


@njit(cache=True)
def _band_marginalize(D, Od, Ox, start, count, last):
    """Schur complements of the ``count`` oldest rows onto their successors; drops them. Returns
    the new storage row of the oldest node."""
    for _ in range(count):
        _eliminate(D, Od, Ox, start, start + 1, last)
        D[start] = 0.0
        Od[start] = 0.0
        Ox[start] = 0.0
        start += 1
    return start


class WindowMarginals:
    """The window's information matrix as blocks, oldest node first, and its marginals.

    Parameters
    ----------
    gm : bool
        Nodes carry a GNSS-error state (blocks of 18 instead of 15).
    scale : bool
        Nodes carry an odometry scale factor (one more row, the last).
    bandwidth : int
        How many nodes apart a factor may reach: 1 for a chain (block-tridiagonal ``H``, the
        kept forward sweep); more for factors on several nodes (``smoother-accw``'s window
        factors), whose marginals come from :func:`_band_covariances`. A wider factor raises
        :class:`NotAChain`.
    """

    def __init__(self, gm: bool, bandwidth: int = 1, scale: bool = False):
        self.b = node_size(gm, scale)
        self.w = int(bandwidth)
        self.clear()

    def clear(self) -> None:
        """Forget the system (the next :meth:`sync` rebuilds it)."""
        self.first: Any = None  # node index of the oldest node held (int; None: nothing held)
        self.n = 0  # nodes held
        self.start = 0  # storage row of the oldest node
        self.f_valid = -1  # storage rows <= this have a valid forward sweep F
        self.fe = -1  # band: the kept copy has rows < fe eliminated (-1: none)
        self.reach = 1  # band: widest factor seen since the last rebuild [nodes]
        self._alloc(64)

    def sync(self, isam, new_factors: gtsam.NonlinearFactorGraph) -> None:
        """Bring the blocks to the smoother's state right after an update with ``new_factors``.

        ``isam`` is the :class:`gnssacc.estimators.fixed_lag.FixedLagISAM2`. Rebuilt from all its
        factors after a
        relinearisation or when nothing is held, else updated incrementally.
        """
        theta = isam.getLinearizationPoint()
        if self.first is None or isam.getISAM2Result().getVariablesRelinearized() > 0:
            self.rebuild(isam.getFactors(), theta)
            return
        try:
            gfg = new_factors.linearize(theta)
        except RuntimeError:  # a new factor on a node already marginalised (a lag
            self.rebuild(isam.getFactors(), theta)  # shorter than the node spacing)
            return
        self.add(gfg)
        count = 0
        while count < self.n - 1 and not theta.exists(symbol_key("x", self.first + count)):
            count += 1
        if count:
            self._marginalize(count)

    def rebuild(self, factors: gtsam.NonlinearFactorGraph, theta: gtsam.Values) -> None:
        """The blocks of all ``factors`` linearised at ``theta``, factor by factor (the dense
        Hessian of the whole window grows with the square of its nodes: 10 Hz nodes, 10 s lag)."""
        nodes = [k & _INDEX_MASK for k in theta.keys() if k >> 56 == ord("x")]
        self.clear()
        self.first = min(nodes)
        self._grow(max(nodes))
        gfg = factors.linearize(theta)
        infos, keys, bounds = [], [], [0]
        for j in range(gfg.size()):
            f = gfg.at(j)
            if f is not None:
                infos.append(f.information())
                keys.extend(f.keys())
                bounds.append(len(keys))
        self._scatter_many(infos, np.array(keys, np.int64), np.array(bounds, np.int64))

    def _scatter_many(self, infos: list, keys: np.ndarray, bounds: np.ndarray) -> None:
        """:meth:`_scatter` of each factor in turn, in one compiled call: ``infos`` their
        information matrices, factor ``f``'s keys ``keys[bounds[f]:bounds[f + 1]]``."""
        if not infos:
            return
        index = keys & _INDEX_MASK
        last = int(index.max())
        if last >= self.first + self.n:
            self._grow(last)
        flat = np.concatenate([np.asarray(a, float).ravel(order="F") for a in infos])
        sizes = np.array([a.shape[0] for a in infos], np.int64)
        lows = _scatter_all(
            self.D, self.O, self.Ox, flat, sizes, keys, bounds, self.first, self.start
        )
        if lows[-1] < 0:
            bad = keys[bounds[len(lows) - 1] : bounds[len(lows)]]
            raise NotAChain(
                f"a factor on {[key_name(int(k)) for k in bad]} does not fit "
                "the window's band of nodes"
            )
        lasts = np.maximum.reduceat(index, bounds[:-1])
        self.f_valid = min(self.f_valid, int(lows.min()) - 1)
        self.reach = max(self.reach, int(np.max(lasts - (lows - self.start + self.first))))

    def add(self, gfg: gtsam.GaussianFactorGraph) -> None:
        """Add the information of an update's new linear factors (appending new nodes as needed),
        from one dense (augmented) Hessian of the graph, its variables in key order: for the few
        variables of an update far cheaper than a Python loop over its factors."""
        keys = gfg.keyVector()
        if keys:
            self._scatter(gfg.augmentedHessian(), np.array(keys, np.int64))

    def _scatter(self, info: np.ndarray, keys: np.ndarray) -> None:
        last = int((keys & _INDEX_MASK).max())
        if last >= self.first + self.n:
            self._grow(last)
        info = np.asfortranarray(info)  # as gtsam gives it: one compiled version of the kernel
        low = _scatter(self.D, self.O, self.Ox, info, keys, self.first, self.start)
        if low < 0:
            raise NotAChain(
                f"a factor on {[key_name(int(k)) for k in keys]} does not fit "
                "the window's band of nodes"
            )
        self.f_valid = min(self.f_valid, low - 1)
        self.reach = max(self.reach, last - (low - self.start + self.first))
        if self.fe >= 0:  # the kept copy of a band: the same information, unless
            if low >= self.fe:  # it reaches a row already eliminated there
                _scatter(self.Dc, self.Oc, self.Oxc, info, keys, self.first, self.start)
            else:
                self.fe = -1

    def marginalize_first(self) -> None:
        """Schur complement of the oldest node onto the next ones; drop it."""
        self._marginalize(1)

    def _marginalize(self, count: int) -> None:
        if self.w == 1:
            self.start, self.f_valid = _marginalize(
                self.D, self.O, self.F, self.start, count, self.f_valid
            )
        else:
            self.start = _band_marginalize(
                self.D, self.O, self.Ox, self.start, count, self.start + self.n - 1
            )
            if self.fe < self.start:  # the kept copy had not eliminated them yet
                self.fe = -1
        self.first += count
        self.n -= count

    def covariances(self, nodes) -> np.ndarray:
        """Marginal covariances of ``nodes``' blocks (ascending node indices), one query: pose
        tangent (6), velocity (3), bias (6)[, GNSS error (3)] each; array (len(nodes), b, b)."""
        last, shift = self.start + self.n - 1, self.start - self.first
        rows = [node + shift for node in nodes]
        if not (
            self.start <= rows[0]
            and rows[-1] <= last
            and all(a < b for a, b in zip(rows, rows[1:], strict=False))
        ):
            raise KeyError(f"nodes {list(nodes)} are not ascending nodes of the window")
        if self.w == 1:
            covs, self.f_valid, ok = _node_covariances(
                self.D, self.O, self.F, self.start, self.f_valid, np.array(rows, np.int64), last
            )
        else:
            covs, ok = self._band_covariances(np.array(rows, np.int64), last)
        if not ok:
            raise np.linalg.LinAlgError(
                f"the marginal information of a node of {list(nodes)} is not positive definite"
            )
        return covs

    def _band_covariances(self, rows: np.ndarray, last: int):
        """Band covariances; first eliminates the kept copy up to the widest factor's reach before
        the newest row (new factors are not expected further back; if one is, the copy is made
        again), so the newest node's query costs that many eliminations."""
        s, n = self.start, last + 1
        if self.fe < 0:
            self.Dc[s:n], self.Oc[s:n], self.Oxc[s:n] = self.D[s:n], self.O[s:n], self.Ox[s:n]
            self.fe = s
        target = last - self.reach
        if target > self.fe:
            _band_advance(self.Dc, self.Oc, self.Oxc, self.fe, target, last)
            self.fe = target
        return _band_covariances(
            self.D, self.O, self.Ox, self.Dc, self.Oc, self.Oxc, s, self.fe, rows, last
        )

    def _alloc(self, cap: int) -> None:
        b = self.b
        self.D, self.O, self.F = (np.zeros((cap, b, b)) for _ in range(3))
        self.Ox = np.zeros((cap, self.w - 1, b, b))  # couplings two or more nodes apart
        if self.w > 1:  # the band's kept, partly eliminated copy
            self.Dc, self.Oc, self.Oxc = (
                np.zeros_like(self.D),
                np.zeros_like(self.O),
                np.zeros_like(self.Ox),
            )

    def _grow(self, last: int) -> None:
        """Hold nodes up to ``last``; moves the window to the front of storage when it runs out."""
        n = last - self.first + 1
        if self.start + n > len(self.D):
            D, Od, Ox, F, s, m = self.D, self.O, self.Ox, self.F, self.start, self.n
            kept = (self.Dc, self.Oc, self.Oxc) if self.w > 1 else ()
            self._alloc(max(2 * n, 64))
            self.D[:m], self.O[:m], self.Ox[:m], self.F[:m] = (
                D[s : s + m],
                Od[s : s + m],
                Ox[s : s + m],
                F[s : s + m],
            )
            for new, old in zip(
                (self.Dc, self.Oc, self.Oxc) if self.w > 1 else (), kept, strict=False
            ):
                new[:m] = old[s : s + m]
            self.f_valid -= s
            self.fe = self.fe - s if self.fe >= s else -1
            self.start = 0
        self.n = n


def warm_up(band: bool = False) -> float:
    """Compile (or load) the kernels of a chain of nodes' window (or of a band, ``band``: the
    window-consistent acceleration factors') by running them on a window of three nodes with the
    array types a smoother gives them; the seconds it took. No gtsam (the install compiles them).
    The nodes carry an odometry scale factor, whose one-dimensional factors' information (a 1 x 1
    array, C- and Fortran-contiguous at once) numba types as C-contiguous: a second version of
    :func:`_scatter`, which a run with wheel odometry calls too."""
    t0 = time.perf_counter()
    window = WindowMarginals(gm=False, bandwidth=2 if band else 1, scale=True)
    window.first = 0
    window._grow(2)
    for i in range(3):
        keys = np.array([symbol_key(c, i) for c in "xvb"], np.int64)
        window._scatter(np.asfortranarray(np.eye(window.b - 1)), keys)
        window._scatter(np.eye(1), np.array([symbol_key("k", i)], np.int64))
    batch = np.array([symbol_key(c, i) for i in range(3) for c in "xvb"], np.int64)
    infos = [np.asfortranarray(np.eye(window.b - 1)) for _ in range(3)]  # a rebuild's batch
    window._scatter_many(infos, batch, np.array([0, 3, 6, 9], np.int64))
    window.covariances([0, 1, 2])
    window.marginalize_first()
    return time.perf_counter() - t0
