"""The smoother's node layout with fast fixes: which fixes are nodes, the factor that folds the
others into the node before them, and the estimates against a node per fix."""

import subprocess
import sys
from dataclasses import replace

import gtsam
import numpy as np
import pytest
from gnssacc.factors import preintegrated_position_factor
from gtsam.symbol_shorthand import B, G, V, X

from gnssacc import pipeline
from gnssacc.analysis.metrics import truth_at
from gnssacc.estimators.layout import POS
from gnssacc.core.config import load_config
from gnssacc.core.earth import earth_rate_n, normal_gravity
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.estimators.settings import SmootherSettings
from gnssacc.estimators.aids.gnss_position import node_fixes
from gnssacc.estimators.smoother import estimate
from gnssacc.sources.sim import simulate

LEVER = np.array([0.8, -0.3, -1.2])


def _pim(f_b, w_b, dt, bias_hat, g=9.81, omega=np.zeros(3), acc_psd=1e-4, gyro_psd=1e-6):  # noqa: B008 (never mutated)
    p = gtsam.PreintegrationCombinedParams.MakeSharedD(g)
    p.setAccelerometerCovariance(np.eye(3) * acc_psd)
    p.setGyroscopeCovariance(np.eye(3) * gyro_psd)
    p.setIntegrationCovariance(np.eye(3) * 1e-8)
    p.setBiasAccCovariance(np.eye(3) * 1e-8)
    p.setBiasOmegaCovariance(np.eye(3) * 1e-10)
    p.setOmegaCoriolis(omega)
    pim = gtsam.PreintegratedCombinedMeasurements(p, bias_hat)
    for f, w in zip(f_b, w_b):
        pim.integrateMeasurement(f, w, dt)
    return pim


def _error(pim, pose, vel, bias, z, lever):
    """The factor's error from GTSAM's prediction alone (no Jacobians involved)."""
    pred = pim.predict(gtsam.NavState(pose, vel), bias)
    return pred.position() + pred.attitude().matrix() @ lever - z


@pytest.mark.parametrize("gm", [False, True], ids=["white", "gauss-markov"])
def test_folded_fix_factor_jacobians_by_finite_differences_on_the_manifold(gm):
    rng = np.random.default_rng(4)
    n = 40  # 0.4 s of turning, accelerating IMU samples
    f_b = np.array([0.8, 0.3, -9.7]) + 0.3 * rng.normal(size=(n, 3))
    w_b = np.array([0.02, -0.01, 0.25]) + 0.05 * rng.normal(size=(n, 3))
    pim = _pim(
        f_b,
        w_b,
        0.01,
        gtsam.imuBias.ConstantBias(np.array([0.02, 0.0, -0.01]), np.array([1e-3, 0, 0])),
        omega=earth_rate_n(0.6),
    )
    pose = gtsam.Pose3(gtsam.Rot3(euler_to_dcm(0.05, -0.1, 2.0)), np.array([12.0, -3.0, 0.5]))
    vel, bias = (
        np.array([6.0, -2.0, 0.1]),
        gtsam.imuBias.ConstantBias(np.array([0.05, -0.03, 0.02]), np.array([2e-3, -1e-3, 5e-4])),
    )
    z = np.array([14.0, -4.0, 0.0])
    tau, g0, g1 = (
        np.array([20.0, 30.0, 5.0]),
        np.array([0.4, -0.7, 1.1]),
        np.array([0.5, -0.6, 0.9]),
    )
    keys = (X(0), V(0), B(0)) + ((G(0), G(1)) if gm else ())
    factor = preintegrated_position_factor(
        keys,
        pim,
        z,
        LEVER,
        np.eye(3),
        np.eye(3),
        (tau, np.array([1.0, 1.0, 2.0]), 0.5) if gm else None,
    )
    values = gtsam.Values()
    values.insert(X(0), pose)
    values.insert(V(0), vel)
    values.insert(B(0), bias)
    if gm:
        values.insert(G(0), g0)
        values.insert(G(1), g1)
    # the GNSS error at the fix: the bridge's mean between the two nodes' errors
    phi = lambda t: np.exp(-t / tau)  # noqa: E731
    s, T = pim.deltaTij(), 0.5
    w_j = phi(T - s) * (1 - phi(s) ** 2) / (1 - phi(T) ** 2) if gm else np.zeros(3)
    w_i = phi(s) - w_j * phi(T) if gm else np.zeros(3)
    err = lambda p, v, b, ga, gb: _error(pim, p, v, b, z, LEVER) + w_i * ga + w_j * gb  # noqa: E731
    np.testing.assert_allclose(
        factor.unwhitenedError(values), err(pose, vel, bias, g0, g1), atol=1e-12
    )
    A, b = factor.linearize(values).jacobian()
    L = np.linalg.cholesky(
        np.linalg.inv(factor.noiseModel().covariance())
    )  # the whitening GTSAM applied
    J = np.linalg.solve(L.T, A)  # back to the unwhitened Jacobian: A = L^T J
    eps = 1e-6
    for k in range(21 if gm else 15):
        d = np.zeros(21)
        d[k] = eps
        args = [
            (
                pose.retract(s * d[0:6]),
                vel + s * d[6:9],
                bias.retract(s * d[9:15]),
                g0 + s * d[15:18],
                g1 + s * d[18:21],
            )
            for s in (1, -1)
        ]
        num = (err(*args[0]) - err(*args[1])) / (2 * eps)
        np.testing.assert_allclose(J[:, k], num, atol=2e-6)


def test_gauss_markov_bridge_is_the_conditional_of_the_stationary_process():
    """The folded fix's GNSS error given the two nodes' errors: the weights and variance of the
    factor against Gaussian conditioning of the stationary process's joint covariance
    (Cov(g(a), g(b)) = sigma^2 exp(-|a - b| / tau))."""
    from importlib import import_module

    bridge = import_module("gnssacc.factors.preintegrated_position_factor")._bridge
    tau, sigma, T = np.array([5.0, 47.0, 300.0]), np.array([0.3, 0.5, 2.0]), 0.4
    for s in (0.05, 0.2, 0.35):
        A, K, var = bridge(s, tau, sigma, T)
        for ax in range(3):
            times = np.array([0.0, T, s])
            C = sigma[ax] ** 2 * np.exp(-np.abs(times[:, None] - times[None, :]) / tau[ax])
            w = np.linalg.solve(C[:2, :2], C[:2, 2])
            np.testing.assert_allclose([A[ax], K[ax]], w, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(var[ax], C[2, 2] - C[2, :2] @ w, rtol=1e-6, atol=1e-15)


def test_folded_fix_factor_predicts_the_true_antenna_from_a_perfect_imu():
    """On a simulated drive with a perfect IMU (its samples are the true interval averages), the
    true state at a node carried 0.45 s ahead by the preintegrated samples lands on the true
    antenna: the error is the integration's discretisation only (a car's jerk of ~1 m/s^3 over
    10 ms samples: millimetres over half a second), far below any fix's sigma."""
    run = simulate(
        "car",
        40.0,
        imu_grade="perfect",
        noise="none",
        seed=2,
        truth_rate_hz=100.0,
        lever_arm_b=tuple(LEVER),
    )
    o, tr, imu = run.origin, run.truth, run.imu
    p_true = o.to_ned(tr.lat, tr.lon, tr.h)
    g = float(normal_gravity(o.lat0, o.h0))
    worst = 0.0
    for i0 in range(500, 3500, 250):  # nodes at 5 .. 35 s
        i1 = i0 + 45
        k0 = int(np.searchsorted(imu.t, tr.t[i0], side="right"))
        k1 = int(np.searchsorted(imu.t, tr.t[i1], side="right"))
        pim = _pim(
            imu.f_b[k0:k1],
            imu.omega_ib_b[k0:k1],
            float(np.median(np.diff(imu.t))),
            gtsam.imuBias.ConstantBias(),
            g=g,
            omega=earth_rate_n(o.lat0),
        )
        R0 = euler_to_dcm(*tr.rpy[i0])
        pose = gtsam.Pose3(gtsam.Rot3(R0), p_true[i0])
        R1 = euler_to_dcm(*tr.rpy[i1])
        ant = p_true[i1] + R1 @ LEVER
        e = _error(pim, pose, tr.v_n[i0], gtsam.imuBias.ConstantBias(), ant, LEVER)
        worst = max(worst, float(np.linalg.norm(e)))
    assert worst < 0.01


def test_fixes_taken_as_nodes():
    rng = np.random.default_rng(1)
    t20 = np.arange(0.0, 30.0, 0.05) + rng.uniform(-0.004, 0.004, 600)
    keep = node_fixes(t20, 0.5)
    assert np.all(keep[::10]) and keep.sum() == 60  # every tenth fix of 20 Hz
    t1 = np.arange(0.0, 30.0, 1.0) + rng.uniform(-0.1, 0.1, 30)
    assert np.all(node_fixes(t1, 0.5))  # 1 Hz with jitter: all of them
    t2 = np.arange(0.0, 30.0, 0.5) + rng.uniform(-0.05, 0.05, 60)
    assert np.all(node_fixes(t2, 0.5))  # as fast as the spacing: all
    gap = np.concatenate([np.arange(0.0, 10.0, 0.05), np.arange(10.37, 20.0, 0.05)])
    keep = node_fixes(gap, 0.5)
    assert keep[np.searchsorted(gap, 10.37)] and keep.sum() == 40
    assert np.all(node_fixes(t20, 0.0))


def _smoothed(run, methods, spacings, **over):
    cfg = load_config(None, overrides=over or None)
    prep = pipeline.prepare(run, cfg, "none", methods)
    base = SmootherSettings.from_config(prep.cfg)
    return prep, {
        (m, sp): estimate(prep, replace(base, min_node_spacing_s=sp), m)[m]
        for m in methods
        for sp in spacings
    }


def test_one_hertz_fixes_keep_a_node_each_and_the_same_estimates():
    run = simulate("car", 120.0, seed=5)
    _, sols = _smoothed(run, ["smoother", "smoother-acc"], (0.5, 0.0))
    for m in ("smoother", "smoother-acc"):
        a, b = sols[(m, 0.5)], sols[(m, 0.0)]
        assert a.stats["n_gps_folded"] == 0 and a.stats["n_nodes"] == b.stats["n_nodes"]
        for name in ("t", "lat", "lon", "h", "v_n", "rpy", "b_a", "b_g", "sigma"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize(
    "method,gm",
    [("smoother", False), ("smoother-acc", False), ("smoother", True)],
    ids=["smoother", "smoother-acc", "gauss-markov"],
)
@pytest.mark.slow
def test_twenty_hertz_fixes_folded_give_the_estimates_of_a_node_per_fix(method, gm):
    """Nodes every 0.5 s with the 9 fixes between them folded in, against a node at each of the
    fixes: at the common nodes every state within one sigma of the other's estimate (the same
    information: they differ by the IMU noise correlation the folded factors leave out and, for
    -acc, the acceleration windows over the nodes' fixes)."""
    # (the car for the Gauss-Markov fixes: on the slow UGV their 2.5 m wander reads as a unit error)
    # (fixes only: 20 Hz white Doppler velocities folded 9 to a node leave out the IMU noise they
    # share, which their precision makes visible, up to 2 sigma in pitch; test_gnss_velocity checks
    # folded velocities at 5 Hz)
    run = simulate(
        "car" if gm else "ugv-slow",
        60.0,
        gnss_rate_hz=20.0,
        seed=7,
        noise="gm" if gm else "white",
        velocity=False,
    )
    over: dict = (
        {"gnss": {"gm_sigma_m": [2.5, 2.5, 4.0], "gm_tau_s": 60.0}} if gm else {}
    )  # the simulator's
    # The equivalence does not depend on the lag: at 10 s a node per 20 Hz fix keeps 200 nodes in
    # the window instead of the default 20 s's 400 (half the test's time).
    over["smoother"] = {"lag_s": 10.0}
    prep, sols = _smoothed(run, [method], (0.5, 0.0), **over)
    a, b = sols[(method, 0.5)], sols[(method, 0.0)]
    assert (
        a.stats["n_gps_folded"] > 0.85 * len(run.gnss.t)
        and a.stats["n_nodes"] < 0.12 * b.stats["n_nodes"]
    )
    common, ia, ib = np.intersect1d(a.t, b.t, return_indices=True)
    assert len(common) == len(a.t)  # the folded layout's nodes are nodes of the other
    o = prep.run.origin
    d_pos = o.to_ned(a.lat[ia], a.lon[ia], a.h[ia]) - o.to_ned(b.lat[ib], b.lon[ib], b.h[ib])
    d_att = (a.rpy[ia] - b.rpy[ib] + np.pi) % (2 * np.pi) - np.pi
    diff = np.hstack(
        [d_pos, a.v_n[ia] - b.v_n[ib], d_att, a.b_a[ia] - b.b_a[ib], a.b_g[ia] - b.b_g[ib]]
    )
    assert np.all(np.abs(diff) <= b.sigma[ib])


@pytest.mark.slow
def test_folded_smoother_sigmas_are_consistent_with_its_errors():
    """With 20 Hz fixes folded into 2 Hz nodes, the normalised position errors of the fixed-lag
    estimate against the truth (after 30 s) have a mean square per axis near 1: the band and the
    runs of test_smoother's consistency test for a node per fix."""
    zs = []
    for seed in (0, 1):
        run = simulate(
            "car", 240.0, imu_grade="industrial", noise="white", seed=seed, gnss_rate_hz=20.0
        )
        prep, sols = _smoothed(run, ["smoother"], (0.5,))
        sol = sols[("smoother", 0.5)]
        assert sol.stats["n_gps_folded"] > 0.85 * len(run.gnss.t)
        p_true, valid = truth_at(prep.run, sol.t)
        zs.append(
            (
                (prep.run.origin.to_ned(sol.lat, sol.lon, sol.h) - p_true)[valid]
                / sol.sigma[valid, POS]
            )[60:]
        )
    msq = np.mean(np.concatenate(zs) ** 2, axis=0)
    assert np.all(msq > 0.3) and np.all(msq < 3.0), msq


@pytest.mark.parametrize("gm", [False, True], ids=["white", "gauss-markov"])
@pytest.mark.slow
def test_folded_fixes_with_wheel_odometry_and_the_constraint_on_the_nodes(gm):
    """Wheel odometry and the non-holonomic constraint with 10 Hz fixes folded into 2 Hz nodes:
    the aids go on the folded layout's nodes, one odometry sample per node with its scale factor
    on every node, and the estimates agree with a node per fix within one sigma at the common
    nodes. The odometry is used every 0.5 s ([odometry] interval_s), so that both layouts have a
    node at each sample used (the aids are not folded: at the default 0.2 s a node per fix would
    use 2.5 times as many samples, and its estimates differ by more than the folded fixes')."""
    run = simulate(  # fixes only: see test_twenty_hertz_fixes_folded_give_the_estimates_...
        "car",
        60.0,
        gnss_rate_hz=10.0,
        odom_hz=10.0,
        seed=2,
        noise="gm" if gm else "white",
        velocity=False,
    )
    over = (
        {"gnss": {"gm_sigma_m": [2.5, 2.5, 4.0], "gm_tau_s": 60.0}} if gm else {}
    )  # the simulator's
    over["odometry"] = {"interval_s": 0.5}
    prep, sols = _smoothed(run, ["smoother"], (0.5, 0.0), **over)
    a, b = sols[("smoother", 0.5)], sols[("smoother", 0.0)]
    n = a.stats["n_nodes"]
    assert a.stats["n_gps_folded"] > 0.75 * len(run.gnss.t) and n < 0.25 * b.stats["n_nodes"]
    assert 0.9 * (n - 1) <= a.stats["n_odo_factors"] + a.stats["n_odo_skipped_sign"] <= n - 1
    assert (
        0
        < a.stats["n_nhc_factors"] + a.stats["n_nhc_skipped_rest"] + a.stats["n_nhc_skipped_turn"]
        <= n - 1
    )
    common, ia, ib = np.intersect1d(a.t, b.t, return_indices=True)
    assert len(common) == len(a.t)
    o = prep.run.origin
    d_pos = o.to_ned(a.lat[ia], a.lon[ia], a.h[ia]) - o.to_ned(b.lat[ib], b.lon[ib], b.h[ib])
    d_att = (a.rpy[ia] - b.rpy[ib] + np.pi) % (2 * np.pi) - np.pi
    diff = np.hstack(
        [d_pos, a.v_n[ia] - b.v_n[ib], d_att, a.b_a[ia] - b.b_a[ib], a.b_g[ia] - b.b_g[ib]]
    )
    assert np.all(np.abs(diff) <= b.sigma[ib])


EVERY_STATE = """
from gnssacc import pipeline
from gnssacc.core.config import load_config
from gnssacc.sources.sim import simulate

run = simulate("car", 30.0, gnss_rate_hz=5.0, odom_hz=10.0, seed=3)
cfg = load_config(None, overrides={"gnss": {"gm_sigma_m": 0.5, "gm_tau_s": 60.0}})
_, sols, _ = pipeline.compare(run, cfg, ["smoother-accw"], tune="none")
s = sols["smoother-accw"].stats
print(s["n_gps_folded"], s["n_odo_factors"], s["n_acc_factors"])
"""


def test_folded_fixes_with_every_extra_state_and_window_factors_run():
    """Folded fixes, Gauss-Markov GNSS error and odometry scale states on every node (five
    variables a node) and the window-consistent acceleration factors, which touch only the poses
    of their oldest node: the smoother runs to the end (the ordering groups handed to iSAM2 once
    outnumbered the variables it re-eliminated, and CCOLAMD corrupted memory: an abort, hence
    the separate process)."""
    out = subprocess.run(
        [sys.executable, "-c", EVERY_STATE], capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert all(int(c) > 0 for c in out.stdout.split())


def test_bridge_covariance_is_the_conditional_of_the_stationary_process_at_several_times():
    """The joint covariance of the Gauss-Markov error at the folded fixes' times given the two
    nodes' values, against Gaussian conditioning of the stationary process's covariance
    (Cov(g(a), g(b)) = sigma^2 exp(-|a - b| / tau)), per axis and across axes (independent)."""
    from gnssacc.factors import bridge_covariance

    tau, sigma, T = np.array([4.9, 47.0, 300.0]), np.array([0.28, 0.5, 0.0]), 0.5
    s = np.array([0.05, 0.1, 0.25, 0.45])
    got = bridge_covariance(s, tau, sigma, T)
    times = np.concatenate([[0.0, T], s])
    for ax in range(3):
        C = sigma[ax] ** 2 * np.exp(-np.abs(times[:, None] - times[None, :]) / tau[ax])
        cond = C[2:, 2:] - C[2:, :2] @ np.linalg.solve(C[:2, :2] + 1e-300 * np.eye(2), C[:2, 2:])
        if sigma[ax] == 0.0:
            cond = np.zeros_like(cond)
        np.testing.assert_allclose(got[ax::3, ax::3], cond, rtol=1e-6, atol=1e-14)
    off = got.copy()
    for ax in range(3):
        off[ax::3, ax::3] = 0.0
    assert not off.any()  # the axes are independent


def _joint_setup(m: int):
    """A node's state, a bias and ``m`` fixes 0.05 s apart after it, each with its preintegration
    (turning, accelerating samples)."""
    rng = np.random.default_rng(9)
    f_b = np.array([0.8, 0.3, -9.7]) + 0.3 * rng.normal(size=(10 * m, 3))
    w_b = np.array([0.02, -0.01, 0.25]) + 0.05 * rng.normal(size=(10 * m, 3))
    bias_hat = gtsam.imuBias.ConstantBias(np.array([0.02, 0.0, -0.01]), np.array([1e-3, 0, 0]))
    pims = [_pim(f_b[: 5 * (k + 1)], w_b[: 5 * (k + 1)], 0.01, bias_hat) for k in range(m)]
    pose = gtsam.Pose3(gtsam.Rot3(euler_to_dcm(0.05, -0.1, 2.0)), np.array([12.0, -3.0, 0.5]))
    vel = np.array([6.0, -2.0, 0.1])
    bias = gtsam.imuBias.ConstantBias(np.array([0.05, -0.03, 0.02]), np.array([2e-3, -1e-3, 5e-4]))
    z = np.array([12.0, -3.0, 0.5]) + 0.3 * np.arange(1, m + 1)[:, None] * np.array(
        [1.0, -0.3, 0.0]
    )
    covs = [np.diag([1e-4, 2e-4, 4e-4]) * (k + 1) for k in range(m)]
    R_fs = [euler_to_dcm(0.05, -0.1, 2.0 + 0.01 * k) for k in range(m)]
    gm = (np.array([4.9, 30.0, 5.0]), np.array([0.28, 0.3, 0.5]), 0.5)
    values = gtsam.Values()
    values.insert(X(0), pose)
    values.insert(V(0), vel)
    values.insert(B(0), bias)
    values.insert(G(0), np.array([0.4, -0.7, 1.1]))
    values.insert(G(1), np.array([0.5, -0.6, 0.9]))
    return pims, z, covs, R_fs, gm, values


def test_joint_folded_factor_stacks_the_single_ones_with_the_bridges_joint_covariance():
    """The fixes of one interval in one factor: the error and the Jacobians of each fix are those
    of its own factor, the covariance's diagonal blocks too, and between two fixes the bridge's
    covariance; the Jacobians by finite differences on the manifold."""
    from gnssacc.factors import bridge_covariance, preintegrated_positions_factor

    m = 4
    pims, z, covs, R_fs, gm, values = _joint_setup(m)
    keys = (X(0), V(0), B(0), G(0), G(1))
    joint = preintegrated_positions_factor(keys, pims, z, LEVER, covs, R_fs, gm)
    singles = [
        preintegrated_position_factor(keys, pims[k], z[k], LEVER, covs[k], R_fs[k], gm)
        for k in range(m)
    ]
    np.testing.assert_allclose(
        joint.unwhitenedError(values),
        np.concatenate([f.unwhitenedError(values) for f in singles]),
        atol=1e-12,
    )
    cov = joint.noiseModel().covariance()
    s = np.array([p.deltaTij() for p in pims])
    bridge = bridge_covariance(s, *gm)
    for a in range(m):
        for b in range(m):
            block = cov[3 * a : 3 * a + 3, 3 * b : 3 * b + 3]
            if a == b:
                np.testing.assert_allclose(
                    block, singles[a].noiseModel().covariance(), rtol=1e-9, atol=1e-15
                )
            else:
                np.testing.assert_allclose(
                    block, bridge[3 * a : 3 * a + 3, 3 * b : 3 * b + 3], rtol=1e-9, atol=1e-15
                )
    assert np.abs(bridge[0, 3]) > 0.5 * np.sqrt(bridge[0, 0] * bridge[3, 3])  # far from independent

    def unwhitened_jacobian(factor):
        A, _ = factor.linearize(values).jacobian()
        L = np.linalg.cholesky(np.linalg.inv(factor.noiseModel().covariance()))
        return np.linalg.solve(L.T, A)

    J = unwhitened_jacobian(joint)
    np.testing.assert_allclose(J, np.vstack([unwhitened_jacobian(f) for f in singles]), atol=1e-9)
    pose, vel, bias = values.atPose3(X(0)), values.atVector(V(0)), values.atConstantBias(B(0))
    g0, g1 = values.atVector(G(0)), values.atVector(G(1))

    def err(d):
        v = gtsam.Values()
        v.insert(X(0), pose.retract(d[0:6]))
        v.insert(V(0), vel + d[6:9])
        v.insert(B(0), bias.retract(d[9:15]))
        v.insert(G(0), g0 + d[15:18])
        v.insert(G(1), g1 + d[18:21])
        return joint.unwhitenedError(v)

    eps = 1e-6
    for k in range(21):
        d = np.zeros(21)
        d[k] = eps
        np.testing.assert_allclose(J[:, k], (err(d) - err(-d)) / (2 * eps), atol=2e-6)
