r"""The offset between the IMU clock and the GNSS clock, measured from the data.

The offset ``tau`` is what ``[mounting] imu_time_offset_s`` means: it is added to every IMU time
stamp to put it on the GNSS clock (an IMU stamped on UTC beside fixes on GPS time needs +18 s).

Two stages:

1. **Cross-correlation** (:func:`coarse_offset`), searching +-``max_offset_s`` (60 s). The signals
   are those of :mod:`gnssacc.checks.motionmatch`, which need no attitude, mounting or trusted units:
   first the magnitude of the GNSS-derived horizontal acceleration against the magnitude of the
   IMU's horizontal specific force, smoothed with the same kernel in a frame fixed on the ground
   (:func:`gnssacc.checks.motionmatch.smooth_horizontal`), on a 0.05 s lag grid (invariant to the
   heading, the mounting, mirror images and unit scale factors), taking the lag whose correlation
   is most significant over its overlap (:func:`_significance`: a long shift leaves a short
   overlap, whose chance correlations run high); then, within +-1 s of
   that peak at 10 ms, the complex correlation of the two in the GNSS velocity frame (the signs of
   the along- and across-track parts too; direct or mirrored, whichever fits). Its uncertainty is
   a block jackknife: the run is cut into :data:`JACKKNIFE_BLOCKS` pieces and the peak found
   again without each. The estimate counts as determined only when the peak stands out from the
   correlations at lags more than a window away (:data:`MIN_PEAK`, :data:`MIN_MARGIN`).
2. **Innovation likelihood** (:func:`refine_offset`): the EKF (position updates, the configured
   noise) is run with the IMU shifted by ``delta`` and the log-likelihood of its position
   innovations is maximised over ``delta`` within a bracket around stage 1 (scipy's bounded
   ``minimize_scalar``); the uncertainty comes from the curvature of the log-likelihood over a
   step of about two sigma (:data:`CURVATURE_DROP`: it is jagged on a smaller scale). This uses
   all the information the fixes hold and is run only when the offset is to be applied
   (``"auto"``) or stage 1 contradicts the configured offset.

What is attainable depends on the fixes. Measured on a simulated 120 s car run (consumer IMU):
1 Hz fixes with 5 cm white noise give a 1-sigma of ~4 ms, 0.5 m white ~17 ms, 3 m white ~70 ms;
stage 1 alone is good to a few tenths of a second with 3 m fixes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.recording import RecordedRun
from .motionmatch import GnssKinematics, LevelledImu, at_times, smooth_horizontal, velocity_frame

#: Largest offset searched [s]: clock mix-ups of whole seconds (GPS-UTC is 18 s since 2017) and
#: logger latencies; hours (time zones) are rejected by the overlap of the time spans instead.
MAX_OFFSET_S = 60.0
#: Lag step of the magnitude cross-correlation: this fraction of the smoothing window (the peak is
#: about a window wide and refined by a parabola, then by the complex correlation at 10 ms), but
#: at least COARSE_STEP_S [s].
COARSE_STEP_FRACTION = 1.0 / 60.0
COARSE_STEP_S = 0.05
#: Lag step of the complex correlation and the jackknife [s] (the 10 ms resolution asked for).
FINE_STEP_S = 0.01
JACKKNIFE_BLOCKS = 8
#: A peak is trusted when its correlation reaches MIN_PEAK and exceeds the best correlation at
#: lags more than a window away by MIN_MARGIN: with n_eff independent windows the correlation of
#: unrelated signals scatters by ~1/sqrt(n_eff) (0.3 for 12 windows), so a real peak of 0.8-0.95
#: (measured on simulated car and slow-UGV runs) stands clear while chance peaks do not.
MIN_PEAK = 0.5
MIN_MARGIN = 0.2
#: Most (lag, centre) pairs the correlations evaluate at once: bounds their temporaries (about
#: 80 bytes a pair) to a few MB whatever the run length (a 6000 s run has ~6000 centres and
#: thousands of lags); each lag's sums are over its own row, so the chunking changes no number.
CHUNK_ENTRIES = 65_536
#: Fewest comparison epochs for any verdict.
MIN_CENTRES = 12
#: Least GNSS acceleration signal-to-noise power ratio (:attr:`GnssKinematics.snr`) for a verdict:
#: below it the fixes show too little motion (a parked vehicle's fixes correlate only by chance).
MIN_SNR = 3.0
#: Least RMS of the IMU's smoothed horizontal specific force for a verdict [m/s^2]: a parked
#: vehicle's is its sensor noise averaged over seconds (~0.001-0.01), a driven one's, even a slow
#: UGV's, is several tenths.
MIN_IMU_RMS_MPS2 = 0.05
#: A real correlation peak is placed to within a fraction of the smoothing window: a jackknife
#: sigma above this fraction of it means the peak is not a feature of the whole run.
MAX_SIGMA_FRACTION = 0.25
#: Model error of stage 1, added in quadrature to its jackknife sigma [s]: it compares the
#: horizontal specific force (which holds the body's roll and pitch in corners and under braking,
#: with the suspension's lag) and course rates (which lead the heading by the wheelbase geometry,
#: l / v ~ 0.1-0.3 s) with the motion of a point; on the KITTI drive the two signals agree on a
#: peak 0.25 s from the EKF likelihood's.
STAGE1_MODEL_SIGMA_S = 0.1


@dataclass
class OffsetEstimate:
    """A measured IMU-to-GNSS clock offset.

    Attributes
    ----------
    offset_s : float
        To be added to the IMU time stamps [s].
    sigma_s : float
        Its 1-sigma [s].
    determined : bool
        Whether the data determine it (enough motion and a clear correlation peak).
    rho, rho_other : float
        Peak correlation and the best one more than a window away from it (stage 1).
    method : str
        ``"cross-correlation"`` or ``"EKF likelihood"``.
    """

    offset_s: float
    sigma_s: float
    determined: bool
    rho: float = float("nan")
    rho_other: float = float("nan")
    method: str = "cross-correlation"

    def text(self) -> str:
        return f"{self.offset_s:+.3f} s +- {self.sigma_s:.3f} s ({self.method})"


def _magnitude_rho(
    lev: LevelledImu, mag_s: np.ndarray, kin: GnssKinematics, lags: np.ndarray, edge: float
) -> tuple[np.ndarray, np.ndarray]:
    """Correlation of the GNSS acceleration magnitude with the smoothed IMU one per lag (lags in
    chunks, vectorised; lags overlapping fewer than a third of the centres give NaN), and the
    number of centres each was computed over."""
    g = np.hypot(kin.a[:, 0], kin.a[:, 1])
    out = np.full(len(lags), np.nan)
    count = np.zeros(len(lags))
    need = max(MIN_CENTRES, len(kin) // 3)
    chunk = max(int(CHUNK_ENTRIES // max(len(kin), 1)), 1)
    for j0 in range(0, len(lags), chunk):
        tq = kin.t[None, :] - lags[j0 : j0 + chunk, None]
        m = (tq >= lev.t0 + edge) & (tq <= lev.t_end - edge)
        x = at_times(lev.t0, lev.step, mag_s, tq.ravel()).reshape(tq.shape)
        n = m.sum(axis=1)
        n_safe = np.maximum(n, 1)
        mx, mg = (x * m).sum(1) / n_safe, (g * m).sum(1) / n_safe
        dx, dg = (x - mx[:, None]) * m, (g - mg[:, None]) * m
        den = np.sqrt((dx**2).sum(1) * (dg**2).sum(1))
        rho = np.where(
            (n >= need) & (den > 0), (dx * dg).sum(1) / np.where(den > 0, den, 1.0), np.nan
        )
        out[j0 : j0 + chunk] = rho
        count[j0 : j0 + chunk] = n
    return out, count


def _significance(rho: np.ndarray, count: np.ndarray, kin: GnssKinematics) -> np.ndarray:
    """Fisher's z of each lag's correlation times the square root of its independent windows
    less 3 (NaN with 3 or fewer): the standard normal score of a correlation that unrelated
    signals would give. Correlations over different overlaps compare on this scale only: a chance
    peak over a short overlap is high in ``rho`` but not in significance (60 s of highway driving
    with 8 s windows gave rho 0.94 at a lag of -32.6 s, over 3.4 windows, against 0.93 at the true
    lag over 6.5)."""
    step = float(np.median(np.diff(kin.t))) if len(kin) > 1 else kin.window_s
    dof = count * step / kin.window_s - 3.0
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.arctanh(np.clip(rho, -0.999999, 0.999999)) * np.sqrt(np.where(dof > 0, dof, np.nan))
    return z


def _complex_rho(
    lev: LevelledImu, fh_s: np.ndarray, kin: GnssKinematics, lags: np.ndarray, sel: np.ndarray
) -> np.ndarray:
    """Best of the direct and mirrored complex correlations per lag, over centres ``sel`` (lags
    in chunks of :data:`CHUNK_ENTRIES` lag-centre pairs)."""
    z_g, _, moving = velocity_frame(kin)
    use = sel & moving
    t, zg = kin.t[use], z_g[use]
    chunk = max(int(CHUNK_ENTRIES // max(len(t), 1)), 1)
    return (
        np.concatenate(
            [
                _complex_rho_lags(lev, fh_s, t, zg, lags[j : j + chunk], 0.5 * kin.window_s)
                for j in range(0, len(lags), chunk)
            ]
        )
        if len(lags)
        else np.zeros(0)
    )


def _complex_rho_lags(
    lev: LevelledImu, fh_s: np.ndarray, t: np.ndarray, zg: np.ndarray, lags: np.ndarray, edge: float
) -> np.ndarray:
    """:func:`_complex_rho` for some lags, vectorised over lags and centres."""
    tq = t[None, :] - lags[:, None]
    m = (tq >= lev.t0 + edge) & (tq <= lev.t_end - edge)
    x = at_times(lev.t0, lev.step, fh_s, tq.ravel()).reshape(tq.shape + (2,))
    zi = (x[..., 0] + 1j * x[..., 1]) * m
    zgm = zg[None, :] * m
    norm = np.sqrt((np.abs(zi) ** 2).sum(1) * (np.abs(zgm) ** 2).sum(1))
    best = np.maximum(np.abs((zi * np.conj(zgm)).sum(1)), np.abs((zi * zgm).sum(1)))
    return np.where((m.sum(1) >= 4) & (norm > 0), best / np.where(norm > 0, norm, 1.0), np.nan)


def _peak(lags: np.ndarray, rho: np.ndarray) -> float:
    """Lag of the maximum, refined by a parabola through it and its neighbours."""
    j = int(np.nanargmax(rho))
    if 0 < j < len(rho) - 1 and np.all(np.isfinite(rho[j - 1 : j + 2])):
        a, b, c = rho[j - 1], rho[j], rho[j + 1]
        den = a - 2 * b + c
        if den < 0:
            return float(lags[j] + 0.5 * (a - c) / den * (lags[1] - lags[0]))
    return float(lags[j])


def _jackknife(lev: LevelledImu, fh_s: np.ndarray, kin: GnssKinematics, tau: float) -> float:
    """Block-jackknife 1-sigma of the complex-correlation peak near ``tau`` [s]."""
    lags = tau + np.arange(-0.5, 0.5 + 1e-9, FINE_STEP_S)
    blocks = np.array_split(np.arange(len(kin)), JACKKNIFE_BLOCKS)
    peaks = []
    for b in blocks:
        sel = np.ones(len(kin), bool)
        sel[b] = False
        rho = _complex_rho(lev, fh_s, kin, lags, sel)
        if np.all(np.isnan(rho)):
            return float("inf")
        peaks.append(_peak(lags, rho))
    k = len(peaks)
    return float(np.sqrt((k - 1) / k * np.sum((np.array(peaks) - np.mean(peaks)) ** 2)))


def coarse_offset(
    lev: LevelledImu, kin: GnssKinematics, max_offset_s: float = MAX_OFFSET_S
) -> OffsetEstimate:
    """Stage 1 of the module notes: the clock offset from cross-correlations.

    Parameters
    ----------
    lev : LevelledImu
        The IMU on its own clock.
    kin : GnssKinematics
        The fixes' kinematics (:func:`gnssacc.checks.motionmatch.choose_window`).
    max_offset_s : float
        Search range [s].

    Returns
    -------
    OffsetEstimate
        ``determined=False`` (offset 0) when there is too little motion or no clear peak.
    """
    none = OffsetEstimate(0.0, float("inf"), False)
    if kin is None or len(kin) < MIN_CENTRES or not kin.snr >= MIN_SNR:
        return none
    W = kin.window_s
    fh_s = smooth_horizontal(lev, W)
    lags = np.arange(
        -max_offset_s, max_offset_s + 1e-9, max(COARSE_STEP_S, COARSE_STEP_FRACTION * W)
    )
    mag = np.hypot(fh_s[:, 0], fh_s[:, 1])
    rho, count = _magnitude_rho(lev, mag, kin, lags, 0.5 * W)
    np.square(fh_s[:, 0], out=mag)  # the power per grid point, in the magnitude's array
    mag += np.square(fh_s[:, 1])
    imu_rms = float(np.sqrt(np.mean(mag)))
    del mag
    z = _significance(rho, count, kin)
    if np.all(np.isnan(z)):
        return none
    j = int(np.nanargmax(z))  # the most significant lag, then the correlation peak near it
    near = np.abs(lags - lags[j]) <= 0.5 * W
    tau0 = _peak(lags[near], np.where(np.isfinite(z[near]), rho[near], np.nan))
    rho_peak = float(np.nanmax(np.where(near & np.isfinite(z), rho, np.nan)))
    far = (np.abs(lags - tau0) > W) & np.isfinite(z)
    rho_other = float(rho[far][np.nanargmax(z[far])]) if np.any(far) else 0.0
    fine = tau0 + np.arange(-1.0, 1.0 + 1e-9, FINE_STEP_S)
    rho_f = _complex_rho(lev, fh_s, kin, fine, np.ones(len(kin), bool))
    tau = _peak(fine, rho_f) if np.any(np.isfinite(rho_f)) else tau0
    sigma = _jackknife(lev, fh_s, kin, tau)
    ok = (
        rho_peak >= MIN_PEAK
        and rho_peak - rho_other >= MIN_MARGIN
        and sigma <= MAX_SIGMA_FRACTION * W
        and imu_rms >= MIN_IMU_RMS_MPS2
    )
    sigma = float(np.hypot(sigma, STAGE1_MODEL_SIGMA_S))
    return OffsetEstimate(
        tau if ok else 0.0, sigma if ok else float("inf"), bool(ok), rho_peak, rho_other
    )


def shifted(run: RecordedRun, delta_s: float) -> RecordedRun:
    """The run with ``delta_s`` [s] added to every IMU time stamp (and the wheel odometry's, on
    the same clock)."""
    return run.with_imu_shift(delta_s)
