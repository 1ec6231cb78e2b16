"""The smoother's start: the joint prior factor's Jacobians on the manifold (finite differences), and
the EKF-to-GTSAM mapping of the initial covariance (``smoother.initial_prior``) against a sampled
transform: EKF error states drawn from the EKF's own initial covariance, each turned into the true
state by the EKF's documented error convention and then into the prior factor's error (GTSAM's
``Rot3.Logmap`` of the rotation, the translation in the prior's body axes); the sample covariance
must equal the mapped one within a likelihood-ratio (Wishart) bound. And the reason the error is
not ``Pose3.Logmap``: a position that moves from the prior's along a direction the prior ties to
the GNSS error must not tell the heading."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gnssacc.factors import joint_prior_factor
from gtsam.symbol_shorthand import B, G, X
from scipy.stats import chi2

from gnssacc.core.config import load_config
from gnssacc.core.earth import LocalTangentFrame, radii
from gnssacc.core.recording import InitialState
from gnssacc.core.rotations import euler_to_dcm, rotvec_to_dcm
from gnssacc.estimators.state import initial_state
from gnssacc.estimators.settings import SmootherSettings
from gnssacc.estimators.aids.gnss_position import gnss_error_states
from gnssacc.estimators.layout import StateLayout
from gnssacc.estimators.smoother_graph import initial_prior

POSE0 = gtsam.Pose3(gtsam.Rot3(euler_to_dcm(0.1, -0.2, 2.4)), np.array([12.0, -3.0, 1.5]))
BIAS0 = np.array([0.02, -0.01, 0.03, 1e-3, -2e-3, 5e-4])
G0_PRIOR = np.array([0.4, -0.3, 1.1])


def _values(pose, bias, g):
    v = gtsam.Values()
    v.insert(X(0), pose)
    v.insert(B(0), gtsam.imuBias.ConstantBias(bias[:3], bias[3:]))
    if g is not None:
        v.insert(G(0), g)
    return v


@pytest.mark.parametrize("with_gm", [False, True])
def test_joint_prior_jacobians_by_finite_differences_on_the_manifold(with_gm):
    m = 15 if with_gm else 12
    rng = np.random.default_rng(3)
    L = rng.standard_normal((m, m))
    cov = L @ L.T + np.eye(m)
    f = joint_prior_factor(
        X(0), B(0), G(0) if with_gm else None, POSE0, BIAS0, G0_PRIOR if with_gm else None, cov
    )
    # Far from the prior (0.5 rad, metres), where LogmapDerivative differs clearly from identity.
    xi = np.array([0.3, -0.25, 0.3, 2.0, -1.0, 0.5])
    pose = POSE0.compose(gtsam.Pose3.Expmap(xi))
    bias = BIAS0 + np.array([0.01, 0.02, -0.01, 1e-4, 2e-4, -3e-4])
    g = G0_PRIOR + np.array([0.5, -0.2, 0.1]) if with_gm else None
    values = _values(pose, bias, g)
    # The error at a known offset: the rotation vector and the translation of Expmap(xi) in the
    # prior's axes, and the bias and GNSS offsets.
    e = f.unwhitenedError(values)
    np.testing.assert_allclose(e[0:3], xi[0:3], atol=1e-12)
    np.testing.assert_allclose(e[3:6], gtsam.Pose3.Expmap(xi).translation(), atol=1e-12)
    np.testing.assert_allclose(e[6:12], bias - BIAS0, atol=1e-15)
    if with_gm:
        np.testing.assert_allclose(e[12:15], g - G0_PRIOR, atol=1e-15)
    # The linearised factor (whitened) back to unwhitened Jacobians, against central differences
    # of the factor's own error under GTSAM's retraction of each variable.
    A, _ = f.linearize(values).jacobian()
    Lw = np.linalg.cholesky(np.linalg.inv(cov))
    J = np.linalg.solve(Lw.T, A)
    eps = 1e-6
    col = 0
    for var, dim in ((0, 6), (1, 6)) + (((2, 3),) if with_gm else ()):
        for k in range(dim):
            d = np.zeros(dim)
            d[k] = eps
            args_p, args_m = [pose, bias, g], [pose, bias, g]
            if var == 0:
                args_p[0], args_m[0] = pose.retract(d), pose.retract(-d)
            else:
                args_p[var], args_m[var] = args_p[var] + d, args_m[var] - d
            num = (f.unwhitenedError(_values(*args_p)) - f.unwhitenedError(_values(*args_m))) / (
                2 * eps
            )
            np.testing.assert_allclose(
                J[:, col], num, atol=1e-8, err_msg=f"variable {var}, column {k}"
            )
            col += 1


# --- the EKF-to-GTSAM covariance mapping ---------------------------------------------------------

LAT, LON, H = np.radians(47.3), np.radians(8.5), 420.0


def _start(with_gm: bool):
    """A self-initialised start: levelled (tilt tied to the accelerometer bias) and, with the GNSS
    error modelled, a position fitted to the fixes (tied to the GNSS error). Small roll/pitch sigmas
    make the tilt almost entirely the bias's image, so the correlation signs matter."""
    init = InitialState(
        t=0.0,
        lat=LAT,
        lon=LON,
        h=H,
        v_n=np.array([3.0, -1.0, 0.1]),
        rpy=np.array([0.05, -0.08, 2.0]),
        sigma_pos_m=np.array([0.8, 0.9, 1.5]),
        sigma_vel_mps=np.array([0.1, 0.12, 0.2]),
        sigma_att_rad=np.array([1e-3, 1.5e-3, 0.05]),
        b_a=np.array([0.01, -0.02, 0.005]),
        b_g=np.array([1e-4, -2e-4, 5e-5]),
        sigma_b_a=np.array([0.05, 0.04, 0.06]),
        sigma_b_g=np.array([2e-4, 3e-4, 1e-4]),
        fit_window=(0.0, 5.0),
        levelled=True,
    )
    gnss = {"gm_sigma_m": [2.5, 2.0, 4.0]} if with_gm else {}
    return init, load_config(overrides={"gnss": gnss} if gnss else None)


def _smoother_error(init, origin, pose0, dx):
    """Prior-factor error and velocity offset of the truth that is ``dx`` away from the start,
    under the EKF's convention (estimate minus truth; ``R_est = Exp(phi) R_true``; the bias states
    are what is left after the estimate, ``b_true = b_est + db``; GNSS error estimate minus truth)."""
    R_M, R_N = radii(init.lat)
    lat = init.lat - dx[0] / (R_M + init.h)
    lon = init.lon - dx[1] / ((R_N + init.h) * np.cos(init.lat))
    h = init.h + dx[2]
    R_true = rotvec_to_dcm(-dx[6:9]) @ init.R_nb
    truth = gtsam.Pose3(gtsam.Rot3(R_true), origin.to_ned(lat, lon, h))
    rel = pose0.between(truth)
    e = [gtsam.Rot3.Logmap(rel.rotation()), rel.translation(), dx[9:15]]  # b_true - b0 = db
    if len(dx) > 15:
        e.append(-dx[15:18])  # g_true - g0, g0 = 0
    e.append(-dx[3:6])  # v_true - v0
    return np.concatenate(e)


def _lr_statistic(samples: np.ndarray, C: np.ndarray) -> tuple[float, int]:
    """Likelihood-ratio statistic of ``Cov = C`` for zero-mean samples, ``N (tr A - log det A - p)``,
    ``A = C^-1 S``; chi-square with ``p (p + 1) / 2`` dof under the hypothesis (Anderson, 2003, 10.8)."""
    n, p = samples.shape
    S = samples.T @ samples / n
    A = np.linalg.solve(C, S)
    return n * (np.trace(A) - np.linalg.slogdet(A)[1] - p), p * (p + 1) // 2


@pytest.mark.parametrize("with_gm", [False, True])
def test_initial_prior_covariance_matches_the_sampled_nonlinear_transform(with_gm):
    init, cfg = _start(with_gm)
    cfg = SmootherSettings.from_config(cfg)
    layout = StateLayout.build(gnss_error_states(cfg))
    P = initial_state(init, cfg, layout).P
    assert P.shape[0] == (18 if with_gm else 15)
    origin = LocalTangentFrame(LAT + 1e-5, LON - 2e-5, H - 3.0)  # the run's origin, near the start
    pose0 = gtsam.Pose3(gtsam.Rot3(init.R_nb), origin.to_ned(init.lat, init.lon, init.h))
    cov, c_vel = initial_prior(init, cfg, layout)
    m = cov.shape[0]
    C = np.zeros((m + 3, m + 3))
    C[:m, :m], C[m:, m:] = cov, c_vel  # velocity: uncorrelated with the rest
    rng = np.random.default_rng(11)
    n = 10000
    dx = rng.standard_normal((n, P.shape[0])) @ np.linalg.cholesky(P).T
    e = np.array([_smoother_error(init, origin, pose0, d) for d in dx])
    stat, dof = _lr_statistic(e, C)
    # False-failure rate 1e-3 under a correct mapping (the transform is linear to ~1e-4 relative at
    # these sigmas; its bias is far below the 1/sqrt(n) sampling scatter).
    assert stat < chi2.ppf(1 - 1e-3, dof), (stat, chi2.ppf(1 - 1e-3, dof))
    # The test has power where it matters: the tilt/bias (and position/GNSS-error) correlations
    # are strong, so flipping their sign is far outside the bound.
    corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    assert np.max(np.abs(corr[0:3, 6:9])) > 0.8
    if with_gm:
        assert np.max(np.abs(corr[3:6, 12:15])) > 0.8


def test_a_position_off_the_prior_does_not_tell_the_heading():
    """A still start: the position known to a metre, its sum with the GNSS error to a centimetre.
    With the pose 1 m from the prior's position (the GNSS error the opposite way) and fixes that
    pin that sum, the heading stays as free as the prior says: the marginal information on yaw of
    the linearised prior and fixes equals the prior's. (``Pose3.Logmap``'s translation turns with
    the rotation by ``-w x t / 2``: there, the fixes and the prior together "measured" the yaw.)"""
    sig_p, sig_sum, sig_yaw = 1.0, 0.01, np.radians(6.0)
    cov = np.diag(
        np.r_[1e-6, 1e-6, sig_yaw**2, np.full(3, sig_p**2), np.full(6, 1e-4), np.zeros(3)]
    )
    cov[12:15, 12:15] = np.eye(3) * (sig_p**2 + sig_sum**2)
    cov[3:6, 12:15] = cov[12:15, 3:6] = -np.eye(3) * sig_p**2  # R0 = I: body = NED
    pose0 = gtsam.Pose3(gtsam.Rot3(), np.zeros(3))
    f = joint_prior_factor(X(0), B(0), G(0), pose0, np.zeros(6), np.zeros(3), cov)
    shift = np.array([1.0, 0.0, 0.0])
    values = _values(gtsam.Pose3(gtsam.Rot3(), shift), np.zeros(6), -shift)
    A, _ = f.linearize(values).jacobian()  # columns: rotation, translation, bias, GNSS error
    fix = np.zeros((3, 15))  # the fixes: position + GNSS error, to 1 cm (R = I)
    fix[:, 3:6], fix[:, 12:15] = np.eye(3) / 0.01, np.eye(3) / 0.01
    info = A.T @ A + fix.T @ fix
    marginal_yaw = 1.0 / np.linalg.inv(info + 1e-9 * np.eye(15))[2, 2]
    assert marginal_yaw == pytest.approx(1.0 / sig_yaw**2, rel=1e-3)
