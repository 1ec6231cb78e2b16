"""Tests of the IMU data-quality check (synthetic defects and the real KITTI file from gtsam)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from gnssacc.checks.quality import (
    KINDS,
    SuspectNoise,
    check_imu,
    inflation_psd,
    inflation_segments,
)
from gnssacc.core.config import DEG, load_config
from gnssacc.core.recording import ImuData

RATE_HZ = 100.0


def _clean(n=6000, seed=1, jitter_s=0.0):
    """Static-ish white-noise IMU at 100 Hz: FRD, gravity on -z."""
    rng = np.random.default_rng(seed)
    t = 1000.0 + np.arange(n) / RATE_HZ + rng.uniform(-jitter_s, jitter_s, n)
    f_b = np.array([0.1, -0.2, -9.81]) + 0.05 * rng.standard_normal((n, 3))
    w_b = np.array([1e-3, -2e-3, 5e-4]) + 0.01 * rng.standard_normal((n, 3))
    return ImuData(t, f_b, w_b)


def _with_defects():
    """Clean noise plus one defect of each kind at known samples (see the expected values)."""
    imu = _clean(jitter_s=2e-4)
    t, f_b, w_b = imu.t, imu.f_b.copy(), imu.omega_ib_b.copy()
    # Linear interpolation (per sample) between real anchors 999 and 1051: samples 1000..1050.
    a, b = 999, 1051
    for x in (f_b, w_b):
        x[a : b + 1] = np.linspace(x[a], x[b], b - a + 1)
    # Frozen: samples 2001..2010 repeat sample 2000.
    f_b[2001:2011] = f_b[2000]
    w_b[2001:2011] = w_b[2000]
    # Clipped bursts: gz at +5 rad/s for samples 3000..3019, ax at -40 m/s^2 for 4000..4007.
    w_b[3000:3020, 2] = 5.0
    f_b[4000:4008, 0] = -40.0
    # Gap: drop samples 5001..5049, so the sample after 5000 closes a 0.5 s interval.
    keep = np.ones(len(t), bool)
    keep[5001:5050] = False
    return ImuData(t[keep], f_b[keep], w_b[keep]), t


@pytest.fixture(scope="module")
def cfg():
    return load_config()


def test_clean_noise_has_no_spans(cfg):
    rep = check_imu(_clean(jitter_s=2e-4), cfg)
    assert rep.spans == []
    assert not rep.suspect_mask(rep.n_samples).any()


def test_quiet_quantised_channel_is_not_saturated(cfg):
    imu = _clean()
    lsb = 1e-3
    # A static gyro barely above its quantisation step: values mostly 0 or +-1 LSB.
    imu.omega_ib_b[:, 0] = np.round(0.4 * np.random.default_rng(5).standard_normal(len(imu))) * lsb
    assert check_imu(imu, cfg).of_kind("saturated") == []


def test_each_kind_found_at_the_right_place(cfg):
    imu, t_orig = _with_defects()
    rep = check_imu(imu, cfg)
    got = {k: [(s.i_start, s.i_end, s.channels) for s in rep.of_kind(k)] for k in KINDS}
    assert got["interpolated"] == [(1000, 1051, "all")]
    assert got["frozen"] == [(2001, 2011, "all")]
    assert sorted(got["saturated"]) == [(3000, 3020, "gz"), (4000, 4008, "ax")]
    assert got["gap"] == [(5001, 5002, "all")]
    gap = rep.of_kind("gap")[0]
    assert gap.t_start == t_orig[5000] and gap.t_end == t_orig[5050]
    interp = rep.of_kind("interpolated")[0]
    assert interp.t_start == t_orig[999] and interp.t_end == t_orig[1050]
    # Nothing else, and the mask is exactly the union of the spans.
    assert len(rep.spans) == 5
    mask = rep.suspect_mask(len(imu))
    assert mask.sum() == 51 + 10 + 20 + 8 + 1
    assert mask[1000] and mask[1050] and not mask[999] and not mask[1051]


@pytest.mark.parametrize("block", [7, 50, 1000])
def test_interpolation_check_in_blocks_finds_the_same_spans(cfg, monkeypatch, block):
    # Blocks of rows (bounded memory on long runs) with the defect straddling block edges:
    # the same spans, anchors and notes (the largest second difference) as in one piece.
    import gnssacc.checks.quality as quality

    imu, _ = _with_defects()
    whole = check_imu(imu, cfg).spans
    monkeypatch.setattr(quality, "CHECK_BLOCK_ROWS", block)
    assert check_imu(imu, cfg).spans == whole
    assert any(s.kind == "interpolated" for s in whole)


def test_time_linear_interpolation_with_jittered_stamps(cfg):
    imu = _clean(jitter_s=3e-3)  # stamps jitter by up to 30 % of the interval
    t = imu.t
    a, b = 2000, 2100
    for x in (imu.f_b, imu.omega_ib_b):
        frac = ((t[a : b + 1] - t[a]) / (t[b] - t[a]))[:, None]
        x[a : b + 1] = x[a] + frac * (x[b] - x[a])
    spans = check_imu(imu, cfg).of_kind("interpolated")
    assert [(s.i_start, s.i_end) for s in spans] == [(a + 1, b)]


def test_short_straight_stretch_is_not_flagged(cfg):
    imu = _clean()
    a, b = 500, 510  # 0.1 s < interp_min_s = 0.2 s
    for x in (imu.f_b, imu.omega_ib_b):
        x[a : b + 1] = np.linspace(x[a], x[b], b - a + 1)
    assert check_imu(imu, cfg).spans == []


def test_report_summary_and_json(cfg):
    imu, _ = _with_defects()
    rep = check_imu(imu, cfg)
    lines = rep.summary().splitlines()
    assert [ln.split()[0] for ln in lines] == list(KINDS)
    assert "2 span(s)" in lines[KINDS.index("saturated")]
    d = json.loads(json.dumps(rep.to_dict()))
    assert d["totals"]["frozen"]["count"] == 1 and len(d["spans"]) == 5
    assert d["dt_median_s"] == pytest.approx(0.01, rel=0.05)


@pytest.mark.parametrize("mode", ["fixed", "local"])
def test_inflation_psd_integrates_to_sigma_T_squared(cfg, mode):
    from gnssacc.core.config import load_config

    cfg = load_config(overrides={"quality": {"suspect_sigma_mode": mode}})
    imu, _ = _with_defects()
    rep = check_imu(imu, cfg)
    q_gyro, q_accel = inflation_psd(imu, rep, SuspectNoise.from_config(cfg))
    assert q_gyro.shape == q_accel.shape == (len(imu), 3)
    dt = np.diff(imu.t, prepend=imu.t[0])  # sample k holds over (t[k-1], t[k]]
    cap_g = cfg["quality"]["suspect_gyro_sigma_dps"] * DEG
    cap_a = cfg["quality"]["suspect_accel_sigma_mps2"]
    clean = ~rep.suspect_mask(len(imu))
    w = cfg["quality"]["suspect_local_window_s"]
    for s in rep.spans:
        sl = slice(s.i_start, s.i_end)
        T = s.t_end - s.t_start
        if mode == "fixed":
            sg, sa = np.full(3, cap_g), np.full(3, cap_a)
        else:
            # Independent recomputation: std of the clean neighbours within w seconds, capped.
            near = (np.abs(imu.t - s.t_start) <= w) | (np.abs(imu.t - s.t_end) <= w)
            near |= (imu.t >= s.t_start - w) & (imu.t <= s.t_end + w)
            idx = np.flatnonzero(near & clean)
            idx = idx[(idx < s.i_start) | (idx >= s.i_end)]
            sg = np.minimum(imu.omega_ib_b[idx].std(axis=0), cap_g)
            sa = np.minimum(imu.f_b[idx].std(axis=0), cap_a)
            assert np.all(sg < cap_g)  # quiet channels get far less than the cap
        if s.channels != "ax":
            np.testing.assert_allclose(
                np.sum(q_gyro[sl] * dt[sl, None], axis=0), (sg * T) ** 2, rtol=1e-9
            )
        if s.channels != "gz":
            np.testing.assert_allclose(
                np.sum(q_accel[sl] * dt[sl, None], axis=0), (sa * T) ** 2, rtol=1e-9
            )
    # A clipped gyro does not de-weight the accelerometers, and vice versa.
    gz = rep.of_kind("saturated")[0]
    assert q_accel[gz.i_start : gz.i_end].max() == 0.0 and q_gyro[4000:4008].max() == 0.0
    assert np.all(q_gyro[clean] == 0) and np.all(q_accel[clean] == 0)


def test_inflation_segments_are_made_again_when_what_they_come_from_changes(cfg):
    """The segments are kept for the same IMU data, report and settings (the tuner's passes ask
    for them each), and made afresh, as a fresh report's, when the report's spans, the data or
    the settings differ."""
    imu, _ = _with_defects()
    rep = check_imu(imu, cfg)
    local = SuspectNoise.from_config(cfg)
    first = inflation_segments(imu, rep, local)
    assert len(first.i0) >= 4 and inflation_segments(imu, rep, local) is first
    fixed = SuspectNoise.from_config(
        load_config(overrides={"quality": {"suspect_sigma_mode": "fixed"}})
    )
    assert not np.array_equal(inflation_segments(imu, rep, fixed).q_gyro, first.q_gyro)
    dropped = rep.spans.pop(0)  # the same report object, one span fewer
    fewer = inflation_segments(imu, rep, local)
    assert len(fewer.i0) < len(first.i0) and dropped.i_start not in fewer.i0
    other = ImuData(imu.t, imu.f_b, imu.omega_ib_b * 2.0)  # other data, the same spans
    doubled = inflation_segments(other, rep, local)
    np.testing.assert_allclose(doubled.q_gyro, 4.0 * fewer.q_gyro, rtol=1e-12)


# --- the real KITTI file shipped with gtsam --------------------------------------------------------

KITTI_INTERP_STARTS = (
    46570.894,
    46733.226,
    46737.575,
    46754.163,
    46770.751,
    46813.457,
    46840.094,
    46842.273,
)


@pytest.fixture(scope="module")
def kitti_imu():
    gtsam = pytest.importorskip("gtsam")
    path = os.path.join(os.path.dirname(gtsam.__file__), "Data", "KittiEquivBiasedImu.txt")
    if not os.path.exists(path):
        pytest.skip("gtsam wheel without Data/KittiEquivBiasedImu.txt")
    a = np.loadtxt(path, skiprows=1)  # Time dt accelX accelY accelZ omegaX omegaY omegaZ
    return ImuData(a[:, 0], a[:, 2:5], a[:, 5:8])


def test_kitti_defects(kitti_imu, cfg):
    rep = check_imu(kitti_imu, cfg)
    interp = rep.of_kind("interpolated")
    assert len(interp) == 8
    assert all(1.5 <= s.duration_s <= 1.7 for s in interp)
    assert np.allclose([s.t_start for s in interp], KITTI_INTERP_STARTS, atol=0.01)
    gaps = rep.of_kind("gap")
    assert len(gaps) == 1
    assert gaps[0].i_start == 1 and gaps[0].duration_s == pytest.approx(1.92, abs=0.01)
    assert rep.of_kind("frozen") == [] and rep.of_kind("saturated") == []
