"""The linear-Gaussian filter reference of GNSS-acceleration aiding (aiding_theory.kf_*): the exact
correlation-aware filter reproduces position-only; the uncorrelated one is overconfident."""

import numpy as np
import pytest
from scipy.linalg import expm

from gnssacc.analysis.aiding_theory import (
    kf_departure,
    kf_filter,
    kf_model,
    kf_monte_carlo,
    kf_simulate,
)


@pytest.mark.parametrize("dt, q", [(1.0, 1.0), (0.2, 30.0)])
def test_kf_model_is_the_exact_discretisation(dt, q):
    """Van Loan: expm([[-A, G q G^T], [0, A^T]] dt) gives F and Q independently."""
    A = np.diag([1.0, 1.0], 1)
    GQG = np.zeros((3, 3))
    GQG[2, 2] = q
    E = expm(np.block([[-A, GQG], [np.zeros((3, 3)), A.T]]) * dt)
    F_ref = E[3:, 3:].T
    F, Q = kf_model(dt, q)
    np.testing.assert_allclose(F, F_ref, atol=1e-12)
    np.testing.assert_allclose(Q, F_ref @ E[:3, 3:], rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("dt, q, R", [(1.0, 1.0, 1.0), (1.0, 10.0, 9.0), (0.2, 30.0, 4e-4)])
@pytest.mark.parametrize("accel_first", [False, True])
def test_exact_correlation_aware_filter_equals_position_only(dt, q, R, accel_first):
    """Clones with the fix noises as states: means and covariances equal position-only to 1e-9
    (relative to their scale), over runs long enough for the window to slide many times."""
    rng = np.random.default_rng(7)
    x0, P0 = np.zeros(3), np.diag([R, 1.0, 1.0])
    for _ in range(3):
        _, z = kf_simulate(80, dt, q, R, x0, P0, rng)
        a = kf_filter(z, dt, q, R, "position", x0, P0)
        c = kf_filter(z, dt, q, R, "cloned", x0, P0, accel_first)
        scale_x = np.sqrt(np.diagonal(a.P, axis1=1, axis2=2))
        assert np.max(np.abs(c.x - a.x) / scale_x) < 1e-9
        assert np.max(np.abs(c.P - a.P) / (scale_x[:, :, None] * scale_x[:, None, :])) < 1e-9
        sigma_a2 = 6.0 * R / dt**4
        if accel_first:
            # Applied first, the acceleration does carry information (that of z_k) ...
            assert np.nanmin(c.s_acc) > 1e-3 * sigma_a2
        else:
            # ... applied after the position update it is fully predicted: zero innovation variance.
            assert np.nanmax(np.abs(c.s_acc)) < 1e-9 * sigma_a2
        # The uncorrelated form changes the estimate.
        b = kf_filter(z, dt, q, R, "paper", x0, P0)
        assert np.max(np.abs(b.x - a.x) / scale_x) > 1e-3


def test_uncorrelated_acceleration_is_overconfident():
    """200 Monte-Carlo runs, an agile vehicle (jerk PSD 10 m^2/s^5, 1 Hz, R = 1 m^2): position-only
    and the exact filter are consistent, the paper's literal model (acceleration state at t_k)
    grossly overconfident, and the window-consistent but uncorrelated form overconfident."""
    r = kf_monte_carlo(runs=200, n=40, dt=1.0, q=10.0, R=1.0, seed=0)
    print({v: round(d["nees"], 3) for v, d in r.items()})
    for v in ("position", "cloned"):
        assert 0.8 < r[v]["nees"] < 1.2, (v, r[v]["nees"])
    assert r["paper-epoch"]["nees"] > 1.5
    assert r["paper"]["nees"] > 1.1
    dep = kf_departure("paper", runs=200, n=40, dt=1.0, q=10.0, R=1.0, seed=0)
    np.testing.assert_allclose(dep, r["paper"]["stated_var"] / r["paper"]["error_var"])
    ref = r["position"]["stated_var"] / r["position"]["error_var"]
    assert np.all(dep < ref) and dep[1] < 0.8


def test_known_velocity_error_is_the_running_mean_of_the_fix_errors():
    # Closed form: the floor of velocity aiding is the mean fix error so far (a filter) or up to
    # the lag (a fixed-lag smoother); between fixes it holds the last one's value.
    from gnssacc.analysis.aiding_theory import known_velocity_error

    t_fix = np.arange(5.0)
    err = np.array([[3.0, 0.0], [-1.0, 2.0], [1.0, 4.0], [-3.0, 2.0], [0.0, 2.0]])
    causal = known_velocity_error(t_fix, err, np.array([0.0, 0.5, 1.0, 2.9, 4.0]))
    np.testing.assert_allclose(causal, [[3.0, 0.0], [3.0, 0.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]])
    lagged = known_velocity_error(t_fix, err, np.array([0.0, 3.0]), lag_s=2.0)
    np.testing.assert_allclose(lagged, [[1.0, 2.0], [0.0, 2.0]])
    with pytest.raises(ValueError, match="before the first fix"):
        known_velocity_error(t_fix, err, np.array([-0.1]))


def test_known_velocity_error_falls_as_one_over_root_n_on_white_fixes():
    # Monte Carlo against the closed form: with white errors of variance s^2 the error after n
    # fixes has variance s^2 / n.
    from gnssacc.analysis.aiding_theory import known_velocity_error

    rng = np.random.default_rng(3)
    n, runs = 100, 4000
    t_fix = np.arange(float(n))
    at = np.array([0.0, 9.0, 99.0])
    e = np.stack(
        [known_velocity_error(t_fix, rng.normal(0, 3.0, (n, 1)), at)[:, 0] for _ in range(runs)]
    )
    np.testing.assert_allclose(e.var(axis=0), 9.0 / np.array([1, 10, 100]), rtol=0.08)
