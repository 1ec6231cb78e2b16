"""What every figure shares: method colours and line styles, plain-number log axes, the
outage shading and the "not drawn, because ..." signal.

Inputs are matplotlib axes and method ids; outputs are styles and axis settings (no files)."""

from __future__ import annotations

import numpy as np

#: Fixed colours per method family, so that a method has the same colour in every figure and run.
COLOURS = {
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
#: The raw fixes' line (grey, dotted) wherever they are drawn beside the methods.
FIX_STYLE = {"color": "0.45", "ls": ":", "lw": 2.0}
#: Opacity of a +-3 sigma band: light enough that four of them do not make one opaque block.
BAND_ALPHA = 0.07


class NotDrawn(Exception):
    """A figure that cannot be drawn for the run's data; the message says why, in words
    (e.g. "the truth has neither velocity nor attitude")."""


def style(mid: str) -> dict:
    """Colour and line style of a method: an ``-online`` estimate dashed in its smoother's colour;
    a method without the acceleration drawn wider under the one with it, so that both are seen
    where they lie on top of each other."""
    base = mid.removesuffix("-online")
    aided = "-acc" in base or "-gm" in base
    return {
        "color": COLOURS.get(base, "C7"),
        "ls": "--" if mid.endswith("-online") else "-",
        "lw": 1.2 if aided else 2.4,
    }


def is_smoothed(mid: str) -> bool:
    """Whether a solution is a smoothed one (a smoother's own, not its online estimate)."""
    return mid.startswith("smoother") and not mid.endswith("-online")


def plt():
    """``matplotlib.pyplot`` on the file-only Agg backend (never needs a display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as pyplot

    return pyplot


#: Mantissas tried in turn for a log axis's ticks, coarse to fine.
MANTISSAS = ((1.0, 2.0, 5.0), (1.0, 1.5, 2.0, 3.0, 5.0, 7.0), tuple(float(m) for m in range(1, 10)))


def plain_log_ticks(lo: float, hi: float) -> list[float]:
    """Major tick values of a log axis over ``[lo, hi]``: the 1-2-5 steps inside it (thinned to
    decades when there are more than seven); over a narrower range the first of finer round steps
    (1-1.5-2-3-5-7, then every digit) to give two, else two or three rounded values inside it."""
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo <= 0 or hi <= lo:
        return []
    e0, e1 = int(np.floor(np.log10(lo))), int(np.ceil(np.log10(hi)))
    for mantissas in MANTISSAS:
        steps = [m * 10.0**e for e in range(e0, e1 + 1) for m in mantissas]
        ticks = [float(f"{v:.6g}") for v in steps if lo <= v <= hi]
        if len(ticks) > 7:  # decades only, then every other one
            ticks = [v for v in ticks if f"{v:.0e}".startswith("1")]
        while len(ticks) > 7:
            ticks = ticks[::2]
        if len(ticks) >= 2:
            return ticks
    inner = np.geomspace(lo, hi, 5)[1:-1]
    digits = 2 if hi / lo > 1.1 else 3
    return sorted({float(f"{v:.{digits}g}") for v in inner})


def plain_number(v: float) -> str:
    """A tick label in plain digits: ``0.02``, ``5``, ``300`` (never ``2x10^-2``)."""
    return f"{v:.12g}" if abs(v) >= 1e-4 else f"{v:.1g}"


def plain_log_axis(axis) -> None:
    """Label a log axis (``ax.xaxis`` / ``ax.yaxis``) in plain numbers at :func:`plain_log_ticks`,
    minor ticks unlabelled; the ticks follow the axis limits when they change later."""
    from matplotlib.ticker import Locator, FuncFormatter, NullFormatter

    class PlainLogLocator(Locator):
        def __call__(self):
            lo, hi = sorted(self.axis.get_view_interval())
            return plain_log_ticks(lo, hi)

    axis.set_major_locator(PlainLogLocator())
    axis.set_major_formatter(FuncFormatter(lambda v, _: plain_number(v)))
    axis.set_minor_formatter(NullFormatter())


def shade_outages(ax, run, label: bool = False) -> None:
    """Grey spans over the run's GNSS outages (time axis in seconds from the start)."""
    for k, (a, b) in enumerate(run.outages):
        ax.axvspan(
            a, b, color="0.85", zorder=0, lw=0, label="GNSS outage" if label and not k else None
        )


def split_at_gaps(t: np.ndarray, y: np.ndarray, factor: float = 3.0) -> np.ndarray:
    """``y`` with NaN inserted where ``t`` jumps by more than ``factor`` times its median step,
    so that a line is never drawn across a gap (a GNSS outage); returns ``(t, y)`` stacked as
    two rows of the same length."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    if len(t) < 3:
        return np.vstack([t, y])
    dt = np.diff(t)
    gaps = np.flatnonzero(dt > factor * np.median(dt))
    return np.vstack([np.insert(t, gaps + 1, np.nan), np.insert(y, gaps + 1, np.nan)])
