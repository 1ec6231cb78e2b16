"""Synthetic GNSS fixes for sources with truth: seeded noise profiles and outages.

Profiles (1-sigma, metres, N/E/D):

``white``
    iid Gaussian, 3 / 3 / 5.
``gm``
    first-order Gauss-Markov, tau = 60 s, 2.5 / 2.5 / 4, plus white 0.5 / 0.5 / 0.8.
``precise``
    iid Gaussian, 0.5 / 0.5 / 0.8 (a dual-frequency or SBAS-corrected receiver).
``rtk``
    iid Gaussian, 0.02 / 0.02 / 0.04 (fixed-ambiguity RTK).
``filtered``
    first-order Gauss-Markov, tau = 30 s, 0.6 / 0.6 / 1.0, plus white 0.02 / 0.02 / 0.03: a
    receiver whose own filter smooths its high-rate fixes (their scatter from one fix to the next
    says little about their error).
``none``
    the truth itself (for tests).

The sigma attached to each fix (what the estimators are told) is the profile's total
stationary 1-sigma per axis.

Doppler velocities (:func:`velocities_from_truth`, :data:`VELOCITY_PROFILES`): a receiver's
velocity comes from the carrier's Doppler shift, independently of its position solution and about
a hundred times more precisely; its error is white (1-sigma 0.05 / 0.05 / 0.08 m/s N/E/D) plus a
small first-order Gauss-Markov part (0.01 / 0.01 / 0.015 m/s, tau = 5 s: multipath, satellite
geometry changes), for every position profile but ``none`` (the truth). They are drawn from their
own stream, so a run's fixes and IMU keep their draws whether or not it has velocities.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..core.earth import OMEGA_IE
from ..core.errors import InputError
from ..core.recording import GnssFixes, GnssVelocity, RecordedRun, Truth

PROFILES = {
    "white": {"gm_sigma": np.zeros(3), "tau_s": 60.0, "white_sigma": np.array([3.0, 3.0, 5.0])},
    "gm": {
        "gm_sigma": np.array([2.5, 2.5, 4.0]),
        "tau_s": 60.0,
        "white_sigma": np.array([0.5, 0.5, 0.8]),
    },
    "precise": {"gm_sigma": np.zeros(3), "tau_s": 60.0, "white_sigma": np.array([0.5, 0.5, 0.8])},
    "rtk": {"gm_sigma": np.zeros(3), "tau_s": 60.0, "white_sigma": np.array([0.02, 0.02, 0.04])},
    # A receiver whose own filter smooths its high-rate fixes: errors that wander (SBAS/DGPS-grade,
    # tens of seconds) with almost no scatter from one fix to the next; such logs rarely state sigmas.
    "filtered": {
        "gm_sigma": np.array([0.6, 0.6, 1.0]),
        "tau_s": 30.0,
        "white_sigma": np.array([0.02, 0.02, 0.03]),
    },
    "none": {"gm_sigma": np.zeros(3), "tau_s": 60.0, "white_sigma": np.zeros(3)},
}

_DOPPLER = {
    "gm_sigma": np.array([0.01, 0.01, 0.015]),
    "tau_s": 5.0,
    "white_sigma": np.array([0.05, 0.05, 0.08]),
}
#: Doppler velocity errors [m/s] (white and Gauss-Markov, N/E/D) beside each position profile.
VELOCITY_PROFILES = {name: _DOPPLER for name in PROFILES} | {
    "none": {"gm_sigma": np.zeros(3), "tau_s": 20.0, "white_sigma": np.zeros(3)}
}

#: The fix quality a receiver of each profile would state (:data:`gnssacc.core.recording.FIX_QUALITY`).
PROFILE_QUALITY = {"white": 5, "gm": 5, "precise": 4, "rtk": 1, "filtered": 3, "none": 1}


def noise_ned(t: np.ndarray, profile: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Draw a noise sequence for fix times ``t``.

    Parameters
    ----------
    t : ndarray, shape (M,)
        Fix times [s], increasing.
    profile : str
        A key of :data:`PROFILES`.
    seed : int

    Returns
    -------
    noise : ndarray, shape (M, 3)
        NED position errors [m].
    sigma : ndarray, shape (3,)
        Total stationary 1-sigma per axis [m].
    """
    if profile not in PROFILES:
        raise InputError(
            "--noise", f"unknown noise profile {profile!r} (known: {', '.join(PROFILES)})"
        )
    return white_plus_markov(t, PROFILES[profile], np.random.default_rng(seed))


def white_plus_markov(t: np.ndarray, p: dict, rng) -> tuple[np.ndarray, np.ndarray]:
    """White noise of 1-sigma ``p["white_sigma"]`` plus a first-order Gauss-Markov process of
    stationary 1-sigma ``p["gm_sigma"]`` and correlation time ``p["tau_s"]`` [s] at times ``t``
    (per axis, drawn from ``rng``), and the total stationary 1-sigma per axis."""
    white = rng.standard_normal((len(t), 3)) * p["white_sigma"]
    gm = np.zeros((len(t), 3))
    if np.any(p["gm_sigma"] > 0):
        gm[0] = rng.standard_normal(3) * p["gm_sigma"]
        decay = np.exp(-np.diff(t) / p["tau_s"])
        drive = rng.standard_normal((len(t) - 1, 3))
        for k in range(1, len(t)):
            a = decay[k - 1]
            gm[k] = a * gm[k - 1] + np.sqrt(1.0 - a * a) * p["gm_sigma"] * drive[k - 1]
    sigma = np.sqrt(p["gm_sigma"] ** 2 + p["white_sigma"] ** 2)
    return gm + white, sigma


def fixes_from_truth(
    run: RecordedRun, truth: Truth, profile: str, seed: int, p_antenna_n: np.ndarray | None = None
) -> GnssFixes:
    """Make noisy fixes at the truth epochs.

    Parameters
    ----------
    run : RecordedRun
        Supplies the tangent-plane origin.
    truth : Truth
    profile : str
        Noise profile name.
    seed : int
    p_antenna_n : ndarray, shape (K, 3), optional
        NED offset from the truth point to the antenna [m] (``R_nb @ lever_arm_b``).
    """
    p_n = run.origin.to_ned(truth.lat, truth.lon, truth.h)
    if p_antenna_n is not None:
        p_n = p_n + p_antenna_n
    noise, sigma = noise_ned(truth.t, profile, seed)
    lat, lon, h = run.origin.to_llh(p_n + noise)
    sig = np.tile(np.where(sigma > 0, sigma, 0.01), (len(truth.t), 1))
    return GnssFixes(truth.t.copy(), lat, lon, h, sig)


def antenna_velocity(
    v_n: np.ndarray,
    R_nb: np.ndarray,
    omega_ib_b: np.ndarray,
    lat: np.ndarray,
    lever_arm_b: np.ndarray,
) -> np.ndarray:
    """The antenna's velocity relative to the earth, NED [m/s], shape (K, 3):
    ``v_n + R_nb ((omega_ib_b - R_nb^T omega_ie^n) x l_b)`` for the IMU's velocity ``v_n``
    (K, 3), attitude ``R_nb`` (K, 3, 3), inertial body rate ``omega_ib_b`` [rad/s] (K, 3) at
    latitudes ``lat`` [rad] and the lever arm ``lever_arm_b`` [m, body]."""
    lat = np.asarray(lat, float)
    w_ie_n = OMEGA_IE * np.stack([np.cos(lat), np.zeros_like(lat), -np.sin(lat)], -1)
    w_eb_b = omega_ib_b - np.einsum("kji,kj->ki", R_nb, w_ie_n)
    return v_n + np.einsum("kij,kj->ki", R_nb, np.cross(w_eb_b, lever_arm_b))


def velocities_from_truth(
    t: np.ndarray, v_ant_n: np.ndarray, profile: str, seed: int
) -> GnssVelocity:
    """Doppler velocities at times ``t`` [s]: the antenna's true velocity ``v_ant_n`` [m/s, NED]
    (:func:`antenna_velocity`) plus the errors of :data:`VELOCITY_PROFILES` beside the position
    ``profile``, drawn from ``default_rng([seed, 5])`` (``seed``: the run's), with their total
    stationary 1-sigma stated."""
    if profile not in VELOCITY_PROFILES:
        raise InputError(
            "--noise", f"unknown noise profile {profile!r} (known: {', '.join(PROFILES)})"
        )
    noise, sigma = white_plus_markov(
        t, VELOCITY_PROFILES[profile], np.random.default_rng([seed, 5])
    )
    sig = np.tile(np.where(sigma > 0, sigma, 1e-3), (len(t), 1))
    return GnssVelocity(np.asarray(t, float).copy(), v_ant_n + noise, sig)


#: Shortest ``--outage-every`` period [s]: below a second (a fix interval or two) the cycle drops
#: single fixes at random rather than making outages.
MIN_OUTAGE_PERIOD_S = 1.0
#: Most outage spans a run may get (``--outage`` list plus ``--outage-every`` cycles).
MAX_OUTAGES = 10_000


def parse_outages(
    spec: str | None, every: str | None, duration_s: float | None
) -> list[tuple[float, float]]:
    """Outage windows in seconds from the run start.

    Parameters
    ----------
    spec : str or None
        ``"START:LEN[,START:LEN...]"``: START >= 0, LEN > 0, finite, in seconds.
    every : str or None
        ``"PERIOD:LEN"``: a LEN-second outage at the end of every PERIOD-second block, i.e.
        ``[k*PERIOD - LEN, k*PERIOD)`` for k = 1, 2, ..., so the first block starts with GNSS.
        ``0 < LEN < PERIOD`` and ``PERIOD >= MIN_OUTAGE_PERIOD_S``.
    duration_s : float or None
        Run duration [s]. ``None``: only check the syntax and ranges (the CLI does so before
        loading anything); the periodic outages are then left out.

    Returns
    -------
    list of (start, end)

    Raises
    ------
    InputError
        Naming ``--outage`` or ``--outage-every``: unreadable text, a value out of range, an
        outage starting after the run's end, more than :data:`MAX_OUTAGES` outages.
    """
    spans = [_read_span(part, "--outage") for part in spec.split(",")] if spec else []
    if len(spans) > MAX_OUTAGES:
        raise InputError("--outage", f"{len(spans)} outages, more than {MAX_OUTAGES}")
    for a, b in spans:
        if b <= a:
            raise InputError("--outage", f"outage length must be positive in '{a:g}:{b - a:g}'")
        if duration_s is not None and a >= duration_s:
            raise InputError(
                "--outage", f"the outage at {a:g} s starts after the run's end ({duration_s:.1f} s)"
            )
    if every:
        spans += _periodic(every, duration_s)
    return sorted(spans)


def _read_span(text: str, flag: str) -> tuple[float, float]:
    """``"A:B"`` -> (A, A + B) for --outage, (A, B) for --outage-every; finite, A >= 0."""
    what = "START:LEN, e.g. 120:30" if flag == "--outage" else "PERIOD:LEN, e.g. 60:20"
    parts = text.split(":")
    try:
        a, b = (float(p) for p in parts) if len(parts) == 2 else (None, None)
    except ValueError:
        a = b = None
    if a is None:
        raise InputError(flag, f"cannot read {text.strip()!r}: expected {what} (seconds)")
    if not (math.isfinite(a) and math.isfinite(b)) or a < 0:
        raise InputError(
            flag, f"{text.strip()!r}: the times must be finite and not negative ({what})"
        )
    return (a, a + b) if flag == "--outage" else (a, b)


def _periodic(every: str, duration_s: float | None) -> list[tuple[float, float]]:
    """The spans of ``--outage-every PERIOD:LEN`` over a run of ``duration_s`` (none if unknown)."""
    period, length = _read_span(every, "--outage-every")
    if not length > 0:
        raise InputError("--outage-every", f"outage length must be positive in {every.strip()!r}")
    if length >= period:
        raise InputError(
            "--outage-every",
            f"outage length {length:g} s must be shorter than the period {period:g} s",
        )
    if period < MIN_OUTAGE_PERIOD_S:
        raise InputError(
            "--outage-every",
            f"period {period:g} s is shorter than the minimum {MIN_OUTAGE_PERIOD_S:g} s",
        )
    if duration_s is None:
        return []
    n = int(math.floor((duration_s + length) / period)) + 1
    if n > MAX_OUTAGES:
        raise InputError(
            "--outage-every",
            f"{every.strip()!r} makes about {n} outages over the {duration_s:.0f} s "
            f"run, more than {MAX_OUTAGES}: choose a longer period",
        )
    return [
        (k * period - length, k * period)
        for k in range(1, n + 1)
        if k * period - length < duration_s
    ]


def in_spans(t_rel: np.ndarray, spans: list[tuple[float, float]]) -> np.ndarray:
    """Boolean mask of times (relative to the run start) inside any ``[start, end)`` span."""
    mask = np.zeros(len(t_rel), bool)
    for a, b in spans:
        mask |= (t_rel >= a) & (t_rel < b)
    return mask


def apply_outages(run: RecordedRun, spans: list[tuple[float, float]]) -> RecordedRun:
    """Drop the fixes and the GNSS velocities inside the outage spans; record the spans in
    ``run.outages``."""
    if not spans:
        return run
    keep = ~in_spans(run.gnss.t - run.t_start, spans)
    if not np.any(keep):
        raise InputError(run.where, "the outages remove every GNSS fix")
    vel = run.gnss_vel
    if vel is not None:
        vel = vel.select(~in_spans(vel.t - run.t_start, spans))
    return replace(
        run,
        gnss=run.gnss.select(keep),
        gnss_vel=vel,
        outages=tuple((float(a), float(b)) for a, b in spans),
    )


def add_outliers(
    run: RecordedRun, fraction: float, sigma_m: float, seed: int
) -> tuple[RecordedRun, np.ndarray]:
    """``run`` with about ``fraction`` of its fixes moved by N(0, ``sigma_m``^2) per NED axis
    (multipath, jumps), their stated sigma unchanged: heavy-tailed fix errors for simulated runs.

    Returns
    -------
    run : RecordedRun
    moved : ndarray of bool, shape (M,)
        Which fixes were moved.
    """
    if not (0.0 <= fraction <= 1.0 and sigma_m >= 0.0):
        raise ValueError(
            f"add_outliers: fraction {fraction} must be in [0, 1] and sigma_m {sigma_m} >= 0"
        )
    g = run.gnss
    rng = np.random.default_rng(seed)
    moved = rng.random(len(g.t)) < fraction
    p_n = (
        run.origin.to_ned(g.lat, g.lon, g.h)
        + rng.normal(0.0, sigma_m, (len(g.t), 3)) * moved[:, None]
    )
    lat, lon, h = run.origin.to_llh(p_n)
    return run.with_gnss(replace(g, lat=lat, lon=lon, h=h)), moved
