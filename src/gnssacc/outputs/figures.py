"""The figures of a result folder, one question each (``gnssacc run --plots all|basic|none``).

=========================  ====================================================================
``summary.png``            Which method, how good, how sure: horizontal error CDF (without truth:
                           distance to the raw fixes) with each one's 95 % point, beside each
                           method's NEES (without truth: NIS) against its consistent band, the
                           fraction of the run its NIS stays in band and its autocorrelation.
``accel_effect.png``       What the GNSS-derived acceleration changes: the paired difference
                           (with minus without) of the horizontal error per epoch and as a
                           distribution with the 95 % interval of its mean, for the filter and the
                           smoother (:mod:`gnssacc.outputs.accel_figure`).
``trajectory.png``         Where: the track (x east, y north, as ``evo`` draws the TUM export),
                           coloured by horizontal error (without truth: stated horizontal 1-sigma),
                           start and end marked, GNSS outages drawn over the track.
``errors.png``             Position error per axis with the +-3 sigma band, filters and smoothers
                           in separate columns; a last row with the 3-D error on a log scale, so
                           that outages do not flatten the rest.
``velocity_attitude.png``  Velocity and roll/pitch/yaw error with +-3 sigma (the parts the truth
                           has).
``nis.png``                Consistency over time: the EKFs' position NIS (moving mean, never across
                           an outage) against the chi-square band, and every method's distance to
                           the fixes [m] beside the fixes' sigma as read and as modelled.
``biases.png``             Accelerometer and gyro bias estimates with +-3 sigma (and the simulator's
                           true biases when known).
``sigmas.png``             Predicted 1-sigma of every error state.
=========================  ====================================================================

``basic`` writes the first four, ``all`` every one. A figure that cannot be drawn for the run's
data (no truth, no pair of methods with and without the acceleration) is not drawn and
:func:`write_figures` says why in words; a failure costs only that figure. Figures are saved at
:data:`DPI` dots per inch, sized to be read at 100 % on a laptop screen.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..core.display import DISPLAY_SCALE, STATE_GROUPS
from ..core.recording import RecordedRun
from ..core.solution import NavSolution
from ..core.states import BA, BG, POS
from .figstyle import (
    BAND_ALPHA,
    FIX_STYLE,
    NotDrawn,
    is_smoothed,
    plain_log_axis,
    shade_outages,
    style,
)
from .figstyle import plt as _plt

DPI = 100
#: The figures of each ``--plots`` choice, in the report's order.
PLOT_SETS = {
    "none": (),
    "basic": ("summary", "accel_effect", "trajectory", "errors"),
    "all": (
        "summary",
        "accel_effect",
        "trajectory",
        "errors",
        "velocity_attitude",
        "nis",
        "biases",
        "sigmas",
    ),
}
__all__ = ["FIX_STYLE", "PLOT_SETS", "is_smoothed", "style", "write_figures"]


def _save(fig, path: Path) -> None:
    fig.savefig(path, dpi=DPI)
    _plt().close(fig)


def _errors(run: RecordedRun, sol: NavSolution) -> np.ndarray:
    from ..analysis.observability import state_errors

    return state_errors(run, sol)


def _shade_outages(ax, run: RecordedRun) -> None:
    shade_outages(ax, run)


def _families(sols: dict) -> list[tuple[str, list[str]]]:
    """``[(title, [ids])]``: filters (EKFs and the smoothers' online estimates), then smoothers."""
    filt = [m for m in sols if not is_smoothed(m)]
    smooth = [m for m in sols if is_smoothed(m)]
    return [(t, ids) for t, ids in (("filters (causal)", filt), ("smoothers", smooth)) if ids]


def best_methods(sols: dict, metrics: dict) -> list[str]:
    """The best filter and the best smoother (lowest PRMSE; without truth, NIS nearest 1)."""

    def key(mid):
        m = metrics["methods"].get(mid, {})
        if m.get("prmse_m") is not None:
            return m["prmse_m"]
        nis = ((metrics.get("consistency") or {}).get(mid) or {}).get("nis", {}).get("pos")
        return abs(math.log(nis)) if nis else math.inf

    return [min(ids, key=key) for _, ids in _families(sols)]


# --------------------------------------------------------------------------------------------
# summary.png
# --------------------------------------------------------------------------------------------


def _p95(d: np.ndarray) -> float | None:
    d = d[np.isfinite(d)]
    return float(np.percentile(d, 95)) if len(d) else None


def _cdf(ax, d: np.ndarray, label: str, **kw) -> float | None:
    """One CDF line, its 95 % point marked and named in the legend; returns that point [m]."""
    d = np.sort(d[np.isfinite(d)])
    if not len(d):
        return None
    p95 = _p95(d)
    ax.plot(d, np.arange(1, len(d) + 1) / len(d), label=f"{label} (95 %: {p95:.2f} m)", **kw)
    ax.plot(p95, 0.95, "o", color=kw.get("color"), ms=4, zorder=4)
    return p95


def _horizontal_to(run: RecordedRun, sol: NavSolution, truth: bool) -> np.ndarray:
    """Horizontal distance [m] to the truth at the solution epochs, or to the fixes at theirs."""
    from ..analysis.accel_effect import horizontal_distance

    return horizontal_distance(run, sol, truth)[1]


def plot_summary(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``summary.png``: the horizontal error CDF and the consistency of each method (see module)."""
    plt = _plt()
    truth = run.truth is not None
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 5.5), gridspec_kw={"width_ratios": [1.5, 1]})
    dists = {mid: _horizontal_to(run, s, truth) for mid, s in sols.items()}
    tops = [np.nanpercentile(d, 98) for d in dists.values() if np.any(np.isfinite(d))]
    for mid, d in dists.items():
        _cdf(ax, d, mid, **style(mid))
    if truth:
        from ..analysis.metrics import truth_at

        p_true, ok = truth_at(run, run.gnss.t)
        f = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h)
        fix_p95 = _cdf(ax, np.hypot(*(f - p_true)[ok, 0:2].T), "raw fixes", **FIX_STYLE)
        if fix_p95 is not None:  # the fixes' 95 % point always inside the axis
            tops.append(1.05 * fix_p95)
    ax.set_xlim(0, 1.1 * max(tops + [1e-3]))
    ax.axhline(0.95, color="0.6", lw=0.8)
    ax.text(0.99 * ax.get_xlim()[1], 0.93, "95 %", ha="right", va="top", fontsize=8, color="0.4")
    ax.set_xlabel("horizontal error [m]" if truth else "horizontal distance to the raw fixes [m]")
    ax.set_ylabel("fraction of epochs")
    ax.set_title(
        "How good: horizontal error CDF (left and high is better)"
        if truth
        else "No truth: distance to the raw fixes (agreement, not accuracy)"
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    _consistency_panel(bx, sols, metrics, truth)
    fig.suptitle(f"{run.name}: which method, how good, how sure")
    fig.tight_layout()
    _save(fig, path)


def _over_run(sol: NavSolution, cons: dict) -> str:
    """What a method's NIS does over the run: the fraction of time its moving mean is in band
    (EKFs, which keep the NIS per update) and the innovations' lag-1 autocorrelation."""
    from ..analysis.nis_series import fraction_in_band

    parts = []
    t, nis = sol.stats.get("nis_pos_t"), sol.stats.get("nis_pos")
    if t is not None and nis is not None and len(nis):
        frac = fraction_in_band(np.asarray(t, float), np.asarray(nis, float))
        if frac is not None:
            parts.append(f"NIS in band {100 * frac:.0f} % of the run")
    if cons.get("innovation_acf1") is not None:
        parts.append(f"autocorr. {cons['innovation_acf1']:.2f}")
    return ", ".join(parts)


def _consistency_panel(ax, sols: dict, metrics: dict, truth: bool) -> None:
    """Each method's NEES (position, attitude) or NIS as dots on a log axis over its shaded band,
    and under its name what its NIS does over the run (:func:`_over_run`)."""
    from ..analysis.consistency import band

    ids = list(sols)
    labels = []
    for k, mid in enumerate(ids):
        m = metrics["methods"].get(mid, {})
        err = m.get("errors") or {}
        cons = (metrics.get("consistency") or {}).get(mid) or {}
        items = []
        if truth and err.get("nees_position"):
            items.append(("o", err["nees_position"], "position NEES"))
        if truth and err.get("nees_attitude"):
            items.append(("s", err["nees_attitude"], "attitude NEES"))
        nis = (cons.get("nis") or {}).get("pos")
        if nis is not None:
            lo, hi = band(
                int((cons.get("n") or {}).get("pos") or 1), acf1=cons.get("innovation_acf1")
            )
            items.append(("D", {"value": nis, "band": [lo, hi]}, "NIS (mean)"))
        for j, (marker, fig_, label) in enumerate(items):
            y = k + (j - (len(items) - 1) / 2) * 0.22
            lo, hi = fig_["band"]
            ax.plot([lo, hi], [y, y], color="0.8", lw=6, solid_capstyle="butt", zorder=1)
            ax.plot(
                fig_["value"],
                y,
                marker,
                color=style(mid)["color"],
                ms=7,
                zorder=3,
                label=label if k == 0 else None,
                mfc="white" if label.startswith("NIS") else None,
            )
        over = _over_run(sols[mid], cons)
        labels.append(f"{mid}\n{over}" if over else mid)
    ax.set_xscale("log")
    plain_log_axis(ax.xaxis)
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_yticks(range(len(ids)))
    ax.set_yticklabels(labels, fontsize=8)
    ax.set_ylim(len(ids) - 0.5, -0.5)
    ax.set_xlabel("per dof, log scale (1 = consistent; grey: its band)")
    ax.set_title(
        "How sure: stated uncertainty vs actual errors" if truth else "How sure: NIS (no truth)"
    )
    ax.grid(alpha=0.3, axis="x", which="both")
    if ax.get_legend_handles_labels()[0]:  # below the axis: the dots may sit anywhere in it
        ax.legend(
            fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=3, frameon=False
        )


# --------------------------------------------------------------------------------------------
# trajectory.png
# --------------------------------------------------------------------------------------------


#: A track longer than this many times its width (about its own line) is drawn along and across
#: that line, the across axis stretched: at equal scale a straight road is a one-pixel strip.
MAX_EQUAL_ASPECT = 8.0


class TrackFrame:
    """The plane a track is drawn in: east/north at equal scale, or, for a straight track
    (longer than :data:`MAX_EQUAL_ASPECT` times its width), along/across its principal line.

    Parameters
    ----------
    pts : ndarray, shape (K, 2)
        East, north [m] of the truth and the tracks drawn.
    """

    def __init__(self, pts: np.ndarray):
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        self.centre = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - self.centre, full_matrices=False)
        self.u, self.v = vt[0], np.array([-vt[0][1], vt[0][0]])
        along, across = (pts - self.centre) @ self.u, (pts - self.centre) @ self.v
        self.ratio = np.ptp(along) / max(np.ptp(across), 1.0)
        self.straight = self.ratio > MAX_EQUAL_ASPECT

    def xy(self, east: np.ndarray, north: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plot coordinates [m] of points given east, north [m]."""
        if not self.straight:
            return east, north
        d = np.column_stack([east, north]) - self.centre
        return d @ self.u, d @ self.v

    def label(self, ax) -> None:
        """Axis labels and, at equal scale, the aspect."""
        if self.straight:
            heading = np.degrees(np.arctan2(self.u[0], self.u[1])) % 360.0
            ax.set_xlabel(f"along the track [m] (heading {heading:.0f} deg)")
            ax.set_ylabel("across the track [m], stretched")
        else:
            ax.set_xlabel("east [m]")
            ax.set_ylabel("north [m]")
            ax.set_aspect("equal", adjustable="box")  # the limits stay; the box takes their shape

    def note(self) -> str:
        """For the title: how the plane is drawn."""
        if not self.straight:
            return "x east / y north"
        return f"straight ({self.ratio:.0f}x longer than wide): along / across its line"


def _mark_outages(ax, run: RecordedRun, sol: NavSolution, x: np.ndarray, y: np.ndarray) -> None:
    """The track inside each GNSS outage drawn over a wide red band (under the coloured track)."""
    for k, (a, b) in enumerate(run.outages):
        m = (sol.t - run.t_start >= a) & (sol.t - run.t_start <= b)
        if np.any(m):
            ax.plot(
                x[m],
                y[m],
                "-",
                color="tab:red",
                lw=9,
                alpha=0.45,
                solid_capstyle="butt",
                zorder=2,
                label="GNSS outage" if k == 0 else None,
            )


def _track_values(run: RecordedRun, sols: dict, show: list[str], truth: bool) -> dict:
    """The colour of each shown track: horizontal error [m], or without truth the stated
    horizontal 1-sigma [m]."""
    if truth:
        return {mid: _horizontal_to(run, sols[mid], True) for mid in show}
    return {mid: np.hypot(sols[mid].sigma[:, 0], sols[mid].sigma[:, 1]) for mid in show}


def plot_trajectory(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``trajectory.png``: the best filter's and smoother's tracks coloured by horizontal error."""
    plt = _plt()
    from matplotlib.collections import LineCollection

    show = best_methods(sols, metrics)
    truth = run.truth is not None
    fig, axes = plt.subplots(
        1, len(show), figsize=(6 * len(show) + 1.5, 6.5), squeeze=False, layout="constrained"
    )
    fx = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h)
    tracks = {mid: run.origin.to_ned(sols[mid].lat, sols[mid].lon, sols[mid].h) for mid in show}
    tr = run.origin.to_ned(run.truth.lat, run.truth.lon, run.truth.h) if truth else None
    frame = TrackFrame(
        np.concatenate([p[:, [1, 0]] for p in tracks.values()] + ([tr[:, [1, 0]]] if truth else []))
    )
    values = _track_values(run, sols, show, truth)
    every = np.concatenate([v[np.isfinite(v)] for v in values.values()] + [np.zeros(1)])
    vmax = max(float(np.percentile(every, 98)), 1e-3)
    clipped = float(every.max()) > vmax
    for ax, mid in zip(axes[0], show, strict=True):
        sol, p = sols[mid], tracks[mid]
        x, y = frame.xy(p[:, 1], p[:, 0])
        ax.plot(
            *frame.xy(fx[:, 1], fx[:, 0]), ".", ms=2.5, color="0.6", label="GNSS fixes", zorder=1
        )
        if truth:
            ax.plot(
                *frame.xy(tr[:, 1], tr[:, 0]), "-", color="0.2", lw=0.8, label="truth", zorder=4
            )
        seg = np.stack([np.column_stack([x[:-1], y[:-1]]), np.column_stack([x[1:], y[1:]])], axis=1)
        lc = LineCollection(
            seg, array=values[mid][:-1], cmap="viridis", clim=(0, vmax), lw=2.5, zorder=3
        )
        ax.add_collection(lc)
        _mark_outages(ax, run, sol, x, y)
        ax.plot(x[0], y[0], "^", color="tab:green", ms=11, mec="k", zorder=5, label="start")
        ax.plot(x[-1], y[-1], "s", color="tab:red", ms=10, mec="k", zorder=5, label="end")
        xs, ys = [x], [y]
        if truth:
            tx, ty = frame.xy(tr[:, 1], tr[:, 0])
            xs.append(tx)
            ys.append(ty)
        _fit(ax, np.concatenate(xs), np.concatenate(ys))
        frame.label(ax)
        ax.set_title(mid)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="best")
    cb = fig.colorbar(lc, ax=axes[0].tolist(), shrink=0.8, extend="max" if clipped else "neither")
    what = "horizontal error [m]" if truth else "stated horizontal 1-sigma [m] (no truth)"
    clip = f", clipped at {vmax:.2f} (98th percentile; max {every.max():.2f})" if clipped else ""
    cb.set_label(what + clip)
    fig.suptitle(
        f"{run.name}: track, {frame.note()}\n(origin {np.degrees(run.origin.lat0):.5f}, "
        f"{np.degrees(run.origin.lon0):.5f} deg)",
        fontsize=10,
    )
    _save(fig, path)


def _fit(ax, x: np.ndarray, y: np.ndarray) -> None:
    """Limits around the track and truth (fixes outside them are cut), with a margin."""
    ok = np.isfinite(x) & np.isfinite(y)
    for lim, v in ((ax.set_xlim, x[ok]), (ax.set_ylim, y[ok])):
        pad = 0.05 * max(np.ptp(v), 1.0)
        lim(v.min() - pad, v.max() + pad)


# --------------------------------------------------------------------------------------------
# errors.png, velocity_attitude.png, biases.png
# --------------------------------------------------------------------------------------------


def _band_plot(ax, t, e, s, mid, fill: bool = True) -> None:
    """The error line between its +-3 sigma edges (thin lines in its colour), the band filled
    lightly only when ``fill`` (a panel with one method: several fills make one opaque block)."""
    st = style(mid)
    if fill:
        ax.fill_between(t, -3 * s, 3 * s, color=st["color"], alpha=BAND_ALPHA, lw=0)
    for sign in (-3, 3):
        ax.plot(t, sign * s, color=st["color"], lw=0.7, alpha=0.7, ls=st["ls"])
    ax.plot(t, e, label=mid, **st)


def _ylim(ax, arrays) -> None:
    arrays = [np.abs(a[np.isfinite(a)]) for a in arrays]
    arrays = [a for a in arrays if len(a)]
    if arrays:
        lim = np.percentile(np.concatenate(arrays), 98)
        if lim > 0:
            ax.set_ylim(-1.2 * lim, 1.2 * lim)


def plot_errors(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``errors.png``: N/E/D position error with +-3 sigma, filters and smoothers side by side,
    and the 3-D error on a log scale (the outage view)."""
    plt = _plt()
    fams = _families(sols)
    fig, axes = plt.subplots(
        4,
        len(fams),
        figsize=(7 * len(fams), 10),
        sharex=True,
        squeeze=False,
        gridspec_kw={"height_ratios": [1, 1, 1, 1.1]},
    )
    for c, (title, ids) in enumerate(fams):
        seen = {i: [] for i in range(3)}
        for mid in ids:
            sol = sols[mid]
            e = _errors(run, sol)[:, POS]
            t = sol.t - run.t_start
            for i in range(3):
                _band_plot(axes[i, c], t, e[:, i], sol.sigma[:, i], mid, fill=len(ids) == 1)
                seen[i] += [e[:, i], 3 * sol.sigma[:, i]]
            axes[3, c].semilogy(t, np.linalg.norm(e, axis=1), **style(mid))
        for i, axis in enumerate(("north", "east", "down")):
            _ylim(axes[i, c], seen[i])
            axes[i, c].set_ylabel(f"{axis} error [m]")
        axes[3, c].set_ylabel("3-D error [m], log")
        plain_log_axis(axes[3, c].yaxis)
        axes[0, c].set_title(f"{title}: estimate - truth, thin lines +-3 sigma")
        axes[0, c].legend(fontsize=8, ncol=2, loc="upper right")
        axes[3, c].set_xlabel("time since start [s]")
        for ax in axes[:, c]:
            _shade_outages(ax, run)
            ax.grid(alpha=0.3, which="both")
    note = " (grey: GNSS outages)" if run.outages else ""
    fig.suptitle(
        f"{run.name}: position error{note}; axes cut at the 98th percentile, the log row shows "
        "all; the with/without-acceleration difference: accel_effect.png"
    )
    fig.tight_layout()
    _save(fig, path)


def plot_velocity_attitude(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``velocity_attitude.png``: velocity N/E/D and roll/pitch/yaw errors of the best filter and
    smoother with +-3 sigma: a column for each part the truth has, none for what it lacks."""
    tr = run.truth
    parts = []
    if tr is not None and tr.v_n is not None:
        parts.append(("velocity", "m/s", "NED", slice(3, 6), 1.0))
    if tr is not None and tr.rpy is not None:
        parts.append(("attitude", "deg", ("roll", "pitch", "yaw"), slice(6, 9), math.degrees(1.0)))
    if not parts:
        raise NotDrawn("the truth has positions only (no velocity, no attitude) to compare with")
    plt = _plt()
    show = best_methods(sols, metrics)
    fig, axes = plt.subplots(
        3, len(parts), figsize=(6.5 * len(parts) + 0.5, 8.5), sharex=True, squeeze=False
    )
    for mid in show:
        sol = sols[mid]
        e = _errors(run, sol)
        t = sol.t - run.t_start
        for c, (_, _, _, sl, scale) in enumerate(parts):
            for i in range(3):
                k = sl.start + i
                if np.any(np.isfinite(e[:, k])):
                    sig = sol.sigma[:, k] * scale
                    _band_plot(axes[i, c], t, e[:, k] * scale, sig, mid, fill=len(show) == 1)
    for c, (name, unit, labels, _, _) in enumerate(parts):
        for i, lab in enumerate(labels):
            ax = axes[i, c]
            ax.set_ylabel(f"{lab} error [{unit}]")
            _shade_outages(ax, run)
            ax.grid(alpha=0.3)
            _ylim(ax, [np.asarray(ln.get_ydata(), float) for ln in ax.get_lines()])
        axes[0, c].set_title(f"{name} error, thin lines +-3 sigma")
        axes[2, c].set_xlabel("time since start [s]")
    axes[0, 0].legend(fontsize=8)
    missing = {"velocity", "attitude"} - {p[0] for p in parts}
    tail = f" (the truth has no {missing.pop()})" if missing else ""
    fig.suptitle(
        f"{run.name}: {' and '.join(p[0] for p in parts)} error of {', '.join(show)}{tail}"
    )
    fig.tight_layout()
    _save(fig, path)


def plot_biases(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``biases.png``: accelerometer [mg] and gyro [deg/h] bias estimates of the best filter and
    smoother with +-3 sigma (around the estimate), and the simulator's true biases when known."""
    plt = _plt()
    show = best_methods(sols, metrics)
    fig, axes = plt.subplots(2, 3, figsize=(14, 7), sharex=True)
    true = None
    if run.sim is not None and run.sim.bias is not None and len(run.sim.bias) == len(run.imu.t):
        ref = sols[show[0]]
        true = (ref.t, run.sim.bias.at(ref.t, run.imu.t))
    for r, (name, attr, sl) in enumerate(
        (("accelerometer bias", "b_a", BA), ("gyro bias", "b_g", BG))
    ):
        unit = STATE_GROUPS[3 + r][2]
        for i, ax in enumerate(axes[r]):
            k = sl.start + i
            for mid in show:
                sol = sols[mid]
                t, b, s = (
                    sol.t - run.t_start,
                    getattr(sol, attr)[:, i] * DISPLAY_SCALE[k],
                    sol.sigma[:, k] * DISPLAY_SCALE[k],
                )
                st = style(mid)
                ax.fill_between(t, b - 3 * s, b + 3 * s, color=st["color"], alpha=0.12, lw=0)
                ax.plot(t, b, label=mid, **st)
            if true is not None:
                ax.plot(
                    true[0] - run.t_start,
                    true[1][r][:, i] * DISPLAY_SCALE[k],
                    "k:",
                    lw=1.2,
                    label="true (simulator)",
                )
            ax.set_title(f"{name} {'xyz'[i]} [{unit}]")
            ax.grid(alpha=0.3)
            _shade_outages(ax, run)
    for ax in axes[1]:
        ax.set_xlabel("time since start [s]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"{run.name}: IMU bias estimates (body axes), shaded +-3 sigma")
    fig.tight_layout()
    _save(fig, path)


# --------------------------------------------------------------------------------------------
# nis.png
# --------------------------------------------------------------------------------------------


def _fix_distance_series(run: RecordedRun, sol: NavSolution) -> tuple[np.ndarray, np.ndarray]:
    """Times [s from start] and squared 3-D distance [m^2] of the solution (interpolated) to each fix."""
    g = run.gnss
    inside = (g.t >= sol.t[0]) & (g.t <= sol.t[-1])
    p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    f = run.origin.to_ned(g.lat[inside], g.lon[inside], g.h[inside])
    r = np.column_stack([np.interp(g.t[inside], sol.t, p[:, i]) for i in range(3)]) - f
    return g.t[inside] - run.t_start, np.sum(r**2, axis=1)


def fix_sigma_lines(run: RecordedRun, gnss_model: dict | None) -> list[tuple[float, str, str]]:
    """``[(value [m], label, line style)]``: the fixes' 3-D sigma as read (median), and as the
    estimators model it (``gnss_model``: ``sigma_scale`` times it, with the Gauss-Markov part
    ``gm_sigma_m`` added in quadrature), each labelled with what it is."""
    from ..prepare.fix_noise import FROM_SCATTER

    g = run.gnss
    read = float(np.median(np.linalg.norm(g.sigma_ned, axis=1)))
    if run.meta.get("fix_sigmas") == FROM_SCATTER:
        what = "the fixes' own scatter (they state no sigma)"
    elif not g.sigma_stated:
        what = "the configured default (the fixes state no sigma)"
    else:
        what = "the fixes' stated 3-D sigma, as read"
    lines = [(read, f"{what}: median {read:.2f} m", "--")]
    if gnss_model:
        white = float(gnss_model.get("sigma_scale", 1.0)) * np.asarray(g.sigma_ned)
        gm = np.broadcast_to(np.asarray(gnss_model.get("gm_sigma_m", 0.0), float), (3,))
        total = float(np.median(np.sqrt(np.sum(white**2 + gm**2, axis=1))))
        part = (
            f"white x {gnss_model.get('sigma_scale', 1.0):.3g} + Gauss-Markov "
            f"{np.linalg.norm(gm):.2f} m"
            if np.any(gm > 0)
            else f"x {gnss_model.get('sigma_scale', 1.0):.3g}, no Gauss-Markov part"
        )
        if abs(total - read) > 0.01 * read:
            lines.append((total, f"as the estimators model it ({part}): median {total:.2f} m", ":"))
        else:
            lines[0] = (read, lines[0][1] + f", as modelled ({part})", "--")
    return lines


def plot_nis(
    run: RecordedRun,
    sols: dict,
    metrics: dict,
    path: Path,
    window: int = 20,
    gnss_model: dict | None = None,
) -> None:
    """``nis.png``: EKF position NIS per dof (moving mean over ``window`` updates, never across an
    outage) against the chi-square band of such a mean, and every method's RMS distance to the
    fixes (moving, [m]) beside the fixes' 3-D sigma as read and as modelled
    (:func:`fix_sigma_lines`)."""
    from ..analysis.nis_series import band_of_mean, fraction_in_band, moving_mean

    plt = _plt()
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(12, 8.5), sharex=True)
    lo, hi = band_of_mean(window)
    ax.axhspan(
        lo, hi, color="tab:green", alpha=0.12, zorder=0, label=f"99.7 % band of a mean of {window}"
    )
    drawn = False
    for mid, sol in sols.items():
        t, nis = sol.stats.get("nis_pos_t"), sol.stats.get("nis_pos")
        if t is None or nis is None or not len(nis):
            continue
        t = np.asarray(t, float)
        frac = fraction_in_band(t, nis, window)
        label = mid + (f" (in band {100 * frac:.0f} % of the run)" if frac is not None else "")
        ax.plot(t - run.t_start, moving_mean(t, nis, window), label=label, **style(mid))
        drawn = True
    vel = False
    for mid, sol in sols.items():  # the GNSS velocities' NIS, where the run has them (dotted)
        t, nis = sol.stats.get("nis_vel_t"), sol.stats.get("nis_vel")
        if t is None or nis is None or not len(nis):
            continue
        line = {**style(mid), "ls": ":"}
        t = np.asarray(t, float)
        ax.plot(t - run.t_start, moving_mean(t, nis, window), label=f"{mid} velocity", **line)
        vel = True
    if not drawn:
        ax.text(0.5, 0.5, "no EKF innovations in this run", transform=ax.transAxes, ha="center")
    ax.set_yscale("log")
    plain_log_axis(ax.yaxis)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_ylabel("position NIS per dof" + (" (velocity dotted)" if vel else ""))
    ax.set_title(f"EKF innovations: moving mean of {window} updates (1 = consistent)")
    ax.legend(fontsize=8, ncol=2)
    for mid, sol in sols.items():
        t, d2 = _fix_distance_series(run, sol)
        if len(t):
            bx.plot(t, np.sqrt(moving_mean(t, d2, window)), label=mid, **style(mid))
    for value, label, ls in fix_sigma_lines(run, gnss_model):
        bx.axhline(value, color="0.2", lw=1.2, ls=ls, label=label)
    bx.set_yscale("log")
    plain_log_axis(bx.yaxis)
    bx.set_ylabel("RMS distance to the fixes [m]")
    bx.set_title(
        f"Distance to the raw fixes (moving RMS of {window} fixes): an estimate that uses them lies "
        "within their noise"
    )
    bx.set_xlabel("time since start [s]")
    bx.legend(fontsize=8, ncol=2)
    for a in (ax, bx):
        _shade_outages(a, run)
        a.grid(alpha=0.3, which="both")
    gaps = "; no mean spans a GNSS outage (grey)" if run.outages else ""
    fig.suptitle(f"{run.name}: consistency over time{gaps}")
    fig.tight_layout()
    _save(fig, path)


def plot_sigmas(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``sigmas.png``: 1-sigma of every error state vs time, one panel per state, one line per method."""
    plt = _plt()
    fig, axes = plt.subplots(5, 3, figsize=(14, 14), sharex=True)
    for row, (name, cols, unit, labels) in enumerate(STATE_GROUPS):
        for c, label in enumerate(labels):
            ax = axes[row, c]
            k = cols.start + c
            for mid, sol in sols.items():
                ax.semilogy(
                    sol.t - run.t_start, sol.sigma[:, k] * DISPLAY_SCALE[k], label=mid, **style(mid)
                )
            plain_log_axis(ax.yaxis)
            ax.set_title(f"{name} {label} [{unit}]", fontsize=9)
            ax.grid(alpha=0.3, which="both")
    for ax in axes[-1]:
        ax.set_xlabel("time since start [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"{run.name}: predicted 1-sigma per error state")
    fig.tight_layout()
    _save(fig, path)


def _accel_effect(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    from .accel_figure import plot_accel_effect

    plot_accel_effect(run, sols, metrics, path)


#: Figure name -> drawing function ``(run, sols, metrics, path)``.
FIGURES = {
    "summary": plot_summary,
    "accel_effect": _accel_effect,
    "trajectory": plot_trajectory,
    "errors": plot_errors,
    "velocity_attitude": plot_velocity_attitude,
    "nis": plot_nis,
    "biases": plot_biases,
    "sigmas": plot_sigmas,
}
#: Figures that need the truth, and why they are not drawn without it.
NEEDS_TRUTH = {
    "errors": "the run has no truth to measure errors against",
    "velocity_attitude": "the run has no truth to measure errors against",
}


def gnss_model_of(cfg) -> dict | None:
    """The fixes' noise model of a configuration as ``nis.png`` labels it: ``sigma_scale``,
    ``gm_sigma_m`` (3 values [m]), ``gm_tau_s``."""
    if cfg is None:
        return None
    return {
        "sigma_scale": float(cfg["gnss"]["sigma_scale"]),
        "gm_sigma_m": np.asarray(cfg.gnss_gm_sigma, float).tolist(),
        "gm_tau_s": np.asarray(cfg.gnss_gm_tau, float).tolist(),
    }


def write_figures(
    folder: Path, run: RecordedRun, sols: dict, metrics: dict, which: str = "basic", cfg=None
) -> dict:
    """Draw the figures of ``--plots which`` into ``folder`` (``cfg``: the run's configuration,
    for the fixes' noise model in ``nis.png``).

    Returns
    -------
    dict
        ``{name: None}`` for each figure written and ``{name: reason}`` for each one not drawn:
        a reason in words when the run's data cannot make it (no truth, no pair of methods ...),
        or, for a failure, a sentence naming the warning printed with its details (a failure
        costs that figure only).
    """
    from ..core.errors import warn_data
    from ..core.interrupts import raise_if_interrupted

    out = {}
    for name in PLOT_SETS[which]:
        if name in NEEDS_TRUTH and run.truth is None:
            out[name] = NEEDS_TRUTH[name]
            continue
        target = Path(folder) / f"{name}.png"
        try:
            if name == "nis":
                plot_nis(run, sols, metrics, target, gnss_model=gnss_model_of(cfg))
            else:
                FIGURES[name](run, sols, metrics, target)
            out[name] = None
        except NotDrawn as why:
            _plt().close("all")
            out[name] = str(why)
        except Exception as exc:
            raise_if_interrupted(exc)
            _plt().close("all")
            out[name] = "it could not be drawn (a fault in gnssacc: the run printed a warning)"
            detail = f"{type(exc).__name__}: {' '.join(str(exc).split())[:160]}"
            warn_data(f"{name}.png", f"not drawn: {detail}; the other outputs are complete")
    return out
