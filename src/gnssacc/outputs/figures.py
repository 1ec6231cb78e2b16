"""The figures of a result folder, one question each (``gnssacc run --plots all|basic|none``).

=========================  ====================================================================
``summary.png``            Which method, how good, how sure: horizontal error CDF (without truth:
                           distance to the raw fixes) beside each method's NEES (without truth:
                           NIS) against its consistent band.
``trajectory.png``         Where: the track (x east, y north, as ``evo`` draws the TUM export),
                           coloured by horizontal error (without truth: stated horizontal 1-sigma),
                           start and end marked, GNSS outages drawn over the track.
``errors.png``             Position error per axis with the shaded +-3 sigma band, filters and
                           smoothers in separate columns; a last row with the 3-D error on a log
                           scale, so that outages do not flatten the rest.
``velocity_attitude.png``  Velocity and roll/pitch/yaw error with +-3 sigma (needs that truth).
``nis.png``                Consistency over time: the EKFs' position NIS (moving mean) against the
                           chi-square band, and every method's distance to the fixes [m] beside
                           the fixes' stated sigma.
``biases.png``             Accelerometer and gyro bias estimates with +-3 sigma (and the simulator's
                           true biases when known).
``sigmas.png``             Predicted 1-sigma of every error state.
=========================  ====================================================================

``basic`` writes the first three, ``all`` every one. A figure that cannot be drawn costs only itself
(:func:`write_figures` says why in one line). Figures are saved at :data:`DPI` dots per inch, sized to be
read at 100 % on a laptop screen.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..core.display import DISPLAY_SCALE, STATE_GROUPS
from ..core.recording import RecordedRun
from ..core.solution import NavSolution
from ..core.states import BA, BG, POS

DPI = 100
#: The figures of each ``--plots`` choice, in the report's order.
PLOT_SETS = {
    "none": (),
    "basic": ("summary", "trajectory", "errors"),
    "all": ("summary", "trajectory", "errors", "velocity_attitude", "nis", "biases", "sigmas"),
}
#: Fixed colours per method family, so that a method has the same colour in every figure and run.
_COLOURS = {
    "ekf": "C0",
    "ekf-acc": "C1",
    "smoother": "C2",
    "smoother-acc": "C3",
    "ekf-accw": "C4",
    "smoother-accw": "C5",
    "ekf-gm": "C6",
    "smoother-gm": "C8",
    "ekf-vacc": "C9",
    "smoother-vacc": "saddlebrown",
    "ekf-vaccw": "olive",
    "smoother-vaccw": "teal",
}
#: Horizontal distance [m] under which the raw fixes' CDF is drawn (grey) in ``summary.png``.
FIX_STYLE = {"color": "0.45", "ls": ":", "lw": 2.0}


def style(mid: str) -> dict:
    """Colour and line style of a method: an ``-online`` estimate dashed in its smoother's colour."""
    base = mid.removesuffix("-online")
    return {
        "color": _COLOURS.get(base, "C7"),
        "ls": "--" if mid.endswith("-online") else "-",
        "lw": 1.4,
    }


def is_smoothed(mid: str) -> bool:
    """Whether a solution is a smoothed one (a smoother's own, not its online estimate)."""
    return mid.startswith("smoother") and not mid.endswith("-online")


def _plt():
    import matplotlib

    matplotlib.use("Agg")  # files only; never needs a display
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    fig.savefig(path, dpi=DPI)
    _plt().close(fig)


def _errors(run: RecordedRun, sol: NavSolution) -> np.ndarray:
    from ..analysis.observability import state_errors

    return state_errors(run, sol)


def _shade_outages(ax, run: RecordedRun) -> None:
    for a, b in run.outages:
        ax.axvspan(a, b, color="0.88", zorder=0, lw=0)


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


def _cdf(ax, d: np.ndarray, label: str, **kw) -> None:
    d = np.sort(d[np.isfinite(d)])
    if len(d):
        ax.plot(d, np.arange(1, len(d) + 1) / len(d), label=label, **kw)


def _horizontal_to(run: RecordedRun, sol: NavSolution, truth: bool) -> np.ndarray:
    """Horizontal distance [m] to the truth at the solution epochs, or to the fixes at theirs."""
    if truth:
        return np.hypot(*_errors(run, sol)[:, 0:2].T)
    g = run.gnss
    inside = (g.t >= sol.t[0]) & (g.t <= sol.t[-1])
    p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    f = run.origin.to_ned(g.lat[inside], g.lon[inside], g.h[inside])
    return np.hypot(*[np.interp(g.t[inside], sol.t, p[:, i]) - f[:, i] for i in range(2)])


def plot_summary(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``summary.png``: the horizontal error CDF and the consistency of each method (see module)."""
    plt = _plt()
    truth = run.truth is not None
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [1.6, 1]})
    dists = {mid: _horizontal_to(run, s, truth) for mid, s in sols.items()}
    for mid, d in dists.items():
        _cdf(ax, d, mid, **style(mid))
    if truth:
        from ..analysis.metrics import truth_at

        p_true, ok = truth_at(run, run.gnss.t)
        f = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h)
        _cdf(ax, np.hypot(*(f - p_true)[ok, 0:2].T), "raw fixes", **FIX_STYLE)
    top = max([np.nanpercentile(d, 98) for d in dists.values() if np.any(np.isfinite(d))] + [1e-3])
    ax.set_xlim(0, 1.1 * top)
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


def _plain_log_ticks(axis, lo: float, hi: float) -> None:
    """Label a log axis at 1-2-5 steps in plain numbers (or, over a narrow range, at two rounded
    values inside it), minor ticks unlabelled: over less than a decade matplotlib labels every
    minor tick in powers of ten, and the labels run into each other."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    steps = [m * 10.0**e for e in range(-4, 5) for m in (1.0, 2.0, 5.0)]
    ticks = [v for v in steps if lo <= v <= hi]
    if len(ticks) < 2:
        ticks = sorted({float(f"{v:.2g}") for v in np.geomspace(lo, hi, 4)[1:-1]})
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def _consistency_panel(ax, sols: dict, metrics: dict, truth: bool) -> None:
    """Each method's NEES (position, attitude) or NIS as dots on a log axis over its shaded band."""
    from ..analysis.consistency import band

    ids = list(sols)
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
            items.append(("D", {"value": nis, "band": [lo, hi]}, "NIS"))
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
                mfc="white" if label == "NIS" else None,
            )
    ax.set_xscale("log")
    _plain_log_ticks(ax.xaxis, *ax.get_xlim())
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_yticks(range(len(ids)))
    ax.set_yticklabels(ids)
    ax.invert_yaxis()
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
    values = {}
    for mid in show:
        sol = sols[mid]
        values[mid] = (
            np.hypot(*_errors(run, sol)[:, 0:2].T)
            if truth
            else np.hypot(sol.sigma[:, 0], sol.sigma[:, 1])
        )
    vmax = max(
        [np.nanpercentile(v, 98) for v in values.values() if np.any(np.isfinite(v))] + [1e-3]
    )
    for ax, mid in zip(axes[0], show):
        sol = sols[mid]
        p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
        ax.plot(fx[:, 1], fx[:, 0], ".", ms=2.5, color="0.7", label="GNSS fixes", zorder=1)
        if truth:
            tr = run.origin.to_ned(run.truth.lat, run.truth.lon, run.truth.h)
            ax.plot(tr[:, 1], tr[:, 0], "-", color="0.3", lw=0.8, label="truth", zorder=2)
        seg = np.stack(
            [np.column_stack([p[:-1, 1], p[:-1, 0]]), np.column_stack([p[1:, 1], p[1:, 0]])], axis=1
        )
        lc = LineCollection(
            seg, array=values[mid][:-1], cmap="viridis", clim=(0, vmax), lw=2.5, zorder=3
        )
        ax.add_collection(lc)
        for a, b in run.outages:
            m = (sol.t - run.t_start >= a) & (sol.t - run.t_start <= b)
            if np.any(m):
                ax.plot(
                    p[m, 1],
                    p[m, 0],
                    "-",
                    color="tab:red",
                    lw=6,
                    alpha=0.2,
                    zorder=2,
                    label="GNSS outage" if (a, b) == tuple(run.outages[0]) else None,
                )
        ax.plot(p[0, 1], p[0, 0], "^", color="tab:green", ms=11, mec="k", zorder=5, label="start")
        ax.plot(p[-1, 1], p[-1, 0], "s", color="tab:red", ms=10, mec="k", zorder=5, label="end")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(mid)
        ax.set_xlabel("east [m]")
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("north [m]")
    axes[0, 0].legend(fontsize=8, loc="best")
    cb = fig.colorbar(lc, ax=axes[0].tolist(), shrink=0.8)
    cb.set_label("horizontal error [m]" if truth else "stated horizontal 1-sigma [m] (no truth)")
    fig.suptitle(
        f"{run.name}: track, x east / y north (origin {np.degrees(run.origin.lat0):.5f}, "
        f"{np.degrees(run.origin.lon0):.5f} deg)"
    )
    _save(fig, path)


# --------------------------------------------------------------------------------------------
# errors.png, velocity_attitude.png, biases.png
# --------------------------------------------------------------------------------------------


def _band_plot(ax, t, e, s, mid) -> None:
    st = style(mid)
    ax.fill_between(t, -3 * s, 3 * s, color=st["color"], alpha=0.12, lw=0)
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
                _band_plot(axes[i, c], t, e[:, i], sol.sigma[:, i], mid)
                seen[i] += [e[:, i], 3 * sol.sigma[:, i]]
            axes[3, c].semilogy(t, np.linalg.norm(e, axis=1), **style(mid))
        for i, axis in enumerate(("north", "east", "down")):
            _ylim(axes[i, c], seen[i])
            axes[i, c].set_ylabel(f"{axis} error [m]")
        axes[3, c].set_ylabel("3-D error [m], log")
        axes[0, c].set_title(f"{title}: estimate - truth, shaded +-3 sigma")
        axes[0, c].legend(fontsize=8, ncol=2, loc="upper right")
        axes[3, c].set_xlabel("time since start [s]")
        for ax in axes[:, c]:
            _shade_outages(ax, run)
            ax.grid(alpha=0.3, which="both")
    note = " (grey: GNSS outages)" if run.outages else ""
    fig.suptitle(
        f"{run.name}: position error{note}; axes cut at the 98th percentile, the log row shows all"
    )
    fig.tight_layout()
    _save(fig, path)


def plot_velocity_attitude(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """``velocity_attitude.png``: velocity N/E/D and roll/pitch/yaw errors of the best filter and
    smoother with +-3 sigma."""
    tr = run.truth
    if tr is None or (tr.v_n is None and tr.rpy is None):
        raise ValueError("the truth has neither velocity nor attitude")
    plt = _plt()
    show = best_methods(sols, metrics)
    fig, axes = plt.subplots(3, 2, figsize=(13, 8.5), sharex=True)
    for mid in show:
        sol = sols[mid]
        e = _errors(run, sol)
        t = sol.t - run.t_start
        for c, (sl, scale) in enumerate(((slice(3, 6), 1.0), (slice(6, 9), math.degrees(1.0)))):
            for i in range(3):
                k = sl.start + i
                if np.any(np.isfinite(e[:, k])):
                    _band_plot(axes[i, c], t, e[:, k] * scale, sol.sigma[:, k] * scale, mid)
    for c, (name, unit, labels) in enumerate(
        (("velocity", "m/s", "NED"), ("attitude", "deg", ("roll", "pitch", "yaw")))
    ):
        for i, lab in enumerate(labels):
            ax = axes[i, c]
            ax.set_ylabel(f"{lab} error [{unit}]")
            _shade_outages(ax, run)
            ax.grid(alpha=0.3)
            lines = [ln.get_ydata() for ln in ax.get_lines()]
            _ylim(ax, [np.asarray(y, float) for y in lines])
            if not lines:
                ax.text(
                    0.5, 0.5, f"no {name} truth", transform=ax.transAxes, ha="center", color="0.5"
                )
        axes[0, c].set_title(f"{name} error, shaded +-3 sigma")
        axes[2, c].set_xlabel("time since start [s]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"{run.name}: velocity and attitude error of {', '.join(show)}")
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


def _moving_mean(x: np.ndarray, k: int) -> np.ndarray:
    k = max(1, min(k, len(x)))
    c = np.cumsum(np.insert(np.asarray(x, float), 0, 0.0))
    out = np.full(len(x), np.nan)
    out[k - 1 :] = (c[k:] - c[:-k]) / k
    return out


def _fix_distance_series(run: RecordedRun, sol: NavSolution) -> tuple[np.ndarray, np.ndarray]:
    """Times [s from start] and squared 3-D distance [m^2] of the solution (interpolated) to each fix."""
    g = run.gnss
    inside = (g.t >= sol.t[0]) & (g.t <= sol.t[-1])
    p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    f = run.origin.to_ned(g.lat[inside], g.lon[inside], g.h[inside])
    r = np.column_stack([np.interp(g.t[inside], sol.t, p[:, i]) for i in range(3)]) - f
    return g.t[inside] - run.t_start, np.sum(r**2, axis=1)


def plot_nis(run: RecordedRun, sols: dict, metrics: dict, path: Path, window: int = 20) -> None:
    """``nis.png``: EKF position NIS per dof (moving mean over ``window`` updates) against the
    chi-square band of such a mean, and every method's RMS distance to the fixes (moving, [m])
    beside the fixes' own stated 3-D sigma."""
    from scipy.stats import chi2

    plt = _plt()
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(12, 8), sharex=True)
    k = 3 * window
    lo, hi = chi2.ppf(0.0015, k) / k, chi2.ppf(0.9985, k) / k
    ax.axhspan(
        lo, hi, color="tab:green", alpha=0.12, zorder=0, label=f"99.7 % band of a mean of {window}"
    )
    drawn = False
    for mid, sol in sols.items():
        t, nis = sol.stats.get("nis_pos_t"), sol.stats.get("nis_pos")
        if t is None or nis is None or not len(nis):
            continue
        ax.plot(np.asarray(t) - run.t_start, _moving_mean(nis, window), label=mid, **style(mid))
        drawn = True
    vel = False
    for mid, sol in sols.items():  # the GNSS velocities' NIS, where the run has them (dotted)
        t, nis = sol.stats.get("nis_vel_t"), sol.stats.get("nis_vel")
        if t is None or nis is None or not len(nis):
            continue
        line = {**style(mid), "ls": ":"}
        ax.plot(
            np.asarray(t) - run.t_start, _moving_mean(nis, window), label=f"{mid} velocity", **line
        )
        vel = True
    if not drawn:
        ax.text(
            0.5,
            0.5,
            "no EKF innovations in this run",
            transform=ax.transAxes,
            ha="center",
            color="0.5",
        )
    ax.set_yscale("log")
    _plain_log_ticks(ax.yaxis, *ax.get_ylim())
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_ylabel("position NIS per dof" + (" (velocity dotted)" if vel else ""))
    ax.set_title(f"EKF innovations: moving mean of {window} updates (1 = consistent)")
    ax.legend(fontsize=8, ncol=3)
    for mid, sol in sols.items():
        t, d2 = _fix_distance_series(run, sol)
        if len(t):
            bx.plot(t, np.sqrt(_moving_mean(d2, window)), label=mid, **style(mid))
    sig3 = float(np.median(np.linalg.norm(run.gnss.sigma_ned, axis=1)))
    bx.axhline(
        sig3,
        color="0.3",
        lw=1.0,
        ls="--",
        label=f"the fixes' stated 3-D sigma (median {sig3:.2f} m)",
    )
    bx.set_yscale("log")
    _plain_log_ticks(bx.yaxis, *bx.get_ylim())
    bx.set_ylabel("RMS distance to the fixes [m]")
    bx.set_title(
        f"Distance to the raw fixes (moving RMS of {window} fixes): an estimate that uses them lies "
        "within their noise"
    )
    bx.set_xlabel("time since start [s]")
    bx.legend(fontsize=8, ncol=3)
    for a in (ax, bx):
        _shade_outages(a, run)
        a.grid(alpha=0.3, which="both")
    fig.suptitle(f"{run.name}: consistency over time")
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
            ax.set_title(f"{name} {label} [{unit}]", fontsize=9)
            ax.grid(alpha=0.3, which="both")
    for ax in axes[-1]:
        ax.set_xlabel("time since start [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"{run.name}: predicted 1-sigma per error state")
    fig.tight_layout()
    _save(fig, path)


#: Figure name -> drawing function ``(run, sols, metrics, path)``.
FIGURES = {
    "summary": plot_summary,
    "trajectory": plot_trajectory,
    "errors": plot_errors,
    "velocity_attitude": plot_velocity_attitude,
    "nis": plot_nis,
    "biases": plot_biases,
    "sigmas": plot_sigmas,
}
#: Figures that need the truth.
NEEDS_TRUTH = {"errors", "velocity_attitude"}


def write_figures(
    folder: Path, run: RecordedRun, sols: dict, metrics: dict, which: str = "basic"
) -> dict:
    """Draw the figures of ``--plots which`` into ``folder``.

    Returns
    -------
    dict
        ``{name: None}`` for each figure written and ``{name: reason}`` (one line) for each one not
        drawn (no truth, or a failure: it costs that figure only, and is said as a warning).
    """
    from ..core.errors import warn_data
    from ..core.interrupts import raise_if_interrupted

    out = {}
    for name in PLOT_SETS[which]:
        if name in NEEDS_TRUTH and run.truth is None:
            out[name] = "no truth"
            continue
        try:
            FIGURES[name](run, sols, metrics, Path(folder) / f"{name}.png")
            out[name] = None
        except Exception as exc:
            raise_if_interrupted(exc)
            _plt().close("all")
            out[name] = f"{type(exc).__name__}: {' '.join(str(exc).split())[:160]}"
            if not (name == "velocity_attitude" and isinstance(exc, ValueError)):
                warn_data(f"{name}.png", f"not drawn: {out[name]}; the other outputs are complete")
    return out
