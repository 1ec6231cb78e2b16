"""Every registered aid's Jacobians against central differences, through the aid interface.

The EKF: each aid's measurements (:meth:`gnssacc.estimators.aids.EkfAid.models`) at real filter
states of a pass, every column of ``H`` (the navigation states, the Gauss-Markov GNSS error, the
odometry scale factor) against the difference of ``dz`` with the state moved both ways by the
filter's own correction. The smoother: every kind of factor each aid adds to a run, at random
values, the Jacobian of every key (pose, velocity, bias, GNSS error, scale factor) against the
difference of its whitened error with the key retracted both ways.

The scenario (a simulated UGV with wheel odometry, stops, 5 Hz fixes, the Gauss-Markov fix
error and both acceleration forms) must give every aid of :data:`gnssacc.estimators.aids.REGISTRY`
a measurement and a factor: a new aid fails here until the scenario exercises it.
"""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
import pytest

import gnssacc.estimators.ekf as ekf_module
import gnssacc.estimators.smoother as smoother_module
from gnssacc.core.config import load_config
from gnssacc.estimators.aids import REGISTRY
from gnssacc.estimators.layout import I_POS, SYM_B, SYM_G, SYM_K, SYM_V, SYM_X
from gnssacc.estimators.settings import EkfSettings, SmootherSettings
from gnssacc.estimators.state import correct
from gnssacc.pipeline import prepare
from gnssacc.sources.sim import grade_config, simulate

#: Updates checked per aid in an EKF pass, factors per kind per aid in a smoother run.
PER_AID = 4


@pytest.fixture(scope="module", params=["white", "gauss-markov"])
def prep(request):
    """The scenario with lever arms (so that every aid's factors have all their keys), white fixes
    or the Gauss-Markov fix error."""
    gnss = {"lever_arm_b_m": [0.4, -0.2, -1.1]}
    if request.param == "gauss-markov":
        gnss.update(gm_sigma_m=[1.0, 1.0, 2.0], gm_tau_s=60.0)
    cfg = load_config(
        overrides={
            "imu": grade_config("industrial"),
            "gnss": gnss,
            "nhc": {"lever_arm_b_m": [-0.6, 0.05, 0.3]},
            "odometry": {"lever_arm_b_m": [-0.6, 0.1, 0.3]},
            "smoother": {"min_node_spacing_s": 0.5},
        }
    )
    run = simulate(
        "ugv", 90.0, imu_grade="industrial", gnss_rate_hz=5.0, odom_hz=10.0, seed=7, velocity=True
    )
    return prepare(run, cfg, "none")


def _moved(s, column: int, step: float):
    """A copy of the filter state ``s`` moved by ``step`` along error-state ``column`` (the
    filter's correction of an error of ``-step``)."""
    c = replace(
        s,
        pos=s.pos.copy(),
        v_n=s.v_n.copy(),
        R_nb=s.R_nb.copy(),
        b_a=s.b_a.copy(),
        b_g=s.b_g.copy(),
        P=s.P.copy(),
        x_e=s.x_e.copy(),
    )
    dx = np.zeros(s.P.shape[0])
    dx[column] = -step
    correct(c, dx)
    return c


def _check_ekf(aid, s, j, where: str) -> int:
    """Every measurement of ``aid`` at epoch ``j`` and state ``s``: ``H`` against differences."""
    models = aid.models(s, j)
    for k, m in enumerate(models):
        n = s.P.shape[0]
        num = np.zeros_like(m.H)
        for c in range(n):
            step = 1e-3 if I_POS <= c < I_POS + 3 else 1e-6
            plus = aid.models(_moved(s, c, step), j)[k].dz
            minus = aid.models(_moved(s, c, -step), j)[k].dz
            num[:, c] = (plus - minus) / (2 * step)
        scale = 1.0 + np.max(np.abs(m.H))
        np.testing.assert_allclose(m.H, num, rtol=1e-4, atol=1e-5 * scale, err_msg=where)
    return len(models)


@pytest.mark.parametrize("method", ["ekf-acc", "ekf-accw", "ekf-vacc", "ekf-vaccw"])
def test_every_ekf_aid_jacobian_matches_central_differences(prep, method, monkeypatch):
    checked: dict[str, int] = {}
    real = ekf_module.ekf_aids

    def checking(ctx):
        aids = real(ctx)
        for aid in aids:
            updates = aid.updates

            def wrapped(s, j, stats, aid=aid, updates=updates):
                if checked.get(aid.name, 0) < PER_AID:
                    where = f"{aid.name} at epoch {j}, {method}"
                    checked[aid.name] = checked.get(aid.name, 0) + _check_ekf(aid, s, j, where)
                yield from updates(s, j, stats)

            aid.updates = wrapped
        return aids

    monkeypatch.setattr(ekf_module, "ekf_aids", checking)
    # The Python loop, which asks every aid for its updates (the compiled loop runs the fix's and
    # the constraint's steps itself: tests/test_event_loop.py holds it to this loop).
    monkeypatch.setattr(ekf_module, "COMPILED_LOOP", False)
    sol = ekf_module.estimate(prep, EkfSettings.from_config(prep.cfg), method, output_times=[])
    assert sol.stats["n_odo_updates"] > 0 and sol.stats["n_zupt_updates"] > 0
    missing = {spec.name for spec in REGISTRY} - {n for n, c in checked.items() if c}
    assert not missing, f"the scenario gives these aids no EKF measurement: {missing}"


def _random_value(key: int, rng):
    """A plausible random value of the node variable ``key`` (by its symbol)."""
    c = chr(gtsam.Symbol(key).chr())
    if c == SYM_X:
        return gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(0, 0.5, 3)), rng.normal(0, 50.0, 3))
    if c == SYM_B:
        return gtsam.imuBias.ConstantBias(rng.normal(0, 0.05, 3), rng.normal(0, 1e-3, 3))
    dim = {SYM_V: 3, SYM_G: 3, SYM_K: 1}[c]
    return rng.normal(0, {SYM_V: 5.0, SYM_G: 1.0, SYM_K: 0.02}[c], dim)


def _retract(value, d: np.ndarray):
    if isinstance(value, np.ndarray):
        return value + d
    return value.retract(d)


def _check_factor(factor, rng, where: str) -> None:
    """The whitened Jacobian of every key of ``factor`` at random values against differences."""
    values, keys = gtsam.Values(), list(factor.keys())
    for key in keys:
        values.insert(key, _random_value(key, rng))
    A, _ = factor.linearize(values).jacobian()
    col = 0
    for key in keys:
        value = values.atPose3(key) if chr(gtsam.Symbol(key).chr()) == SYM_X else None
        if value is None:
            c = chr(gtsam.Symbol(key).chr())
            value = values.atConstantBias(key) if c == SYM_B else values.atVector(key)
        dim = 6 if isinstance(value, (gtsam.Pose3, gtsam.imuBias.ConstantBias)) else len(value)
        for d in range(dim):
            step = np.zeros(dim)
            step[d] = 1e-6
            errors = []
            for sign in (1.0, -1.0):
                moved = gtsam.Values(values)
                moved.update(key, _retract(value, sign * step))
                errors.append(factor.whitenedError(moved))
            num = (errors[0] - errors[1]) / 2e-6
            scale = 1.0 + np.max(np.abs(A))
            np.testing.assert_allclose(
                A[:, col + d], num, rtol=1e-4, atol=1e-5 * scale, err_msg=f"{where}, key {key}"
            )
        col += dim


@pytest.mark.parametrize(
    "method", ["smoother-acc", "smoother-accw", "smoother-vacc", "smoother-vaccw"]
)
def test_every_smoother_aid_factor_jacobian_matches_central_differences(prep, method, monkeypatch):
    factors: dict[str, dict] = {}  # aid -> factor type -> factors
    real = smoother_module.smoother_aids

    def capturing(ctx):
        aids = real(ctx)
        for aid in aids:
            for hook in ("interval", "node"):
                orig = getattr(aid, hook)

                def wrapped(graph, *args, aid=aid, orig=orig):
                    n0 = graph.size()
                    orig(graph, *args)
                    for j in range(n0, graph.size()):
                        f = graph.at(j)
                        syms = "".join(chr(gtsam.Symbol(k).chr()) for k in f.keys())
                        kind = f"{type(f).__name__} on {syms}"
                        got = factors.setdefault(aid.name, {}).setdefault(kind, [])
                        if len(got) < PER_AID:
                            got.append(f)

                setattr(aid, hook, wrapped)
        return aids

    monkeypatch.setattr(smoother_module, "smoother_aids", capturing)
    smoother_module.estimate(prep, SmootherSettings.from_config(prep.cfg), method)
    missing = {spec.name for spec in REGISTRY} - set(factors)
    assert not missing, f"the scenario gives these aids no smoother factor: {missing}"
    # A fix between two nodes: a factor on the earlier node's pose, velocity and bias.
    assert any(k.endswith(("xvb", "xvbgg")) for k in factors["gnss_position"]), factors
    rng = np.random.default_rng(3)
    for name, kinds in factors.items():
        for kind, fs in kinds.items():
            for f in fs:
                _check_factor(f, rng, f"{name}: {kind}, {method}")
