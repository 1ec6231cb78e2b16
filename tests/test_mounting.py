"""A user with an upside-down, rotated IMU and a 0.1 s logging delay fixes it in the config."""

import numpy as np
import pytest

from gnssacc.analysis.metrics import score
from gnssacc.core.config import load_config
from gnssacc.core.recording import ImuData
from gnssacc.core.rotations import euler_to_dcm
from gnssacc.prepare.passes import run_ekf
from gnssacc.sources.csvdir import load_csv_run, write_csv_run
from gnssacc.sources.sim import grade_config, simulate


def test_mounting_and_time_offset_from_config(tmp_path):
    run = simulate("car", duration_s=150.0, imu_grade="industrial", noise="white", seed=4)
    R_bi = euler_to_dcm(*np.radians([180.0, 0.0, 90.0]))  # IMU axes -> body axes
    delay = 0.1
    # What the badly mounted, late-stamped IMU logs: body vectors in IMU axes, stamps 0.1 s late.
    logged = run.__class__(
        **{
            **run.__dict__,
            "imu": ImuData(run.imu.t + delay, run.imu.f_b @ R_bi, run.imu.omega_ib_b @ R_bi),
        }
    )
    write_csv_run(logged, tmp_path / "logged")
    imu_cfg = grade_config("industrial")
    fixed_cfg = load_config(
        overrides={
            "imu": imu_cfg,
            "mounting": {"imu_to_body_rpy_deg": [180.0, 0.0, 90.0], "imu_time_offset_s": -delay},
        }
    )
    fixed = load_csv_run(tmp_path / "logged", fixed_cfg)
    np.testing.assert_allclose(fixed.imu.f_b, run.imu.f_b, atol=1e-9)
    np.testing.assert_allclose(fixed.imu.t, run.imu.t, atol=1e-9)

    plain_cfg = load_config(overrides={"imu": imu_cfg})
    reference = score(run, run_ekf(run, plain_cfg, "ekf")).prmse_m
    assert score(fixed, run_ekf(fixed, fixed_cfg, "ekf")).prmse_m < 1.05 * reference
    # Without the config the IMU-and-GNSS filter still navigates (levelling and the yaw bank find
    # the IMU's own axes), but what it reports is the attitude of those axes: roll about 180 deg.
    # (The non-holonomic constraint needs the vehicle's axes: that is what the mounting gives.)
    raw = load_csv_run(tmp_path / "logged", plain_cfg)
    imu_only = load_config(overrides={"imu": imu_cfg, "nhc": {"enabled": False}})
    sol = run_ekf(raw, imu_only, "ekf")
    from gnssacc.analysis.metrics import gnss_score

    assert score(raw, sol).prmse_m < gnss_score(raw).prmse_m
    assert np.all(np.abs(np.degrees(sol.rpy[:, 0])) > 170.0)


@pytest.mark.parametrize("kernel", ["biweight", "box"])
def test_smoothing_in_blocks_equals_one_convolution(monkeypatch, kernel):
    # A long run's grid is smoothed block by block (bounded memory): the same values as one FFT
    # convolution, for complex and real signals, at the ends and across block edges.
    import gnssacc.checks.motionmatch as mm

    rng = np.random.default_rng(3)
    x = rng.standard_normal(1000) + 1j * rng.standard_normal(1000)
    y = rng.standard_normal((1000, 2))
    whole = mm.smooth(x, 0.01, 0.6, kernel), mm.smooth(y, 0.01, 0.6, kernel)
    monkeypatch.setattr(mm, "SMOOTH_BLOCK", 37)
    blocks = mm.smooth(x, 0.01, 0.6, kernel), mm.smooth(y, 0.01, 0.6, kernel)
    for a, b in zip(whole, blocks):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)


def test_fft_lengths_are_scipys():
    # The transform lengths the convolution picks with numpy's FFT against scipy.fft's own
    # choice (5-smooth for a real transform, 11-smooth for a complex one).
    from scipy.fft import next_fast_len

    import gnssacc.checks.motionmatch as mm

    sizes = [*range(1, 3000), *np.random.default_rng(2).integers(3000, 2_000_000, 300).tolist()]
    for n in sizes:
        assert mm._good_size(n, (3, 5)) == next_fast_len(n, real=True), n
        assert mm._good_size(n, (3, 5, 7, 11)) == next_fast_len(n), n


@pytest.mark.parametrize("block", [37, 1 << 16])
def test_fft_convolution_equals_the_direct_sum(monkeypatch, block):
    # The FFT convolution behind the smoothing against numpy's direct sum, real and complex,
    # whole and in blocks.
    import gnssacc.checks.motionmatch as mm

    monkeypatch.setattr(mm, "SMOOTH_BLOCK", block)
    rng = np.random.default_rng(5)
    k = rng.random(61)
    for x in (rng.standard_normal(997), rng.standard_normal(997) + 1j * rng.standard_normal(997)):
        np.testing.assert_allclose(
            mm._convolve_same(x, k), np.convolve(x, k, "same"), rtol=0, atol=1e-12
        )
