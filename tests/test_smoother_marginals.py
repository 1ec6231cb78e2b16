"""The smoother's per-node covariances are the full marginals of the graph iSAM2 holds.

:class:`gnssacc.window_marginals.WindowMarginals` keeps its own copy of the window's linear
system; these tests compare every covariance the smoother records (online and fixed-lag) with
two independent references computed at the same moment: iSAM2's own joint marginal (QR on the
Bayes tree) and a batch QR elimination of all the smoother's factors linearised at its
linearisation point.
"""
import gtsam
import numpy as np
import pytest

import gnssacc.smoother as S
import gnssacc.window_marginals as W
from gnssacc.config import load_config
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


@pytest.mark.parametrize("method,overrides", [("smoother", {}), ("smoother-acc", {}), ("smoother", GM)],
                         ids=["smoother", "smoother-acc", "gauss-markov"])
def test_recorded_covariances_equal_full_marginals(monkeypatch, method, overrides):
    cfg = load_config(overrides={"imu": grade_config("industrial"), **overrides})
    run = simulate("car", duration_s=70.0, imu_grade="industrial", noise="white", seed=4)
    run = with_outages(run, "30:6", None)            # fill nodes, then a window without fixes
    stats = {"calls": 0, "fast": 0, "isam": 0.0, "batch": 0.0, "n_batch": 0}
    fast = W.WindowMarginals.covariances

    def counted(self, nodes):
        out = fast(self, nodes)
        stats["fast"] += len(nodes)
        return out

    orig = S._Smoother.covariances

    def checked(self, nodes):
        covs = orig(self, nodes)
        for i, c in zip(nodes, covs):
            stats["calls"] += 1
            C = c                                    # the node's whole joint marginal
            keys = self.keys(i)
            ref = self.isam.getISAM2().jointMarginalCovariance(keys).fullMatrix()
            stats["isam"] = max(stats["isam"], _worst(C, ref))
            if stats["calls"] % 5 == 0:
                stats["batch"] = max(stats["batch"], _worst(C, _batch_marginal(self.isam, keys)))
                stats["n_batch"] += 1
        return covs

    monkeypatch.setattr(W.WindowMarginals, "covariances", counted)
    monkeypatch.setattr(S._Smoother, "covariances", checked)
    sols = S.run_smoother(run, cfg, method)
    n = sols[method].stats["n_nodes"]
    # Every node: online and fixed-lag; the last node is both at the end (one query).
    assert stats["calls"] == 2 * n - 1
    assert stats["fast"] == stats["calls"]           # never iSAM2's slow query
    assert stats["n_batch"] >= 2 * n // 5
    assert stats["isam"] < 1e-5, stats
    assert stats["batch"] < 1e-5, stats


def test_window_marginals_detect_a_factor_that_breaks_the_chain():
    """A factor between nodes two apart has no place in the block-tridiagonal form."""
    from gtsam.symbol_shorthand import V

    wm = W.WindowMarginals(gm=False)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for k in range(3):
        values.insert(V(k), np.zeros(3))
    graph.add(gtsam.BetweenFactorVector(V(0), V(2), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    wm.first = 0
    wm._grow(2)
    with pytest.raises(W.NotAChain):
        wm.add(graph.linearize(values))
