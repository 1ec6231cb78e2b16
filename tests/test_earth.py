"""Earth model and frame conversions against published WGS-84 values and round trips."""

import numpy as np
import pytest

from gnssacc.core import earth
from gnssacc.core.rotations import (
    dcm_to_euler,
    dcm_to_rotvec,
    euler_error_jacobian,
    euler_to_dcm,
    rotvec_to_dcm,
    skew,
)


def test_normal_gravity_published_values():
    # WGS-84 (NIMA TR8350.2): equatorial and polar normal gravity on the ellipsoid.
    assert earth.normal_gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert earth.normal_gravity(np.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    # Free-air gradient near the surface is about -3.086e-6 s^-2.
    g0, g1 = earth.normal_gravity(np.radians(45), 0.0), earth.normal_gravity(np.radians(45), 100.0)
    assert (g1 - g0) / 100.0 == pytest.approx(-3.086e-6, rel=2e-3)


def test_radii_of_curvature():
    R_M, R_N = earth.radii(0.0)
    assert R_N == pytest.approx(earth.A)
    assert R_M == pytest.approx(earth.A * (1 - earth.E2))
    R_M, R_N = earth.radii(np.pi / 2)
    assert R_M == pytest.approx(R_N)  # at the pole both equal a^2 / b
    assert R_N == pytest.approx(earth.A**2 / earth.B)


def test_ecef_known_points():
    np.testing.assert_allclose(earth.llh_to_ecef(0.0, 0.0, 0.0), [earth.A, 0, 0], atol=1e-9)
    np.testing.assert_allclose(earth.llh_to_ecef(np.pi / 2, 0.0, 0.0), [0, 0, earth.B], atol=1e-6)
    np.testing.assert_allclose(
        earth.llh_to_ecef(0.0, np.pi / 2, 100.0), [0, earth.A + 100, 0], atol=1e-6
    )


def test_llh_ecef_round_trip():
    rng = np.random.default_rng(0)
    lat = rng.uniform(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, 200)
    lon = rng.uniform(-np.pi, np.pi, 200)
    h = rng.uniform(-400, 9000, 200)
    lat2, lon2, h2 = earth.ecef_to_llh(earth.llh_to_ecef(lat, lon, h))
    np.testing.assert_allclose(lat2, lat, atol=1e-11)
    np.testing.assert_allclose(np.angle(np.exp(1j * (lon2 - lon))), 0, atol=1e-11)
    np.testing.assert_allclose(h2, h, atol=1e-5)


def test_tangent_frame_round_trip_and_axes():
    frame = earth.LocalTangentFrame(np.radians(49.0), np.radians(8.4), 110.0)
    p = np.array([[100.0, -50.0, 3.0], [-2000.0, 1500.0, -20.0]])
    np.testing.assert_allclose(frame.to_ned(*frame.to_llh(p)), p, atol=1e-6)
    # A small step north increases latitude by dN / (R_M + h); east by dE / ((R_N + h) cos lat).
    lat, lon, h = frame.to_llh([1.0, 0.0, 0.0])
    R_M, R_N = earth.radii(np.radians(49.0))
    assert lat - np.radians(49.0) == pytest.approx(1.0 / (R_M + 110.0), rel=1e-6)
    lat, lon, h = frame.to_llh([0.0, 1.0, 0.0])
    assert lon - np.radians(8.4) == pytest.approx(
        1.0 / ((R_N + 110.0) * np.cos(np.radians(49.0))), rel=1e-6
    )
    assert frame.to_llh([0.0, 0.0, -5.0])[2] == pytest.approx(115.0, abs=1e-6)


def test_rates():
    np.testing.assert_allclose(earth.earth_rate_n(0.0), [earth.OMEGA_IE, 0, 0])
    R_M, R_N = earth.radii(0.3)
    w = earth.transport_rate_n(0.3, 0.0, np.array([10.0, 20.0, 0.0]))
    np.testing.assert_allclose(w, [20 / R_N, -10 / R_M, -20 * np.tan(0.3) / R_N])


def test_rotation_helpers():
    rng = np.random.default_rng(3)
    for _ in range(50):
        rpy = rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi])
        R = euler_to_dcm(*rpy)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(dcm_to_euler(R), rpy, atol=1e-12)
        phi = rng.normal(size=3) * rng.uniform(0, 3)
        np.testing.assert_allclose(
            dcm_to_rotvec(rotvec_to_dcm(phi)) if np.linalg.norm(phi) < np.pi else 0,
            phi if np.linalg.norm(phi) < np.pi else 0,
            atol=1e-10,
        )
    np.testing.assert_allclose(skew([1, 2, 3]) @ [4, 5, 6], np.cross([1, 2, 3], [4, 5, 6]))
    # Near-pi rotations recover the angle and the (sign-ambiguous) axis.
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    v = dcm_to_rotvec(rotvec_to_dcm(axis * (np.pi - 1e-9)))
    assert abs(abs(v @ axis) - (np.pi - 1e-9)) < 1e-6


def test_euler_error_jacobian_by_finite_differences():
    rpy = np.array([0.2, -0.3, 2.0])
    R = euler_to_dcm(*rpy)
    J = euler_error_jacobian(*rpy)
    eps = 1e-7
    for i in range(3):
        phi = np.zeros(3)
        phi[i] = eps
        d = (
            np.array(dcm_to_euler(rotvec_to_dcm(phi) @ R))
            - np.array(dcm_to_euler(rotvec_to_dcm(-phi) @ R))
        ) / (2 * eps)
        np.testing.assert_allclose(d, J[:, i], atol=1e-6)


# WGS-84 as published in NIMA TR8350.2, 3rd edition (2000), typed from the standard and not taken
# from gnssacc: Table 3.1 (defining parameters) and Table 3.3 (derived geometric and physical constants).
WGS84_A = 6378137.0  # semi-major axis [m]
WGS84_INV_F = 298.257223563  # reciprocal of flattening [-]
WGS84_OMEGA = 7292115.0e-11  # angular velocity of the earth [rad/s]
WGS84_GM = 3986004.418e8  # earth's gravitational constant [m^3/s^2]
WGS84_B = 6356752.3142  # semi-minor axis [m]
WGS84_E2 = 6.69437999014e-3  # first eccentricity squared [-]
WGS84_GAMMA_E = 9.7803253359  # normal gravity at the equator [m/s^2]
WGS84_GAMMA_P = 9.8321849378  # normal gravity at the poles [m/s^2]
WGS84_K = 0.00193185265241  # Somigliana's constant k [-]
WGS84_M = 0.00344978650684  # m = omega^2 a^2 b / GM [-]


def test_wgs84_constants_equal_the_published_values():
    assert earth.A == WGS84_A
    assert 1.0 / earth.F == pytest.approx(WGS84_INV_F, rel=1e-15)
    assert earth.OMEGA_IE == pytest.approx(WGS84_OMEGA, rel=1e-15)
    assert earth.GM == pytest.approx(WGS84_GM, rel=1e-15)
    # Derived values are published to their last printed digit.
    assert earth.B == pytest.approx(WGS84_B, abs=1e-4)
    assert earth.E2 == pytest.approx(WGS84_E2, abs=1e-14)
    assert earth.GAMMA_E == pytest.approx(WGS84_GAMMA_E, abs=1e-10)
    assert earth.SOMIGLIANA_K == pytest.approx(WGS84_K, abs=1e-14)
    assert earth.M_RATIO == pytest.approx(WGS84_M, abs=1e-14)


def _published_normal_gravity(lat, h):
    """TR8350.2 eq. 4-1 (Somigliana) and 4-3 (second-order height expansion), typed constants."""
    s2 = np.sin(lat) ** 2
    f = 1.0 / WGS84_INV_F
    g0 = WGS84_GAMMA_E * (1.0 + WGS84_K * s2) / np.sqrt(1.0 - WGS84_E2 * s2)
    return g0 * (
        1.0 - 2.0 / WGS84_A * (1.0 + f + WGS84_M - 2.0 * f * s2) * h + 3.0 * h**2 / WGS84_A**2
    )


@pytest.mark.parametrize("lat_deg, h", [(0.0, 0.0), (32.0, 50.0), (60.0, 1500.0), (-45.0, -30.0)])
def test_normal_gravity_equals_the_published_formula(lat_deg, h):
    assert earth.normal_gravity(np.radians(lat_deg), h) == pytest.approx(
        _published_normal_gravity(np.radians(lat_deg), h), abs=1e-10
    )
    assert _published_normal_gravity(np.pi / 2, 0.0) == pytest.approx(WGS84_GAMMA_P, abs=1e-9)


def test_compiled_strapdown_holds_still_under_the_published_earth_rate_and_gravity():
    """The numba kernels bake the constants in when they compile (and keep them in their cache):
    an IMU whose readings are built from the published values alone, a gyro sensing the published
    earth rate and an accelerometer the published normal gravity, must stay put for 10 minutes.
    A relative error of 1e-6 in the earth rate tilts the platform by ~4e-8 rad here, which drifts
    by centimetres; the bound is 1 mm."""
    from types import SimpleNamespace

    from gnssacc.estimators.mechanization import Propagator

    lat, lon, h = np.radians(40.0), np.radians(-3.0), 650.0
    R_nb = euler_to_dcm(0.1, 0.05, 1.0)
    n = 60001
    t = np.linspace(0.0, 600.0, n)
    w_n = WGS84_OMEGA * np.array([np.cos(lat), 0.0, -np.sin(lat)])
    f_n = np.array([0.0, 0.0, -_published_normal_gravity(lat, h)])
    z3, seg = np.zeros(3), np.zeros(0, np.int64)
    prop = Propagator(
        t,
        np.tile(R_nb.T @ f_n, (n, 1)),
        np.tile(R_nb.T @ w_n, (n, 1)),
        z3,
        z3,
        z3,
        z3,
        (seg, seg, np.zeros((0, 3)), np.zeros((0, 3))),
    )
    s = SimpleNamespace(
        pos=np.array([lat, lon, h]),
        v_n=z3.copy(),
        R_nb=R_nb.copy(),
        b_a=z3.copy(),
        b_g=z3.copy(),
        P=np.eye(15),
    )
    prop.advance(s, 1, 0.0, 600.0, with_cov=False)
    drift = earth.LocalTangentFrame(lat, lon, h).to_ned(*s.pos)
    assert np.linalg.norm(drift) < 1e-3, drift
    assert np.linalg.norm(s.v_n) < 1e-5
    assert np.max(np.abs(s.R_nb - R_nb)) < 1e-9
