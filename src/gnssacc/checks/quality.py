"""IMU data-quality check, usable on the IMU samples of any source.

Four kinds of defect are flagged, each as a :class:`Span` of suspect IMU samples:

``interpolated``
    Every channel lies on a straight line (second differences below ``quality.interp_tol``) for
    at least ``quality.interp_min_s`` seconds: the logger filled a dropout by linear
    interpolation, so the samples carry no information about what the vehicle really did.
    (The KITTI IMU file shipped with gtsam has eight such stretches of about 1.55 s.)
``gap``
    An interval longer than ``quality.gap_factor`` times the median interval. The span is the
    one sample that closes the gap, because that sample is held over the whole gap interval.
``frozen``
    All channels repeat exactly (first difference exactly zero) for at least
    ``quality.stuck_min_samples`` samples. Frozen data is constant; interpolated data is not.
``saturated``
    A single channel sits at its extreme over the run (max or min) for at least
    ``quality.stuck_min_samples`` consecutive samples, and that extreme is far from the channel's
    typical level (more than :data:`SATURATION_ROBUST_SIGMAS` robust standard deviations from its
    median), so clipping is caught while a quiet static channel is not.

Sample ``k`` holds over the interval ``(t[k-1], t[k]]`` (see :class:`gnssacc.core.recording.ImuData`), so a
span of samples ``i_start .. i_end-1`` covers the time ``t[i_start-1] .. t[i_end-1]``; that is
what ``Span.t_start`` / ``Span.t_end`` hold and what :func:`inflation_psd` uses as the span
duration.

Everything is vectorised over the samples: a 47k-sample file is checked in a few milliseconds.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import NamedTuple

import numpy as np

from ..core.config import DEG, RunConfig
from ..core.memo import LastMade
from ..core.recording import ImuData, gap_indices

#: Channel names, in the column order of the stacked ``[f_b, omega_ib_b]`` array (as in imu.csv).
CHANNELS = ("ax", "ay", "az", "gx", "gy", "gz")

#: Kinds of defect, in report order.
KINDS = ("interpolated", "gap", "frozen", "saturated")

#: A channel's extreme counts as clipping only this many robust sigmas (1.4826 MAD) from its median.
SATURATION_ROBUST_SIGMAS = 8.0


@dataclass
class Span:
    """A stretch of suspect IMU samples.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    t_start, t_end : float
        Time covered by the suspect samples, ``t[i_start-1] .. t[i_end-1]`` [s] (IMU clock).
    i_start, i_end : int
        Suspect sample indices ``i_start <= k < i_end`` (``i_end`` exclusive).
    channels : str
        ``"all"`` or the comma-separated channels concerned (``ax .. gz``).
    note : str
        A short human-readable account (values, lengths).
    """

    kind: str
    t_start: float
    t_end: float
    i_start: int
    i_end: int
    channels: str
    note: str

    @property
    def duration_s(self) -> float:
        return self.t_end - self.t_start

    @property
    def n_samples(self) -> int:
        return self.i_end - self.i_start


@dataclass
class QualityReport:
    """Result of :func:`check_imu`.

    Attributes
    ----------
    spans : list of Span
        Suspect stretches, sorted by start sample.
    n_samples : int
        Number of IMU samples checked.
    dt_median_s, dt_max_s : float
        Median and largest sampling interval [s].
    """

    spans: list[Span] = field(default_factory=list)
    n_samples: int = 0
    dt_median_s: float = float("nan")
    dt_max_s: float = float("nan")

    def of_kind(self, kind: str) -> list[Span]:
        """The spans of one kind."""
        return [s for s in self.spans if s.kind == kind]

    def totals(self) -> dict[str, dict]:
        """Per kind: number of spans, total seconds and total samples (overlaps not merged)."""
        out = {}
        for kind in KINDS:
            spans = self.of_kind(kind)
            out[kind] = {
                "count": len(spans),
                "seconds": float(sum(s.duration_s for s in spans)),
                "samples": int(sum(s.n_samples for s in spans)),
            }
        return out

    def summary(self) -> str:
        """One line per kind with the number of spans and their total duration."""
        lines = []
        for kind, tot in self.totals().items():
            lines.append(
                f"{kind:<12s} {tot['count']:4d} span(s) {tot['seconds']:9.3f} s "
                f"{tot['samples']:7d} sample(s)"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready description (plain Python types)."""
        return {
            "n_samples": int(self.n_samples),
            "dt_median_s": float(self.dt_median_s),
            "dt_max_s": float(self.dt_max_s),
            "totals": self.totals(),
            "spans": [
                {k: (float(v) if isinstance(v, np.floating) else v) for k, v in asdict(s).items()}
                for s in self.spans
            ],
        }

    def between(self, i0: int, i1: int) -> "QualityReport":
        """The report of samples ``i0 .. i1 - 1`` alone (:meth:`RecordedRun.between
        <gnssacc.core.recording.RecordedRun.between>`): the spans that reach into them, their
        sample indices counted from ``i0`` (those cut by an end run past it, as the inflation
        clips them)."""
        spans = [
            replace(s, i_start=s.i_start - i0, i_end=s.i_end - i0)
            for s in self.spans
            if s.i_end > i0 and s.i_start < i1
        ]
        return replace(self, spans=spans, n_samples=max(0, i1 - i0))

    def suspect_mask(self, n: int) -> np.ndarray:
        """Boolean array of length ``n``, True on every sample inside any span."""
        edges = np.zeros(n + 1, int)
        for s in self.spans:
            i0, i1 = max(s.i_start, 0), min(s.i_end, n)
            if i1 > i0:
                edges[i0] += 1
                edges[i1] -= 1
        return np.cumsum(edges[:-1]) > 0


# --- helpers ---------------------------------------------------------------------------------------


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and (exclusive) end indices of the runs of True in a boolean array."""
    edges = np.diff(np.concatenate(([0], np.asarray(mask, np.int8), [0])))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def _span(kind: str, t: np.ndarray, i_start: int, i_end: int, channels: str, note: str) -> Span:
    # Samples i_start..i_end-1 hold over (t[i_start-1], t[i_end-1]]; sample 0 covers no interval.
    t_start = float(t[max(i_start - 1, 0)])
    return Span(kind, t_start, float(t[i_end - 1]), int(i_start), int(i_end), channels, note)


def _sensors(imu: ImuData) -> tuple[np.ndarray, np.ndarray]:
    """The IMU's ``f_b`` and ``omega_ib_b`` (N, 3) as float arrays (SI units, body frame): the
    checks read them in place, never as one (N, 6) copy of the run."""
    return np.asarray(imu.f_b, float), np.asarray(imu.omega_ib_b, float)


def _rows(x: tuple[np.ndarray, np.ndarray], a: int, b: int) -> np.ndarray:
    """Rows ``a .. b-1`` of the channels :data:`CHANNELS` as one (b - a, 6) block."""
    return np.hstack([x[0][a:b], x[1][a:b]])


def _channel(x: tuple[np.ndarray, np.ndarray], c: int) -> np.ndarray:
    """Channel ``c`` of :data:`CHANNELS` (a view)."""
    return x[c // 3][:, c % 3]


# --- the four checks -------------------------------------------------------------------------------

#: Rows of the IMU table the interpolation check differences at once: its temporaries (first and
#: second differences, chord distances: about ten copies of a block, ~8 MiB) stay bounded whatever the
#: run length.
CHECK_BLOCK_ROWS = 16_384


def _straight(t: np.ndarray, x: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Per centre sample ``j + 1`` (``j = 0 .. N-3``): whether it lies on the line through its
    neighbours, and its largest absolute second difference over the channels."""
    d1 = np.diff(x, axis=0)
    d2 = np.diff(d1, axis=0)  # index j: centre sample j+1
    # Loggers interpolate either per sample index or in time; with jittered time stamps only
    # the time-aware form vanishes, so accept either. The time-aware form is twice the distance
    # of the centre sample from the chord through its neighbours,
    # e2 = 2 (h1 d1[j] - h0 d1[j+1]) / (h0 + h1), which equals -d2 for uniform sampling.
    h0 = (t[1:-1] - t[:-2])[:, None]
    h1 = (t[2:] - t[1:-1])[:, None]
    e2_scaled = np.abs(h1 * d1[:-1] - h0 * d1[1:])  # = |e2| (h0 + h1) / 2
    worst = np.abs(d2).max(axis=1)
    straight = (worst < tol) | (e2_scaled.max(axis=1) < 0.5 * tol * (h0 + h1)[:, 0])
    # A constant stretch is also straight: leave it to the frozen check.
    still = np.all(d1 == 0.0, axis=1)
    return straight & ~(still[:-1] & still[1:]), worst


def _interpolated(
    t: np.ndarray, x: tuple[np.ndarray, np.ndarray], tol: float, min_s: float
) -> list[Span]:
    if len(t) < 3:
        return []
    n = len(t) - 2
    straight, worst = np.empty(n, bool), np.empty(n)
    for a in range(0, n, CHECK_BLOCK_ROWS):  # centres a+1 .. b need samples a .. b+1
        b = min(a + CHECK_BLOCK_ROWS, n)
        straight[a:b], worst[a:b] = _straight(t[a : b + 2], _rows(x, a, b + 2), tol)
    spans = []
    for s, f in zip(*_runs(straight)):
        i0, i1 = s + 1, f + 1  # the centres; the two end samples are the real anchors
        if t[i1 - 1] - t[i0 - 1] >= min_s:
            spans.append(
                _span(
                    "interpolated",
                    t,
                    i0,
                    i1,
                    "all",
                    f"{i1 - i0} samples on straight lines (max |second difference| "
                    f"{float(worst[s:f].max()):.1e})",
                )
            )
    return spans


def _gaps(t: np.ndarray, factor: float) -> tuple[list[Span], float, float]:
    idx, dt, dt_med = gap_indices(t, factor)
    if not len(dt):
        return [], float("nan"), float("nan")
    spans = [
        _span(
            "gap",
            t,
            k + 1,
            k + 2,
            "all",
            f"interval {dt[k]:.4f} s = {dt[k] / dt_med:.1f} x median {dt_med:.4f} s",
        )
        for k in idx
    ]
    return spans, dt_med, float(dt.max())


def _frozen(t: np.ndarray, x: tuple[np.ndarray, np.ndarray], min_samples: int) -> list[Span]:
    if len(t) < 2:
        return []
    # index k: sample k+1 repeats sample k (sensor by sensor, no float temporary)
    still = np.all(x[0][1:] == x[0][:-1], axis=1) & np.all(x[1][1:] == x[1][:-1], axis=1)
    spans = []
    for s, f in zip(*_runs(still)):
        if f - s >= min_samples:
            # The first sample of the run is the last real reading; its repeats are suspect.
            spans.append(
                _span(
                    "frozen",
                    t,
                    s + 1,
                    f + 1,
                    "all",
                    f"all channels repeat sample {s} exactly {f - s} times",
                )
            )
    return spans


def _saturated(t: np.ndarray, x: tuple[np.ndarray, np.ndarray], min_samples: int) -> list[Span]:
    spans = []
    for c, name in enumerate(
        CHANNELS
    ):  # channel by channel: a long run's temporaries stay one column
        col = _channel(x, c)
        med = float(np.median(col))
        dev = col - med  # one work column, reused in place
        np.abs(dev, out=dev)
        # A coarsely quantised channel can have MAD = 0; fall back to the plain std then.
        sigma = 1.4826 * float(np.median(dev, overwrite_input=True)) or float(np.std(col))
        if sigma == 0:
            continue  # constant channel: nothing to tell apart
        for which, ext in (("max", col.max()), ("min", col.min())):
            far = abs(ext - med) / sigma
            if far <= SATURATION_ROBUST_SIGMAS:
                continue
            np.subtract(col, ext, out=dev)
            at_ext = np.abs(dev, out=dev) <= 1e-9 * max(abs(ext), 1.0)
            for s, f in zip(*_runs(at_ext)):
                if f - s >= min_samples:
                    spans.append(
                        _span(
                            "saturated",
                            t,
                            s,
                            f,
                            name,
                            f"{name} held at its {which} {ext:.6g} for {f - s} samples "
                            f"({far:.0f} robust sigma from its median {med:.4g})",
                        )
                    )
    return spans


def check_imu(imu: ImuData, cfg: RunConfig) -> QualityReport:
    """Flag interpolated, gap, frozen and saturated stretches in IMU data.

    Parameters
    ----------
    imu : ImuData
        IMU samples (times [s], specific force [m/s^2] and angular rate [rad/s], any frame:
        the checks are per channel and frame-independent).
    cfg : RunConfig
        Uses the ``[quality]`` keys ``interp_tol`` (absolute, SI units of each channel),
        ``interp_min_s``, ``gap_factor`` and ``stuck_min_samples``.

    Returns
    -------
    QualityReport
        Spans sorted by start sample; see the module docstring for the definitions.
    """
    q = cfg["quality"]
    t = np.asarray(imu.t, float)
    x = _sensors(imu)
    stuck = int(q["stuck_min_samples"])
    gaps, dt_med, dt_max = _gaps(t, float(q["gap_factor"]))
    spans = (
        _interpolated(t, x, float(q["interp_tol"]), float(q["interp_min_s"]))
        + gaps
        + _frozen(t, x, stuck)
        + (_saturated(t, x, stuck) if len(t) else [])
    )
    spans.sort(key=lambda s: (s.i_start, KINDS.index(s.kind)))
    return QualityReport(spans, len(t), dt_med, dt_max)


def inflation_psd(
    imu: ImuData, report: QualityReport, suspect: SuspectNoise
) -> tuple[np.ndarray, np.ndarray]:
    """Extra white-noise PSD per IMU sample and channel, to de-weight suspect samples.

    Over a flagged span of duration ``T`` each channel's reading is treated as wrong by an
    unknown constant of 1-sigma ``s``, which leaves an angle (velocity) error of variance
    ``(s T)^2`` at the end of the span. The estimators only take white noise, so the same
    end-of-span variance is expressed as white noise of PSD ``q = s^2 T`` on every sample of the
    span: ``sum_k q dt_k = s^2 T * T``. Estimators add ``q[k] * dt_k`` to the variance of
    sample ``k`` on that body axis.

    ``s`` per channel (``quality.suspect_sigma_mode``): ``"local"``, the channel's standard
    deviation over the clean samples within ``quality.suspect_local_window_s`` on both sides of
    the span, capped by ``suspect_gyro_sigma_dps`` / ``suspect_accel_sigma_mps2`` (a car's roll
    rate barely varies around a turn, its yaw rate does, and the inflation follows); ``"fixed"``,
    those caps on every channel. Saturated spans inflate only the sensor that clipped (gyro for
    ``g*``, accelerometer for ``a*``); all other kinds inflate both. Where spans overlap the
    larger PSD is kept, so a sample is not counted twice.

    Returns
    -------
    q_gyro_extra : ndarray, shape (N, 3)
        Additive gyro white-noise PSD per body axis [rad^2/s].
    q_accel_extra : ndarray, shape (N, 3)
        Additive accelerometer white-noise PSD per body axis [(m/s^2)^2/s].
    """
    seg = inflation_segments(imu, report, suspect)
    q_gyro = np.zeros((len(imu), 3))
    q_accel = np.zeros((len(imu), 3))
    for a, b, qg, qa in zip(seg.i0, seg.i1, seg.q_gyro, seg.q_accel):
        q_gyro[a:b] = qg
        q_accel[a:b] = qa
    return q_gyro, q_accel


@dataclass(frozen=True)
class SuspectNoise:
    """The error assumed over a suspect span (``[quality]``): per channel either ``"local"``, its
    standard deviation over the clean samples within ``local_window_s`` [s] on both sides, capped
    by ``gyro_sigma_dps`` [deg/s] / ``accel_sigma_mps2`` [m/s^2], or ``"fixed"``, those caps."""

    mode: str
    local_window_s: float
    gyro_sigma_dps: float
    accel_sigma_mps2: float

    @classmethod
    def from_config(cls, cfg: RunConfig) -> "SuspectNoise":
        q = cfg["quality"]
        return cls(
            str(q["suspect_sigma_mode"]),
            float(q["suspect_local_window_s"]),
            float(q["suspect_gyro_sigma_dps"]),
            float(q["suspect_accel_sigma_mps2"]),
        )


def _span_sigmas(
    imu: ImuData, span: Span, clean: np.ndarray, suspect: SuspectNoise
) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel 1-sigma (gyro [rad/s], accel [m/s^2]) of the error assumed over a span."""
    cap_g = suspect.gyro_sigma_dps * DEG
    cap_a = suspect.accel_sigma_mps2
    if suspect.mode == "fixed":
        return np.full(3, cap_g), np.full(3, cap_a)
    w = suspect.local_window_s
    lo = int(np.searchsorted(imu.t, span.t_start - w))
    hi = int(np.searchsorted(imu.t, span.t_end + w, side="right"))
    around = np.arange(lo, hi)
    around = around[clean[lo:hi] & ((around < span.i_start) | (around >= span.i_end))]
    if around.size < 5:
        return np.full(3, cap_g), np.full(3, cap_a)
    return (
        np.minimum(imu.omega_ib_b[around].std(axis=0), cap_g),
        np.minimum(imu.f_b[around].std(axis=0), cap_a),
    )


class InflationSegments(NamedTuple):
    """Suspect IMU spans as sorted, disjoint sample segments with their extra noise.

    Attributes
    ----------
    i0, i1 : ndarray of int, shape (S,)
        Segment sample ranges ``[i0, i1)``, sorted and disjoint.
    q_gyro, q_accel : ndarray, shape (S, 3)
        Additive PSDs per body axis on each segment [rad^2/s], [(m/s^2)^2/s].
    """

    i0: np.ndarray
    i1: np.ndarray
    q_gyro: np.ndarray
    q_accel: np.ndarray

    def touch(self, k0: int, k1: int) -> bool:
        """Whether samples ``[k0, k1)`` overlap a segment (:func:`touches_segments`)."""
        return touches_segments(k0, k1, self.i0, self.i1)


def inflation_segments(
    imu: ImuData, report: QualityReport, suspect: SuspectNoise
) -> InflationSegments:
    """The inflation of :func:`inflation_psd` as non-overlapping sample segments.

    Memory is proportional to the number of suspect spans, not to the run length; this is
    what the estimators use. The last one made is given again for the same ``imu`` and
    ``report`` objects, unchanged, and ``suspect`` (the tuner's ~90 passes over one run ask for
    it each; made afresh it cost 3 ms a pass on KITTI's suspect spans). Not to be written to.
    """
    mark = (len(imu), float(imu.t[0]), float(imu.t[-1])) if len(imu) else None
    spans = tuple((s.i_start, s.i_end, s.kind, s.channels) for s in report.spans)
    key = (mark, spans, suspect)
    segments = _LAST_SEGMENTS.get((imu, report), key)
    if segments is None:
        segments = _LAST_SEGMENTS.keep((imu, report), key, _segments(imu, report, suspect))
    return segments


#: The last :func:`inflation_segments` made, from its IMU data and report and what else (one per
#: run: a windowed tuning's windows are runs of their own, :meth:`QualityReport.between`).
_LAST_SEGMENTS = LastMade(slots=8)


def _segments(imu: ImuData, report: QualityReport, suspect: SuspectNoise) -> InflationSegments:
    """:func:`inflation_segments` made afresh."""
    n = len(imu)
    clean = ~report.suspect_mask(n) if report.spans else np.ones(n, bool)
    spans = []
    for s in report.spans:
        a, b = max(s.i_start, 0), min(s.i_end, n)
        if b <= a:
            continue
        T = max(s.duration_s, 0.0)
        sg, sa = _span_sigmas(imu, s, clean, suspect)
        gyro = s.kind != "saturated" or s.channels.startswith("g")
        accel = s.kind != "saturated" or s.channels.startswith("a")
        spans.append(
            (a, b, sg**2 * T if gyro else np.zeros(3), sa**2 * T if accel else np.zeros(3))
        )
    # Split at every span edge; on each elementary piece keep the largest PSD of the spans covering it.
    edges = sorted({e for a, b, _, _ in spans for e in (a, b)})
    i0, i1, q_g, q_a = [], [], [], []
    for a, b in zip(edges[:-1], edges[1:]):
        cover = [(qg, qa) for s0, s1, qg, qa in spans if s0 <= a and b <= s1]
        if cover:
            i0.append(a)
            i1.append(b)
            q_g.append(np.max([c[0] for c in cover], axis=0))
            q_a.append(np.max([c[1] for c in cover], axis=0))
    if not i0:
        return InflationSegments(
            np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3))
        )
    return InflationSegments(
        np.array(i0, np.int64), np.array(i1, np.int64), np.array(q_g), np.array(q_a)
    )


def touches_segments(k0: int, k1: int, seg_i0: np.ndarray, seg_i1: np.ndarray) -> bool:
    """Whether samples ``[k0, k1)`` overlap any segment ``[i0, i1)`` of :func:`inflation_segments`."""
    return bool(np.any((seg_i0 < k1) & (seg_i1 > k0)))
