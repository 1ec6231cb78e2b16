"""``accel_effect.png``: what the GNSS-derived acceleration changes, the comparison the tool exists
for, which the overlapping curves of ``summary.png`` and ``errors.png`` cannot show.

Inputs: the run and its solutions (:func:`gnssacc.analysis.accel_effect.accel_effects` pairs
them); output: one row per pair (``ekf-acc - ekf``, ``smoother-acc - smoother``), the paired
difference per epoch on the left and its distribution on the right, on the same axis, with the
mean and its 95 % interval.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.recording import RecordedRun
from .figstyle import NotDrawn, plt, shade_outages, style


def _verdict(e) -> str:
    """The pair's effect in words: "smaller by 0.12 m", "larger by ...", or "not told apart"."""
    if not np.isfinite(e.lo):
        return "too few epochs for an interval"
    if not e.decided:
        return "not told from zero"
    return f"{'smaller' if e.mean < 0 else 'larger'} with the acceleration"


def _decimals(e) -> int:
    """Decimals that show the interval's width and its bounds (their sign against zero) with
    two significant digits: at least 3, at most 5."""
    sizes = [abs(v) for v in (e.hi - e.lo, e.lo, e.hi, e.mean) if np.isfinite(v) and v != 0]
    return int(np.clip(1 - np.floor(np.log10(min(sizes))), 3, 5)) if sizes else 3


def _limits(d: np.ndarray) -> tuple[float, float]:
    """The y range: the central 98 % of the differences, symmetric about zero."""
    lim = float(np.percentile(np.abs(d), 98)) * 1.25
    return (-lim, lim) if lim > 0 else (-1e-3, 1e-3)


def plot_accel_effect(run: RecordedRun, sols: dict, metrics: dict, path: Path) -> None:
    """Draw ``accel_effect.png`` (see module); :class:`NotDrawn` when the run has no method both
    with and without the acceleration."""
    from ..analysis.accel_effect import accel_effects

    effects = accel_effects(run, sols)
    if not effects:
        raise NotDrawn(
            "the run has no method both with and without the acceleration (ekf and ekf-acc, or "
            "smoother and smoother-acc)"
        )
    pyplot = plt()
    fig, axes = pyplot.subplots(
        len(effects),
        2,
        figsize=(13, 3.6 * len(effects) + 0.8),
        squeeze=False,
        gridspec_kw={"width_ratios": [3, 1]},
    )
    what = "horizontal error" if effects[0].truth else "horizontal distance to the raw fixes"
    for row, e in zip(axes, effects, strict=True):
        ax, hx = row
        colour = style(e.aided)["color"]
        t = e.t - run.t_start
        ax.plot(t, e.d, color=colour, lw=0.8)
        ylim = _limits(e.d)
        for a in (ax, hx):
            a.axhline(0.0, color="k", lw=0.8)
            if np.isfinite(e.lo):
                a.axhspan(e.lo, e.hi, color=colour, alpha=0.25, lw=0)
            a.axhline(e.mean, color=colour, lw=1.6, ls="--")
            a.set_ylim(*ylim)
            a.grid(alpha=0.3)
        shade_outages(ax, run, label=True)
        ax.set_ylabel(f"{e.aided} - {e.base} [m]")
        ax.set_title(
            f"{e.aided} minus {e.base}: {what} per epoch (below 0: the acceleration helps)",
            fontsize=10,
        )
        inside = e.d[(e.d >= ylim[0]) & (e.d <= ylim[1])]
        hx.hist(inside, bins=40, orientation="horizontal", color=colour, alpha=0.6)
        n = _decimals(e)
        rel = (
            f" ({100 * e.mean / e.base_mean:+.1f} % of {e.base}'s mean)" if e.base_mean > 0 else ""
        )
        hx.set_title(
            f"mean {e.mean:+.{n}f} m{rel}\n95 % interval {e.lo:+.{n}f} .. {e.hi:+.{n}f} m\n"
            f"{_verdict(e)}",
            fontsize=8,
        )
        hx.set_xlabel("epochs")
        hx.tick_params(labelleft=False)
    axes[-1, 0].set_xlabel("time since start [s]")
    if run.outages:
        axes[0, 0].legend(fontsize=8, loc="upper right")
    fig.suptitle(
        f"{run.name}: what the GNSS-derived acceleration changes (paired, same epochs)\n"
        f"dashed: mean, band: its 95 % interval from {effects[0].n_batches} batch means"
        + ("" if effects[0].truth else "; no truth: agreement with the fixes, not accuracy"),
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    pyplot.close(fig)
