"""The smoother's per-node covariances are the full marginals of the graph iSAM2 holds.

:class:`gnssacc.estimators.window_marginals.WindowMarginals` keeps its own copy of the window's linear
system; these tests compare every covariance the smoother records (online and fixed-lag) with
two independent references computed at the same moment: iSAM2's own joint marginal (QR on the
Bayes tree) and a batch QR elimination of all the smoother's factors linearised at its
linearisation point.
"""

import gtsam
import numpy as np
import pytest

from gnssacc.estimators.aids import gnss_accel
from gnssacc.estimators.layout import NODE_B, NODE_V, NODE_X
from gnssacc.prepare.passes import run_smoother
import gnssacc.estimators.smoother_graph as G
import gnssacc.estimators.window_marginals as W
from gnssacc.core.config import load_config
from gnssacc.pipeline import with_outages
from gnssacc.sources.sim import grade_config, simulate

GM = {"gnss": {"gm_sigma_m": 1.5, "gm_tau_s": 40.0}}


def _batch_marginal(isam, keys):
    """Joint marginal of ``keys`` from a batch QR elimination of all factors at the linearisation
    point (``gtsam.Marginals`` eliminates by Cholesky, which these stiff systems defeat)."""
    gfg = isam.getFactors().linearize(isam.getLinearizationPoint())
    order = gtsam.Ordering(keys)
    bn = gfg.marginalMultifrontalBayesNet(order, gtsam.EliminateQR)
    info, _ = gtsam.GaussianFactorGraph(bn).hessian(order)
    return np.linalg.inv(info)


def _worst(C, ref):
    """Largest difference relative to the reference sigmas (the correlation scale)."""
    d = np.sqrt(np.diag(ref))
    rel = np.abs(C - ref) / np.outer(d, d)
    return float(np.nanmax(rel))


def _diagonal_blocks(C):
    """The per-variable blocks (pose, velocity, bias) only: iSAM2's fallback gives no others."""
    out = np.full_like(C, np.nan)
    for sl in (NODE_X, NODE_V, NODE_B):
        out[sl, sl] = C[sl, sl]
    return out


FILL = {"smoother": {"max_node_spacing_s": 0.5}}


@pytest.mark.parametrize(
    "method,overrides,band",
    [
        ("smoother", {}, None),
        ("smoother-acc", {}, None),
        ("smoother", GM, None),
        ("smoother-accw", {}, None),  # window factors on three nodes: a band of the window's width
        ("smoother-accw", FILL, None),  # fill nodes between the fixes: factors on up to five nodes
        ("smoother-accw", {}, 1),
    ],  # a factor wider than the band: iSAM2's queries meanwhile
    ids=["smoother", "smoother-acc", "gauss-markov", "accw", "accw-fill", "accw-too-wide"],
)
def test_recorded_covariances_equal_full_marginals(monkeypatch, method, overrides, band):
    cfg = load_config(overrides={"imu": grade_config("industrial"), **overrides})
    run = simulate("car", duration_s=70.0, imu_grade="industrial", noise="white", seed=4)
    run = with_outages(run, "30:6", None)  # fill nodes, then a window without fixes
    if band is not None:
        monkeypatch.setattr(gnss_accel, "bandwidth", lambda cfg: band)
    part = _diagonal_blocks if band is not None else (lambda C: C)
    stats = {"calls": 0, "fast": 0, "isam": 0.0, "batch": 0.0, "n_batch": 0}
    fast = W.WindowMarginals.covariances

    def counted(self, nodes):
        out = fast(self, nodes)
        stats["fast"] += len(nodes)
        return out

    orig = G.WindowSmoother.covariances

    def checked(self, nodes):
        covs = orig(self, nodes)
        for i, c in zip(nodes, covs):
            stats["calls"] += 1
            C = part(c)  # the node's whole joint marginal
            keys = self.keys(i)
            ref = self.isam.getISAM2().jointMarginalCovariance(keys).fullMatrix()
            stats["isam"] = max(stats["isam"], _worst(C, ref))
            if stats["calls"] % 5 == 0:
                stats["batch"] = max(stats["batch"], _worst(C, _batch_marginal(self.isam, keys)))
                stats["n_batch"] += 1
        return covs

    monkeypatch.setattr(W.WindowMarginals, "covariances", counted)
    monkeypatch.setattr(G.WindowSmoother, "covariances", checked)
    sols = run_smoother(run, cfg, method)
    n = sols[method].stats["n_nodes"]
    # Every node: online and fixed-lag; the last node is both at the end (one query).
    assert stats["calls"] == 2 * n - 1
    if band is None:
        assert stats["fast"] == stats["calls"]  # never iSAM2's slow query
    else:
        assert (
            stats["fast"] < stats["calls"] // 2
        )  # mostly iSAM2's (the chain's first nodes are not)
    assert stats["n_batch"] >= 2 * n // 5
    assert stats["isam"] < 1e-5, stats
    assert stats["batch"] < 1e-5, stats


def _add_random_factors(wm, H, rng, nodes, last, w, scale):
    """Random factors on up to ``w + 1`` consecutive nodes (none beyond ``last``) starting at each
    of ``nodes``, into the WindowMarginals ``wm`` and the dense matrix ``H`` alike."""
    from gtsam.symbol_shorthand import B, V, X

    b = wm.b
    for k in nodes:
        for span in range(min(w, last - k) + 1):
            keys = sorted(f(j) for j in range(k, k + span + 1) for f in (X, V, B))
            idx = np.concatenate(
                [
                    (key & W._INDEX_MASK) * b + W._layout(key)[0] + np.arange(W._layout(key)[1])
                    for key in keys
                ]
            )
            A = rng.normal(size=(len(idx) + 3, len(idx))) / scale[idx % b]
            aug = np.zeros((len(idx) + 1, len(idx) + 1))
            aug[:-1, :-1] = A.T @ A
            wm._scatter(aug, np.array(keys, np.int64))
            H[np.ix_(idx, idx)] += A.T @ A


@pytest.mark.parametrize("w", [1, 2, 3])
def test_band_marginals_equal_the_dense_inverse(w):
    """Every node's covariance against the dense inverse: after building the band, after new
    factors at the newest end (what the kept copy of a band must follow), and after marginalising
    the two oldest nodes (which keeps the marginals of the others). Variables scaled over ten
    orders of magnitude."""
    b, n = 15, 10
    rng = np.random.default_rng(w)
    scale = 10.0 ** rng.uniform(-5, 5, b)
    wm = W.WindowMarginals(gm=False, bandwidth=w)
    wm.first = 0
    wm._grow(n - 2)
    H = np.zeros((n * b, n * b))
    _add_random_factors(wm, H, rng, range(n - 1), n - 2, w, scale)  # nodes 0 .. n-2
    H_now = H[: (n - 1) * b, : (n - 1) * b]

    def worst(H, nodes):
        ref = np.linalg.inv(H)
        covs = wm.covariances(nodes)
        return max(
            _worst(c, ref[j * b : (j + 1) * b, j * b : (j + 1) * b]) for c, j in zip(covs, nodes)
        )

    assert worst(H_now, list(range(n - 1))) < 1e-9
    _add_random_factors(wm, H, rng, range(n - 1 - w, n), n - 1, w, scale)  # up to the new node n-1
    assert worst(H, list(range(n))) < 1e-9
    _add_random_factors(wm, H, rng, [1], n - 1, w, scale)  # behind what the kept copy eliminated
    assert worst(H, list(range(n))) < 1e-9
    wm.marginalize_first()
    wm.marginalize_first()
    assert worst(H, [2, 5, n - 1]) < 1e-9


@pytest.mark.parametrize("w", [1, 2])
def test_a_rebuilds_batch_scatters_as_its_factors_one_by_one(w):
    """A rebuild's batch (:meth:`WindowMarginals._scatter_many`, one compiled call) leaves the
    same blocks, to the bit, as the factors scattered one at a time in the same order, and the
    same bookkeeping; a factor wider than the band in the batch is refused as alone."""
    from gtsam.symbol_shorthand import B, V, X

    rng = np.random.default_rng(11)
    factors = []
    for k in range(6):
        for span in range(min(w, 5 - k) + 1):
            keys = sorted(f(j) for j in range(k, k + span + 1) for f in (X, V, B))
            d = 15 * len(keys) // 3
            A = rng.normal(size=(d + 2, d)) * 10.0 ** rng.uniform(-4, 4, d)
            factors.append((np.asfortranarray(A.T @ A), np.array(keys, np.int64)))
    one, batch = (W.WindowMarginals(gm=False, bandwidth=w) for _ in range(2))
    for wm in (one, batch):
        wm.first = 0
        wm._grow(5)
    for info, keys in factors:
        one._scatter(info, keys)
    bounds = np.cumsum([0] + [len(k) for _, k in factors])
    batch._scatter_many([i for i, _ in factors], np.concatenate([k for _, k in factors]), bounds)
    for name in ("D", "O", "Ox"):
        np.testing.assert_array_equal(getattr(batch, name), getattr(one, name))
    assert (batch.reach, batch.f_valid, batch.n) == (one.reach, one.f_valid, one.n)
    wide = np.array([X(1), X(1 + w + 1)], np.int64)
    with pytest.raises(W.NotAChain):
        batch._scatter_many([np.ones((12, 12))], wide, np.array([0, 2]))  # coupled


def test_band_refuses_a_factor_wider_than_the_band():
    from gtsam.symbol_shorthand import X

    wm = W.WindowMarginals(gm=False, bandwidth=2)
    wm.first = 0
    wm._grow(5)
    with pytest.raises(W.NotAChain):
        wm._scatter(np.ones((13, 13)), np.array([X(1), X(4)], np.int64))


@pytest.mark.parametrize("w", [1, 2])
def test_an_indefinite_window_is_reported_not_divided_by_zero(w):
    """A block that is not positive definite (here: a node with no information on its bias)
    makes the query raise LinAlgError, which the smoother answers from iSAM2 instead."""
    b, n = 15, 4
    rng = np.random.default_rng(7)
    wm = W.WindowMarginals(gm=False, bandwidth=w)
    wm.first = 0
    wm._grow(n - 1)
    _add_random_factors(wm, np.zeros((n * b, n * b)), rng, range(n), n - 1, w, np.ones(b))
    wm.D[wm.start + 2][9:15, :] = 0.0
    wm.D[wm.start + 2][:, 9:15] = 0.0
    wm.O[wm.start + 1][:, 9:15] = 0.0
    wm.O[wm.start + 2][9:15, :] = 0.0
    wm.Ox[:] = 0.0
    with pytest.raises(np.linalg.LinAlgError):
        wm.covariances(list(range(n)))
