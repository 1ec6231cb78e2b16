"""The EKF's compiled per-update kernels against independent references: the fused multiply-add
against exact rational arithmetic, the 3 x 3 products against exact sums, the aids' compiled
position and vehicle-velocity models against plain numpy transcriptions of their module notes'
formulas, and a whole EKF pass on a simulated car (fixes with a lever arm and the Gauss-Markov
fix error, the non-holonomic constraint with a mounting rotation) against the same pass with
those numpy transcriptions in place of the kernels."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from numba import njit

from gnssacc.core.config import load_config
from gnssacc.core.earth import earth_rate_n, radii
from gnssacc.core.rotations import euler_to_dcm, skew
from gnssacc.estimators import small_linalg
from gnssacc.estimators.aids import gnss_position, vehicle
from gnssacc.estimators.layout import ATT, BG, GNSS_ERROR, POS, VEL, MarkovBlock, StateLayout
from gnssacc.estimators.state import FilterState
from gnssacc.prepare.passes import run_ekf
from gnssacc.sources.sim import simulate

EPS = np.finfo(float).eps


def _exact_dot(a, b) -> Fraction:
    return sum((Fraction(float(x)) * Fraction(float(y)) for x, y in zip(a, b)), Fraction(0))


def test_fma_rounds_once():
    """``fma(a, b, c)`` is the exact ``a b + c`` rounded to the nearest double."""
    rng = np.random.default_rng(0)
    for a, b, c in rng.normal(size=(2000, 3)) * rng.uniform(1e-3, 1e3, size=(2000, 3)):
        exact = Fraction(a) * Fraction(b) + Fraction(c)
        assert small_linalg_fma(a, b, c) == float(exact)


@njit
def small_linalg_fma(a, b, c):
    """The intrinsic, called through a compiled function (an intrinsic is not callable from
    Python)."""
    return small_linalg.fma(a, b, c)


@pytest.mark.parametrize("order", ["C", "F"])
def test_products_within_rounding_of_exact(order):
    """``A @ B`` and ``A @ v`` of the kernels: within two roundings of the exact sums (and of
    numpy's own products, which round as often)."""
    rng = np.random.default_rng(1)
    for _ in range(300):
        A = np.asarray(rng.normal(size=(3, 3)), order=order)
        B, v = rng.normal(size=(3, 5)), rng.normal(size=3)
        out = np.zeros((3, 7))
        small_linalg.matmul_into(A, B, out, 2)
        mv = small_linalg.matvec(A, v, small_linalg.rows_contiguous(A))
        for r in range(3):
            scale = float(np.abs(A[r]) @ np.abs(v))
            assert abs(mv[r] - float(_exact_dot(A[r], v))) <= 2 * EPS * scale
            for c in range(5):
                scale = float(np.abs(A[r]) @ np.abs(B[:, c]))
                assert abs(out[r, 2 + c] - float(_exact_dot(A[r], B[:, c]))) <= 2 * EPS * scale
        assert np.allclose(out[:, 2:], A @ B, rtol=0, atol=4 * EPS * np.abs(A).sum() * 3)
        assert not out[:, :2].any()


def _numpy_position_model(pos, R_nb, lever_b, lat, lon, h, gm, i_gm, n):
    """gnss_position's module notes in numpy: ``dz = p_ant,est (+ x_g) - p_fix`` [m, NED],
    ``H = [I, 0, -[(R l) x], 0, 0 (, I)]``."""
    R_M, R_N = radii(pos[0])
    l_n = R_nb @ lever_b
    dz = (
        np.array(
            [
                (pos[0] - lat) * (R_M + pos[2]),
                (pos[1] - lon) * (R_N + pos[2]) * np.cos(pos[0]),
                -(pos[2] - h),
            ]
        )
        + l_n
    )
    H = np.zeros((3, n))
    H[:, POS] = np.eye(3)
    H[:, ATT] = -skew(l_n)
    if i_gm >= 0:
        dz = dz + gm
        H[:, i_gm : i_gm + 3] = np.eye(3)
    return dz, H


def _numpy_vehicle_model(R_nb, v_n, b_g, omega_meas_b, lever_b, w_ie_n, R_vb, vb_rows, n):
    """vehicle's module notes in numpy: ``v_l = R^T v + (omega - b_g - R^T w_ie) x l`` and
    ``H_v = [0, R^T, R^T [v x] + [l x] R^T [w_ie x], 0, -[l x]]``, turned by ``R_vb``."""
    Rt = R_nb.T
    w_ie_b = Rt @ w_ie_n
    v_b = Rt @ v_n + np.cross(omega_meas_b - b_g - w_ie_b, lever_b)
    H = np.zeros((3, n))
    H[:, VEL] = Rt
    H[:, ATT] = Rt @ skew(v_n) + skew(lever_b) @ Rt @ skew(w_ie_n)
    H[:, BG] = -skew(lever_b)
    return R_vb @ v_b, R_vb @ H


def _state(rng, gm: bool) -> FilterState:
    layout = StateLayout.build([MarkovBlock(GNSS_ERROR, np.ones(3), np.ones(3))] if gm else [])
    return FilterState(
        np.array([rng.uniform(-1.2, 1.2), rng.uniform(-3, 3), rng.uniform(-50, 2000)]),
        rng.normal(size=3) * 10,
        euler_to_dcm(*rng.uniform(-np.pi, np.pi, 3) * [0.3, 0.3, 1.0]),
        np.zeros(3),
        rng.normal(size=3) * 1e-3,
        np.eye(layout.n),
        rng.normal(size=layout.n - layout.nav),
        layout,
    )


def test_models_match_their_formulas():
    """The compiled models equal the module notes' formulas in numpy (to rounding), with and
    without a lever arm, the Gauss-Markov fix error and a mounting rotation."""
    rng = np.random.default_rng(2)
    for i in range(200):
        s = _state(rng, gm=i % 2 == 0)
        lever = rng.normal(size=3) if i % 3 else np.zeros(3)
        lay = s.layout
        fix = (s.pos[0] + 1e-6 * rng.normal(), s.pos[1] + 1e-6 * rng.normal(), s.pos[2] + 3.0)
        args = (s.pos, s.R_nb, lever, *fix, s.gm, lay.offset(GNSS_ERROR), lay.n)
        for got, ref in zip(gnss_position.position_model(*args), _numpy_position_model(*args)):
            assert np.allclose(got, ref, rtol=1e-12, atol=1e-9)
        R_vb = euler_to_dcm(0.0, 0.02, -0.01) if i % 4 else np.eye(3)
        args = (s.R_nb, s.v_n, s.b_g, rng.normal(size=3) * 0.1, lever, earth_rate_n(s.pos[0]))
        got = vehicle.vehicle_model(*args, R_vb, i % 3 == 0, lay.n)
        ref = _numpy_vehicle_model(*args, R_vb, True, lay.n)
        for g, r in zip(got, ref):
            assert np.allclose(g, r, rtol=1e-12, atol=1e-13)


def test_pass_with_compiled_models_equals_numpy_reference(monkeypatch):
    """A whole EKF pass with the compiled models gives the numbers of the same pass with the
    numpy transcriptions in their place (to rounding: numpy's BLAS may sum in another order)."""
    cfg = load_config(
        overrides={
            "gnss": {"lever_arm_b_m": [0.4, -0.2, -1.1], "gm_sigma_m": 0.5, "gm_tau_s": 60.0},
            "nhc": {"enabled": True, "pitch_offset_deg": 1.0, "yaw_offset_deg": -0.5},
        }
    )
    run = simulate(
        "car", 120.0, imu_grade="industrial", seed=3, lever_arm_b=(0.4, -0.2, -1.1), give_init=True
    )
    fast = run_ekf(run, cfg, "ekf")
    monkeypatch.setattr(gnss_position, "position_model", _numpy_position_model)
    monkeypatch.setattr(vehicle, "vehicle_model", _numpy_vehicle_model)
    ref = run_ekf(run, cfg, "ekf")
    assert fast.stats["n_pos_updates"] == ref.stats["n_pos_updates"] > 100
    assert fast.stats["n_nhc_updates"] == ref.stats["n_nhc_updates"] > 100
    for key in ("loglik_pos", "loglik_nhc", "nis_pos_mean", "nis_nhc_mean"):
        assert fast.stats[key] == pytest.approx(ref.stats[key], rel=1e-9)
    for a, b in ((fast.lat, ref.lat), (fast.lon, ref.lon), (fast.h, ref.h), (fast.v_n, ref.v_n)):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-9)
