"""Thresholds of the stationary detector (:func:`gnssacc.prepare.stationary.detect_stationary`) and
their reading from a configuration's ``[stationary]`` section; the section's defaults and key
documentation come from here (:mod:`gnssacc.core.config`, :mod:`gnssacc.core.config_docs`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

from .errors import InputError


@dataclass(frozen=True)
class StationaryParams:
    """Thresholds of :func:`detect_stationary`, with their physical reasons.

    Attributes
    ----------
    cell_s : float
        Cell length [s]: two to three periods of engine vibration (>= 20 Hz at idle), so a cell
        mean already damps it.
    block_s : float
        Block length [s] for the still test: ten or more vibration periods, short enough to place
        a stop's edges to a fraction of a second.
    omega_max_dps : float
        Largest norm of a block's mean angular rate at rest [deg/s]: a consumer MEMS turn-on bias
        (up to ~0.5 deg/s per axis) plus earth rate (0.004 deg/s) with margin; a vehicle turning or
        pivoting on the spot turns at several deg/s.
    z : float
        Change threshold in combined standard errors: a false break has a probability of ~1e-5
        per channel and comparison for Gaussian noise, and stays rare with a noisy error estimate.
    floor_accel_mps2, floor_gyro_dps : float
        Absolute floor added to the tolerance [m/s^2], [deg/s], so a noise-free IMU (simulated,
        or a quiet high-grade one) is not failed by rounding: 0.01 m/s^2 is 1 mg, 0.01 deg/s is
        36 deg/h, both below any change a moving vehicle makes over half a second.
    noise_window_s : float
        Window over which the block differences are pooled into a standard error [s] (the
        vibration and noise level changes slowly: engine speed, temperature).
    noise_spread : float
        How much the standard error may exceed the run's quietest level (factor on sigma): the
        stationary error is the sensor noise plus a little vibration leak, the same at every stop
        within this factor; driving texture is larger.
    min_duration_s : float
        Shortest stationary span kept [s]: enough blocks to trust the test and to make a
        stationary update worth it.
    edge_trim_s : float
        Extra cut at both ends of a stretch [s] (the one-block trim of step 2 comes first).
    gap_factor : float
        An IMU interval longer than this many median intervals is a gap (nothing is known there).
    gnss_k_sigma : float
        A stretch is rejected when its fitted horizontal speed exceeds this many sigma (per
        axis) ... 3.44 is the two-dimensional "3 sigma": at rest the speed exceeds it with the
        probability 0.27 % (Rayleigh), as a 1-D value exceeds 3 sigma.
    gnss_speed_floor_mps : float
        ... and exceeds this absolute bound [m/s]. The floor keeps precise fixes from rejecting
        a parked vehicle for the slow wander of their own errors (multipath, atmosphere: a few
        cm/s over tens of seconds); 0.1 m/s still rejects any creep worth knowing about.
    gnss_corr_s : float
        Fix errors closer in time than this are taken as correlated [s]: a receiver's position
        filter and its multipath errors are not independent from one 5-10 Hz fix to the next, so
        ``sigma_v`` is inflated by ``sqrt(gnss_corr_s / fix interval)`` when fixes come faster.
    gnss_min_fixes : int
        Fewest fixes (inside and around a stretch) for a GNSS check; with fewer it is unchecked.
    gnss_margin_s : float
        How far around a stretch fixes are used [s]: beyond a few seconds the IMU's excursion
        bound grows (quadratically) past what the fixes can resolve.
    gnss_excursion_k : float
        Sigma factor for a single outside fix against its excursion bound (4.3: a chi-square
        with 2 degrees of freedom exceeds 4.3^2 with probability 1e-4, so tens of fixes per
        stretch rarely give a false rejection).
    excursion_floor_mps2 : float
        Acceleration allowed on top of the IMU-measured one in the excursion bound and the
        velocity chain [m/s^2]: accelerometer scale-factor and misalignment errors of a few
        percent of the vehicle's accelerations, and the cell-mean vibration residual.
    chain_max_gap_s : float
        Largest gap between two spans for the velocity chain [s]: over longer gaps the
        unmodelled tilt and scale-factor errors of a consumer IMU exceed the floor below.
    chain_floor_mps : float
        Velocity change between two spans that is taken as real [m/s]: well above what noise
        (0.01 m/s over 10 s at 0.2 m/s/sqrt(h)) and vibration produce; a stop, a pull-away or
        a creep changes the velocity by more.
    link_reach_s : float
        How far before and after a span fixes are carried to it by the IMU [s] (step 4b). The
        carried path's error bound grows as ``excursion_floor_mps2 tau^2 / 2`` (22 m at 30 s), so
        farther fixes could not tell a stop from a crawl; nearer ones are the evidence inside a
        GNSS outage.
    chain_cross_axis : float
        Gyro cross-axis coupling budgeted in the velocity chain [-]: a turn by psi fakes a tilt
        change of ``chain_cross_axis psi`` (1 %: uncalibrated consumer MEMS).
    chain_margin : float
        Difference in -2 log-likelihood by which one of two conflicting groups of spans must fit
        "at rest" better than the other to be kept (2: a likelihood ratio of e = 2.7); otherwise
        both go.
    """

    cell_s: float = 0.1
    block_s: float = 0.5
    omega_max_dps: float = 1.0
    z: float = 4.5
    floor_accel_mps2: float = 0.01
    floor_gyro_dps: float = 0.01
    noise_window_s: float = 5.0
    noise_spread: float = 2.0
    min_duration_s: float = 2.0
    edge_trim_s: float = 0.0
    gap_factor: float = 3.0
    gnss_k_sigma: float = 3.44
    gnss_speed_floor_mps: float = 0.1
    gnss_corr_s: float = 1.0
    gnss_min_fixes: int = 2
    gnss_margin_s: float = 3.0
    gnss_excursion_k: float = 4.3
    excursion_floor_mps2: float = 0.05
    chain_max_gap_s: float = 10.0
    chain_floor_mps: float = 0.3
    link_reach_s: float = 30.0
    chain_cross_axis: float = 0.01
    chain_margin: float = 2.0


def params_from_config(cfg) -> StationaryParams:
    """Detector thresholds from a configuration's optional ``[stationary]`` section.

    Parameters
    ----------
    cfg : gnssacc.core.config.RunConfig or dict
        Keys of the section are the field names of :class:`StationaryParams` (same units); a
        missing section or key keeps the documented default.

    Raises
    ------
    InputError
        For a key that is not a field of :class:`StationaryParams`.
    """
    values = cfg if isinstance(cfg, dict) else cfg.values
    section = dict(values.get("stationary", {}))
    known = StationaryParams.__dataclass_fields__
    unknown = sorted(set(section) - set(known))
    if unknown:
        raise InputError(
            "config",
            f"unknown [stationary] key(s) {', '.join(unknown)} (known: {', '.join(known)})",
        )
    return replace(
        StationaryParams(),
        **{k: type(getattr(StationaryParams(), k))(v) for k, v in section.items()},
    )
