r"""GNSS velocities against the fixes: their frame and sign, their time tags, and each axis.

One view, without the IMU: the fixes' track against the track the velocities integrate to. Within
each stretch of velocities without a gap (:data:`GAP_FACTOR` median intervals; :data:`WINDOW_S`
at most, which bounds what a slowly varying velocity error integrates to) the velocities are
integrated (trapezoid) and evaluated at the fixes' times; the fixes less that track, less one
constant per stretch, are the fixes' own errors when the velocities are right. Their squares
over the fixes' noise (their stated variance plus the velocities' white noise integrated over a
stretch) are the view's cost. A stretch is as long as that integrated noise stays within the
fixes' own (:data:`MIN_WINDOW_S` to :data:`WINDOW_S`).

* **Frame and sign** (:func:`frame_proposal`): the velocities as given against two readings of
  them: ENU written where NED is meant (north and east swapped, the vertical negated; with
  horizontal velocities only, north and east swapped) and the vertical sign alone wrong (``vu``
  written where ``vd`` is meant). A reading whose cost is lower than the given's by
  :data:`VIEW_GAIN` (half the difference, on the noise the best reading leaves: the view learns
  the fixes' noise scale from the recording) is proposed; the estimator decides
  (:mod:`gnssacc.prepare.judge`, with the velocity innovations' likelihood).
* **Time tags** (:func:`time_proposal`): the integrated track evaluated at the fixes' times
  shifted by ``d`` (``|d|`` up to :data:`MAX_LAG_S`, steps of :data:`LAG_STEP_S`, refined by a
  parabola): a lag ``d`` makes the track lead or trail by the velocity times ``d``. A lag of at
  least :data:`MIN_LAG_S` that gains :data:`VIEW_GAIN` is proposed (the correction subtracts it
  from the velocities' time tags); the estimator refines it by the likelihood and decides
  (:mod:`gnssacc.prepare.velocity_time`).
* A reading (or lag) is proposed only when it leaves the fixes explained (:func:`fits`): one that
  leaves the velocities contradicting the fixes (a biased axis swapped for another) is not.
* **Each axis** (:func:`axis_contradictions`): the root-mean-square of the fixes less the
  integrated track on one axis, against the fixes' noise on it (the larger of their stated sigma
  and the scatter of their fix-to-fix differences), beyond :data:`CONTRADICTION_RATIO`: the
  velocities contradict the positions there (a bias, a scale, a zeroed or missing axis). One view
  alone: a warning naming the axis with the figures (the fitted scale of the fixes' motion to the
  velocities' and the velocity bias), never a correction. With white fixes the ratio is about 1;
  five is a bias of about ``17 sigma / T`` m/s over ``T`` seconds, or a 10 % scale on a car's
  kilometre.

A recording without velocities, or with ``[velocity] enabled = false``, is not looked at.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.earth import LocalTangentFrame
from ..core.recording import GnssVelocity, RecordedRun
from .findings import Finding

#: A gap between velocities of more than this many median intervals splits the integration.
GAP_FACTOR = 2.5
#: Longest stretch integrated in one piece [s] (module notes), and the shortest: a stretch is
#: as long as the velocities' integrated white noise stays within the fixes' (``6 sigma_fix^2 /
#: (sigma_v^2 dt)``: 300 s for 3 m fixes beside 0.05 m/s velocities, 10 s for 3 cm fixes).
WINDOW_S = 300.0
MIN_WINDOW_S = 10.0
#: A reading is tried only where it changes something: the velocities on the axes it rereads
#: show motion beyond their noise (mean square at least this many times their variance; a flat
#: road's vertical velocity is noise, and its sign cannot be told, nor does it matter).
MOTION_RATIO = 2.0
#: A velocity whose sigma exceeds this many times the median splits the integration too (a course
#: not used at walking pace: the velocity is taken as zero with a speed-sized sigma).
SIGMA_BREAK = 5.0
#: Fewest fixes in a stretch for it to count.
MIN_STRETCH_FIXES = 5
#: Least gain (log-likelihood units, on the learned noise scale) of a proposal by this view: a
#: proposal costs two EKF passes, and one fitted parameter on noise gains more than 6 once in
#: about 5000 runs (chi-square with one degree of freedom beyond 12).
VIEW_GAIN = 6.0
#: The time-tag search [s].
MAX_LAG_S = 2.0
LAG_STEP_S = 0.05
#: Smallest time-tag error worth a correction [s] (at 20 m/s, 1 m).
MIN_LAG_S = 0.05
#: Root-mean-square of an axis' misfit, in its noise, beyond which the axis contradicts (notes).
CONTRADICTION_RATIO = 5.0
AXES = ("north", "east", "down")
#: The readings of the frame check: name, matrix applied to the velocities as given, what the
#: correction does (for messages).
READINGS = (
    (
        "enu",
        np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
        "read the velocities as ENU (swapped north and east, negated the vertical)",
    ),
    (
        "up",
        np.diag([1.0, 1.0, -1.0]),
        "negated the vertical velocity (read it as up, vu)",
    ),
)


def in_use(run: RecordedRun, cfg) -> bool:
    """Whether the run has velocities the estimators use (``[velocity] enabled``)."""
    vel = run.gnss_vel
    return vel is not None and bool(cfg["velocity"]["enabled"]) and bool(vel.measured().any())


@dataclass
class Track:
    """The fixes in a local NED frame [m], their noise beside the integrated velocities
    (``sigma``, [m]), the velocities, and the stretch length [s]."""

    t: np.ndarray
    p: np.ndarray
    sigma: np.ndarray
    vel: GnssVelocity
    window_s: float = WINDOW_S

    @classmethod
    def of(cls, run: RecordedRun) -> "Track":
        """The run's fixes, their noise beside the integrated velocities' (module notes: the
        stated sigma and the velocities' white noise integrated over a stretch, mean removed,
        ``sigma_v^2 dt L / 6``), and the stretch length."""
        g, vel = run.gnss, run.gnss_vel
        frame = LocalTangentFrame(float(g.lat[0]), float(g.lon[0]), float(g.h[0]))
        dt = float(np.median(np.diff(vel.t))) if len(vel) > 1 else 1.0
        var_v = np.nan_to_num(np.nanmedian(vel.sigma_ned**2, axis=0), nan=0.0)
        h_fix, h_v = float(np.median(g.sigma_ned[:, :2] ** 2)), float(np.max(var_v[:2]))
        window = WINDOW_S if h_v <= 0 else 6.0 * h_fix / (h_v * max(dt, 1e-3))
        window = float(np.clip(window, MIN_WINDOW_S, WINDOW_S))
        noise = np.sqrt(g.sigma_ned**2 + var_v * dt * window / 6.0)
        return cls(g.t, frame.to_ned(g.lat, g.lon, g.h), noise, vel, window)

    @property
    def axes(self) -> np.ndarray:
        """The axes every velocity measures (boolean (3,))."""
        return np.all(self.vel.measured(), axis=0)


def stretches(vel: GnssVelocity, axes: np.ndarray, window_s: float = WINDOW_S) -> np.ndarray:
    """Stretch id of each velocity (module notes): a new one after a gap, after a velocity whose
    sigma is :data:`SIGMA_BREAK` times the median or more (it belongs to none: -1), and every
    ``window_s`` [s]."""
    t = vel.t
    if len(t) < 2:
        return np.full(len(t), -1)
    sig = vel.sigma_ned[:, axes].max(axis=1)
    bad = sig > SIGMA_BREAK * float(np.median(sig))
    gap = np.diff(t) > GAP_FACTOR * float(np.median(np.diff(t)))
    new = np.concatenate([[True], gap | bad[1:] | bad[:-1]])
    sid = np.cumsum(new) - 1
    # split long stretches into windows
    out = np.empty(len(t), int)
    nxt = 0
    for s in np.unique(sid):
        m = sid == s
        w = np.floor((t[m] - t[m][0]) / window_s).astype(int)
        out[m] = nxt + w
        nxt += int(w.max()) + 1
    out[bad] = -1
    return out


def integrated(vel: GnssVelocity, v: np.ndarray, sid: np.ndarray, t_eval: np.ndarray):
    """The track the velocities ``v`` (K, 3) integrate to at ``t_eval`` [m], from zero at each
    stretch's start, and each time's stretch id (-1: in none)."""
    P = np.full((len(t_eval), 3), np.nan)
    where = np.full(len(t_eval), -1)
    for s in np.unique(sid[sid >= 0]):
        m = sid == s
        ts, vs = vel.t[m], v[m]
        if len(ts) < 2:
            continue
        steps = 0.5 * (vs[1:] + vs[:-1]) * np.diff(ts)[:, None]
        cum = np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
        hit = (t_eval >= ts[0]) & (t_eval <= ts[-1])
        for i in range(3):
            P[hit, i] = np.interp(t_eval[hit], ts, cum[:, i])
        where[hit] = s
    return P, where


def misfit(track: Track, P: np.ndarray, where: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The fixes less the integrated track less each stretch's weighted mean [m], (N, 3), NaN at
    fixes in no stretch or a stretch with too few fixes, and on unmeasured axes."""
    r = np.full_like(track.p, np.nan)
    w = 1.0 / track.sigma**2
    for s in np.unique(where[where >= 0]):
        m = where == s
        if m.sum() < MIN_STRETCH_FIXES:
            continue
        d = track.p[m] - P[m]
        r[m] = d - np.sum(d * w[m], 0) / np.sum(w[m], 0)
    r[:, ~axes] = np.nan
    return r


def cost(track: Track, r: np.ndarray) -> tuple[float, int]:
    """Sum of the misfits' squares over the fixes' noise variances, and its count."""
    c, n = axis_costs(track, r)
    return float(c.sum()), int(n.sum())


def axis_costs(track: Track, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cost` per axis: sums (3,) and counts (3,)."""
    ok = np.isfinite(r)
    z = np.where(ok, r / track.sigma, 0.0)
    return np.sum(z**2, axis=0), np.sum(ok, axis=0)


def _reading_cost(track, M, sid, axes):
    """The view's cost of the velocities reread by ``M``, its count, whether the reading
    explains the fixes on every axis (:func:`fits`), and the misfits."""
    v = np.nan_to_num(track.vel.v_ned) @ M.T
    P, where = integrated(track.vel, v, sid, track.t)
    r = misfit(track, P, where, axes)
    c, n = axis_costs(track, r)
    explained = all(fits(a, b) for a, b in zip(c, n, strict=True) if b)
    return float(c.sum()), int(n.sum()), explained, r


def correlation_factor(track: Track, r: np.ndarray) -> float:
    """How much the misfits' correlation in time overstates a view's evidence: ``(1 + rho) /
    (1 - rho)`` of their lag-1 autocorrelation (whitened, over consecutive fixes of a stretch
    and every axis), at least 1. Fixes with time-correlated errors (a receiver's filter,
    multipath, the atmosphere) sum to far less evidence than white ones."""
    z = r / track.sigma
    ok = np.isfinite(z[1:]) & np.isfinite(z[:-1])
    if ok.sum() < 2 * MIN_STRETCH_FIXES:
        return 1.0
    a, b = z[1:][ok], z[:-1][ok]
    rho = float(np.clip(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)), 0.0, 0.95))
    return (1.0 + rho) / (1.0 - rho)


def moving(vel: GnssVelocity, axes) -> bool:
    """Whether the velocities on ``axes`` show motion beyond their noise (:data:`MOTION_RATIO`)."""
    v, s = vel.v_ned[:, axes], vel.sigma_ned[:, axes]
    return float(np.nanmean(np.sum(v**2, 1))) >= MOTION_RATIO * float(np.nanmean(np.sum(s**2, 1)))


def frame_proposal(run: RecordedRun, cfg, where: str) -> Finding | None:
    """The frame or sign reading of the velocities that the view favours (module notes), as a
    proposal whose repair rereads them; ``None`` when the velocities as given fit best, or not
    by :data:`VIEW_GAIN`."""
    if not in_use(run, cfg):
        return None
    track = Track.of(run)
    axes = track.axes
    if not axes[:2].all():
        return None
    sid = stretches(track.vel, axes, track.window_s)
    given, n, _, _ = _reading_cost(track, np.eye(3), sid, axes)
    if n < 2 * MIN_STRETCH_FIXES:
        return None
    tried = {"enu": moving(track.vel, [0, 1]), "up": axes[2] and moving(track.vel, [2])}
    readings = {name: _reading_cost(track, M, sid, axes) for name, M, _ in READINGS if tried[name]}
    if not readings:
        return None
    costs = {k: v[0] for k, v in readings.items()}
    name = min(costs, key=lambda k: costs[k])
    # the noise scale the best reading leaves, and its correlation in time
    scale = max(1.0, min(given, costs[name]) / n) * correlation_factor(track, readings[name][3])
    gain = 0.5 * (given - costs[name]) / scale
    if gain < VIEW_GAIN or not readings[name][2]:
        return None
    rms = {k: float(np.sqrt(c / n)) for k, c in (("given", given), (name, costs[name]))}
    details = {"reading": name, "view_gain": gain, "view_scale": scale, "window_s": track.window_s}
    return _frame_finding(name, bool(axes[2]), rms, where, details)


def _frame_finding(name: str, vertical: bool, rms: dict, where: str, details: dict) -> Finding:
    """The proposal of reading ``name`` (of :data:`READINGS`; without a ``vertical``, ENU is north
    and east swapped) with the view's misfits ``rms`` (in fix sigmas) for the message."""
    M, text = next((M, text) for nm, M, text in READINGS if nm == name)
    if not vertical:
        M, text = np.eye(3)[[1, 0, 2]], "swapped the north and east velocities"
    problem = (
        f"the GNSS velocities integrate to a track {rms['given']:.2f} fix sigmas off the fixes "
        f"(root-mean-square), {rms[name]:.2f} when "
        + ("read as ENU" if name == "enu" else "their vertical is read as up")
    )
    fix = (
        "write the velocities as north, east, down (vn, ve, vd)"
        if name == "enu"
        else "write the down velocity vd (positive downward), not vu"
    )
    return Finding(
        "velocity_frame",
        where,
        problem,
        fix,
        lambda r: with_velocities(r, transformed(r.gnss_vel, M)),
        text,
        details=details,
    )


def fits(c: float, n: int) -> bool:
    """Whether a reading whose cost on one axis is ``c`` over ``n`` fixes explains them: its
    misfit's root-mean-square within :data:`CONTRADICTION_RATIO` of their stated noise (a
    reading that leaves the velocities contradicting the fixes is not proposed: swapping a
    biased axis for another moves the contradiction, it does not remove it)."""
    return c / max(n, 1) < CONTRADICTION_RATIO**2


def transformed(vel: GnssVelocity, M: np.ndarray) -> GnssVelocity:
    """``vel`` reread by the signed permutation ``M`` (3 x 3): velocities, sigmas and
    correlations."""
    v = vel.v_ned @ M.T
    perm = np.argmax(np.abs(M), axis=1)  # new axis i is old axis perm[i]
    sign = M[np.arange(3), perm]
    sig = vel.sigma_ned[:, perm]
    corr = None
    if vel.corr_ned is not None:
        full = np.ones((len(vel), 3, 3))
        for (i, j), c in zip(((0, 1), (0, 2), (1, 2)), vel.corr_ned.T, strict=True):
            full[:, i, j] = full[:, j, i] = c
        new = full[:, perm][:, :, perm] * np.outer(sign, sign)
        corr = np.column_stack([new[:, 0, 1], new[:, 0, 2], new[:, 1, 2]])
    return GnssVelocity(vel.t.copy(), v, sig, corr, vel.sigma_stated)


def with_velocities(run: RecordedRun, vel: GnssVelocity | None) -> RecordedRun:
    """``run`` with other GNSS velocities."""
    return replace(run, gnss_vel=vel)


def lag_costs(track: Track, lags: np.ndarray) -> tuple[np.ndarray, int, np.ndarray, list]:
    """The view's cost of the velocities' time tags less each lag [s], over the fixes every lag
    keeps in its stretch (the same fixes for every lag), their count, whether each lag explains
    the fixes on every axis (:func:`fits`), and each lag's misfits."""
    axes = track.axes
    sid = stretches(track.vel, axes, track.window_s)
    v = np.nan_to_num(track.vel.v_ned)
    keep = np.ones(len(track.t), bool)
    runs = []
    for d in lags:
        P, where = integrated(track.vel, v, sid, track.t + d)
        runs.append((P, where))
        keep &= where >= 0
    out, ok, rs = [], [], []
    n = 0
    for P, where in runs:
        r = misfit(track, P, np.where(keep, where, -1), axes)
        c, k = axis_costs(track, r)
        out.append(float(c.sum()))
        ok.append(all(fits(a, b) for a, b in zip(c, k, strict=True) if b))
        rs.append(r)
        n = int(k.sum())
    return np.array(out), n, np.array(ok), rs


def time_proposal(run: RecordedRun, cfg, where: str) -> Finding | None:
    """The velocities' time-tag error the view finds (module notes), as a proposal whose repair
    subtracts it from their time tags; ``None`` below :data:`MIN_LAG_S` or :data:`VIEW_GAIN`."""
    if not in_use(run, cfg):
        return None
    track = Track.of(run)
    if not track.axes[:2].all():
        return None
    lags = np.round(np.arange(-MAX_LAG_S, MAX_LAG_S + 0.5 * LAG_STEP_S, LAG_STEP_S), 6)
    costs, n, explained, misfits = lag_costs(track, lags)
    if n < 2 * MIN_STRETCH_FIXES or not np.all(np.isfinite(costs)):
        return None
    k = int(np.argmin(costs))
    d = float(lags[k])
    if 0 < k < len(lags) - 1:  # the parabola through the best and its neighbours
        c_m, c_0, c_p = costs[k - 1 : k + 2]
        den = c_m - 2.0 * c_0 + c_p
        if den > 0:
            d += float(np.clip(0.5 * LAG_STEP_S * (c_m - c_p) / den, -LAG_STEP_S, LAG_STEP_S))
    zero = costs[int(np.argmin(np.abs(lags)))]
    scale = max(1.0, float(costs[k]) / n) * correlation_factor(track, misfits[k])
    gain = 0.5 * (zero - float(costs[k])) / scale
    if abs(d) < MIN_LAG_S or gain < VIEW_GAIN or not explained[k]:
        return None
    late = "behind" if d > 0 else "ahead of"
    return Finding(
        "velocity_time",
        where,
        f"the GNSS velocities' time tags run {abs(d):.2f} s {late} the fixes' (their integrated "
        f"track fits the fixes best so shifted)",
        "tag each velocity with the time of the fix it was measured with",
        lambda r: with_velocities(r, shifted_velocities(r.gnss_vel, -d)),
        f"subtracted {d:+.2f} s from the velocities' time tags",
        details={"lag_s": d, "view_gain": gain, "vel_shift_s": -d},
    )


def shifted_velocities(vel: GnssVelocity, d: float) -> GnssVelocity:
    """``vel`` with ``d`` [s] added to its time tags."""
    return replace(vel, t=vel.t + d)


def noise_scale(track: Track, P: np.ndarray, stretch_of_fix: np.ndarray, axis: int) -> float:
    """The fixes' noise on one axis [m]: the larger of their median noise (:class:`Track`) and
    the scatter of the fix-to-fix differences of the fixes less the integrated track ``P``
    within the stretches (over sqrt(2))."""
    stated = float(np.median(track.sigma[:, axis]))
    same = (stretch_of_fix[1:] == stretch_of_fix[:-1]) & (stretch_of_fix[1:] >= 0)
    if same.sum() < MIN_STRETCH_FIXES:
        return stated
    d = np.diff(track.p[:, axis] - P[:, axis])[same]
    hf = float(np.std(d - np.median(d)) / np.sqrt(2.0))
    return max(stated, hf)


def axis_fit(track: Track, P: np.ndarray, where: np.ndarray, axis: int):
    """``(scale, bias)``: the fixes on ``axis`` fitted as a constant per stretch plus ``scale``
    times the integrated track plus a drift; ``bias`` is the velocity's [m/s] (minus the drift).
    ``scale`` is NaN when the track does not move enough to tell."""
    ok = (where >= 0) & np.isfinite(P[:, axis])
    ids = np.unique(where[ok])
    A = [(where[ok] == s).astype(float) for s in ids]
    A += [P[ok, axis], track.t[ok] - track.t[ok].mean()]
    sol, *_ = np.linalg.lstsq(np.column_stack(A), track.p[ok, axis], rcond=None)
    moved = np.ptp(P[ok, axis]) if ok.any() else 0.0
    scale = float(sol[-2]) if moved > 3.0 * float(np.median(track.sigma[:, axis])) else np.nan
    return scale, -float(sol[-1])


def axis_contradictions(run: RecordedRun, cfg, where: str) -> Finding | None:
    """A warning naming each axis on which the velocities contradict the fixes (module notes)."""
    if not in_use(run, cfg):
        return None
    track = Track.of(run)
    measured = track.axes
    if not measured.any():
        return None
    sid = stretches(track.vel, measured, track.window_s)
    P, at = integrated(track.vel, np.nan_to_num(track.vel.v_ned), sid, track.t)
    r = misfit(track, P, at, measured)
    said, details, named = [], {}, []
    for i in np.flatnonzero(measured):
        ok = np.isfinite(r[:, i])
        if ok.sum() < 2 * MIN_STRETCH_FIXES:
            continue
        rms = float(np.sqrt(np.mean(r[ok, i] ** 2)))
        noise = noise_scale(track, P, at, i)
        scale, bias = axis_fit(track, P, at, i)
        details[AXES[i]] = {"rms_m": rms, "noise_m": noise, "scale": scale, "bias_mps": bias}
        if rms < CONTRADICTION_RATIO * noise:
            continue
        fit = (
            f"the fixes move {scale:.2f} times the velocities' motion"
            if np.isfinite(scale)
            else "the velocities show no motion there"
        )
        named.append(AXES[i])
        said.append(
            f"{AXES[i]}: the fixes depart from the integrated velocities by {rms:.1f} m RMS "
            f"against their noise of {noise:.1f} m ({fit}; velocity bias {bias:+.2f} m/s)"
        )
    if not said:
        return None
    return Finding(
        "velocity",
        where,
        "the GNSS velocities contradict the fixes on " + "; ".join(said),
        "check the velocity columns on those axes (units, sign, bias); --velocity off leaves the "
        "velocities out",
        details={"axes": details, "contradicting": named},
    )
