"""WGS-84 earth model: radii of curvature, normal gravity, earth and transport rates,
and conversions between geodetic (LLH), ECEF and a local NED tangent plane.

All angles are radians and all lengths metres. The navigation frame n is local
North-East-Down (NED).
"""

from __future__ import annotations

import numpy as np

#: WGS-84 semi-major axis [m].
A = 6378137.0
#: WGS-84 flattening [-].
F = 1.0 / 298.257223563
#: First eccentricity squared [-].
E2 = F * (2.0 - F)
#: Semi-minor axis [m].
B = A * (1.0 - F)
#: Earth rotation rate [rad/s].
OMEGA_IE = 7.292115e-5
#: Earth gravitational constant GM [m^3/s^2].
GM = 3.986004418e14
#: Normal gravity at the equator and the Somigliana constant k (WGS-84).
GAMMA_E = 9.7803253359
SOMIGLIANA_K = 0.00193185265241
#: m = omega^2 a^2 b / GM, used in the height correction of normal gravity.
M_RATIO = OMEGA_IE**2 * A**2 * B / GM


def radii(lat):
    """Meridian and normal (prime-vertical) radii of curvature.

    Parameters
    ----------
    lat : float or ndarray
        Geodetic latitude [rad].

    Returns
    -------
    R_M, R_N : float or ndarray
        Meridian radius and normal radius [m].
    """
    s2 = np.sin(lat) ** 2
    w = 1.0 - E2 * s2
    return A * (1.0 - E2) / w**1.5, A / np.sqrt(w)


def normal_gravity(lat, h):
    """Magnitude of WGS-84 normal gravity (Somigliana, with the second-order height term).

    Parameters
    ----------
    lat : float or ndarray
        Geodetic latitude [rad].
    h : float or ndarray
        Ellipsoidal height [m].

    Returns
    -------
    float or ndarray
        Gravity magnitude [m/s^2]; it points along +D in the NED frame.
    """
    s2 = np.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / np.sqrt(1.0 - E2 * s2)
    return g0 * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 * h**2 / A**2)


def gravity_n(lat, h):
    """Normal gravity vector in NED [m/s^2] (the deflection of the vertical is neglected)."""
    return np.array([0.0, 0.0, normal_gravity(lat, h)])


def earth_rate_n(lat):
    """Earth rotation rate omega_ie resolved in NED [rad/s]."""
    return OMEGA_IE * np.array([np.cos(lat), 0.0, -np.sin(lat)])


def transport_rate_n(lat, h, v_n):
    """Transport rate omega_en resolved in NED [rad/s] for NED velocity ``v_n`` [m/s]."""
    R_M, R_N = radii(lat)
    return np.array([v_n[1] / (R_N + h), -v_n[0] / (R_M + h), -v_n[1] * np.tan(lat) / (R_N + h)])


def llh_to_ecef(lat, lon, h):
    """Geodetic latitude, longitude [rad] and height [m] to ECEF [m]; arrays broadcast.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    lat, lon, h = np.broadcast_arrays(
        np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float)
    )
    _, R_N = radii(lat)
    x = (R_N + h) * np.cos(lat) * np.cos(lon)
    y = (R_N + h) * np.cos(lat) * np.sin(lon)
    z = (R_N * (1.0 - E2) + h) * np.sin(lat)
    return np.stack([x, y, z], axis=-1)


def ecef_to_llh(r_e):
    """ECEF [m] to geodetic latitude, longitude [rad] and height [m].

    Uses Heikkinen's closed-form solution refined by two Newton iterations, accurate to well
    below a millimetre for terrestrial points.

    Parameters
    ----------
    r_e : array_like, shape (..., 3)

    Returns
    -------
    lat, lon, h : ndarray
    """
    r_e = np.asarray(r_e, float)
    x, y, z = r_e[..., 0], r_e[..., 1], r_e[..., 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    # Start from the spherical guess corrected by the eccentricity, then iterate.
    lat = np.arctan2(z, p * (1.0 - E2))
    for _ in range(5):
        _, R_N = radii(lat)
        h = p / np.cos(lat) - R_N
        lat = np.arctan2(z, p * (1.0 - E2 * R_N / (R_N + h)))
    _, R_N = radii(lat)
    # This height expression stays well conditioned near the poles.
    h = p * np.cos(lat) + z * np.sin(lat) - A**2 / R_N
    return lat, lon, h


def R_en(lat, lon):
    """Rotation from ECEF to the NED frame at (lat, lon); ``v_n = R_en @ v_e``."""
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])


class LocalTangentFrame:
    """A local NED tangent plane at a stated geodetic origin.

    Used for metric work (least-squares acceleration, truth comparison, plots). Positions are
    exact ECEF-based conversions, not a flat-earth approximation.

    Parameters
    ----------
    lat0, lon0 : float
        Origin latitude and longitude [rad].
    h0 : float
        Origin ellipsoidal height [m].
    """

    def __init__(self, lat0: float, lon0: float, h0: float):
        self.lat0, self.lon0, self.h0 = float(lat0), float(lon0), float(h0)
        self._r0_e = llh_to_ecef(lat0, lon0, h0)
        self._R_en = R_en(lat0, lon0)

    def to_ned(self, lat, lon, h):
        """Geodetic [rad, rad, m] to NED metres relative to the origin, shape (..., 3)."""
        return (llh_to_ecef(lat, lon, h) - self._r0_e) @ self._R_en.T

    def to_llh(self, p_n):
        """NED metres relative to the origin to geodetic ``(lat, lon, h)`` [rad, rad, m]."""
        r_e = np.asarray(p_n, float) @ self._R_en + self._r0_e
        return ecef_to_llh(r_e)

    def __repr__(self) -> str:
        return (
            f"LocalTangentFrame(lat0={np.degrees(self.lat0):.8f} deg, "
            f"lon0={np.degrees(self.lon0):.8f} deg, h0={self.h0:.3f} m)"
        )


def R_en_batch(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """ECEF -> NED rotations at arrays of latitudes and longitudes [rad], shape (M, 3, 3)
    (:func:`R_en` for many points)."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    R = np.empty((len(sl), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = -sl * co, -sl * so, cl
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = -so, co, 0.0
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -cl * co, -cl * so, -sl
    return R
