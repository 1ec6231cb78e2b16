"""The input checks' IMU signals computed block by block (bounded memory on long runs) give the
numbers of the straightforward whole-array computations, bit for bit where the arithmetic is the
same, and the exact averages where those are known in closed form."""

import numpy as np
import pytest

import gnssacc.checks.motionmatch as mm
from gnssacc.core.recording import ImuData


def whole_box_average(t, x, t0, step, n):
    """Box averages as one computation over the whole record: running integral, interpolated at
    the cell edges, differenced."""
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    edges = np.concatenate([[t[0] - dt[0]], t])
    g = np.clip(t0 + step * (np.arange(n + 1) - 0.5), edges[0], edges[-1])
    width = np.maximum(np.diff(g), 1e-12)
    cum = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x * dt[:, None], axis=0)])
    return np.column_stack(
        [np.diff(np.interp(g, edges, cum[:, i])) / width for i in range(x.shape[1])]
    )


def jittered_record(n, seed=0):
    rng = np.random.default_rng(seed)
    t = 100.0 + np.cumsum(0.01 + 0.002 * rng.random(n))
    return t, rng.standard_normal((n, 3)) + np.array([0.3, -0.2, -9.8])


@pytest.mark.parametrize("block", [37, 1 << 16])
@pytest.mark.parametrize("grid", ["samples", "seconds"])
def test_box_average_in_blocks_equals_the_whole_record(monkeypatch, block, grid):
    # Block edges fall inside cells and samples; the seconds grid reaches past both ends (clipped).
    monkeypatch.setattr(mm, "BOX_BLOCK", block)
    t, x = jittered_record(1000)
    t0, step, n = (t[0], 0.01, 1100) if grid == "samples" else (t[0] - 0.7, 1.0, 14)
    np.testing.assert_array_equal(
        mm.box_average(t, x, t0, step, n), whole_box_average(t, x, t0, step, n)
    )


def test_box_average_of_whole_samples_is_their_mean(monkeypatch):
    # Unit intervals, cells of two samples aligned with them: each cell is the plain mean of its pair.
    monkeypatch.setattr(mm, "BOX_BLOCK", 7)
    t = np.arange(101.0)
    x = np.random.default_rng(1).standard_normal((101, 2))
    out = mm.box_average(t, x, 1.0, 2.0, 50)  # cell j = [2j, 2j + 2]: samples 2j+1, 2j+2
    np.testing.assert_allclose(out, 0.5 * (x[1::2] + x[2::2]), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("block", [37, 1 << 16])
def test_level_imu_projects_one_channel_at_a_time(monkeypatch, block):
    monkeypatch.setattr(mm, "BOX_BLOCK", block)
    t, f = jittered_record(700, seed=2)
    w = np.random.default_rng(3).standard_normal((700, 3))
    lev = mm.level_imu(ImuData(t, f, w), step=0.01)
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    f_mean = dt @ f / dt.sum()  # the time-weighted mean specific force
    down = -f_mean / np.linalg.norm(f_mean)
    np.testing.assert_array_equal(lev.down, down)
    proj = np.column_stack([f @ lev.e1, f @ lev.e2, w @ down])
    ref = whole_box_average(t, proj, t[0], 0.01, len(lev.omega_v))
    np.testing.assert_array_equal(lev.f_h, ref[:, :2])
    np.testing.assert_array_equal(lev.omega_v, ref[:, 2])


def levelled(n=1500, seed=4):
    rng = np.random.default_rng(seed)
    f_h = np.cumsum(rng.standard_normal((n, 2)), axis=0) * 0.01
    omega = 0.3 * np.sin(np.arange(n) * 0.01) + 0.01 * rng.standard_normal(n)
    return mm.LevelledImu(
        5.0,
        0.01,
        np.array([0, 0, 1.0]),
        np.array([1.0, 0, 0]),
        np.array([0, 1.0, 0]),
        f_h,
        omega,
        9.8,
    )


def direct_smooth(x, k):
    """Kernel average by numpy's direct convolution sum."""
    den = np.convolve(np.ones(len(x)), k, "same")
    return np.convolve(x, k, "same") / den


@pytest.mark.parametrize("block", [37, 1 << 16])
def test_smooth_horizontal_in_blocks_equals_the_direct_sum(monkeypatch, block):
    # Ground frame: turned by the integrated heading, averaged, turned back.
    monkeypatch.setattr(mm, "SMOOTH_BLOCK", block)
    lev = levelled()
    k = (1 - (np.arange(-150, 151) / 151.0) ** 2) ** 2  # 3 s biweight on the 0.01 s grid
    turn = np.exp(1j * lev.step * np.cumsum(lev.omega_v))
    f = direct_smooth((lev.f_h[:, 0] + 1j * lev.f_h[:, 1]) * turn, k) / turn
    scale = np.abs(f).max()
    np.testing.assert_allclose(
        mm.smooth_horizontal(lev, 3.0),
        np.column_stack([f.real, f.imag]),
        rtol=0,
        atol=1e-12 * scale,
    )
    imu_axes = mm.LevelledImu(**{**lev.__dict__, "ground_frame": False})
    ref = np.column_stack([direct_smooth(lev.f_h[:, i], k) for i in range(2)])
    np.testing.assert_allclose(
        mm.smooth_horizontal(imu_axes, 3.0), ref, rtol=0, atol=1e-12 * np.abs(ref).max()
    )


@pytest.mark.parametrize("block", [37, 1 << 16])
def test_smooth_horizontal_keeps_the_whole_array_arithmetic(monkeypatch, block):
    # Bit for bit what turning, smoothing (the same FFT blocks) and turning back the whole grid gives.
    monkeypatch.setattr(mm, "SMOOTH_BLOCK", block)
    lev = levelled(seed=5)
    turn = np.exp(np.cumsum(lev.omega_v) * (1j * lev.step))
    z = (lev.f_h[:, 1] * 1j + lev.f_h[:, 0]) * turn
    f = mm.smooth(z, lev.step, 3.0) / turn
    np.testing.assert_array_equal(mm.smooth_horizontal(lev, 3.0), np.column_stack([f.real, f.imag]))
    k = (1 - (np.arange(-150, 151) / 151.0) ** 2) ** 2
    den = np.maximum(mm._convolve_same(np.ones(len(z)), k), 1e-12)
    np.testing.assert_array_equal(
        mm.smooth(lev.f_h, lev.step, 3.0),
        np.column_stack([mm._convolve_same(lev.f_h[:, i], k) / den for i in range(2)]),
    )


@pytest.mark.parametrize("block", [3, 1 << 14])
def test_gap_cells_in_blocks_equal_the_whole_record(monkeypatch, block):
    # Interval k (sample k-1 to k) marks the cell of sample k; gaps on block edges and in cell 0.
    import gnssacc.prepare.stationary as st

    monkeypatch.setattr(st, "GAP_BLOCK_CELLS", block)
    t = np.arange(1003) * 0.01
    for k in (1, 50, 149, 150, 151, 300, 599, 600, 1002):
        t[k:] += 0.05
    c, J = 5, 1003 // 5
    gap = np.concatenate([[False], np.diff(t) > 0.03])[: J * c]
    np.testing.assert_array_equal(st._gap_cells(t, c, J, 0.03), gap.reshape(J, c).any(axis=1))


@pytest.mark.parametrize("block", [5, 4096])
def test_running_median_in_blocks_equals_each_window_median(monkeypatch, block):
    import gnssacc.prepare.stationary as st

    monkeypatch.setattr(st, "MEDIAN_BLOCK_ROWS", block)
    x = np.random.default_rng(6).standard_normal((103, 6))
    ref = np.array([[np.median(x[i : i + 11, c]) for c in range(6)] for i in range(103 - 10)])
    np.testing.assert_array_equal(st._running_median(x, 11), ref)


def test_still_positions_in_blocks_equal_the_whole_record(monkeypatch):
    # The verdicts of a simulated run's cells, compared 7 positions at a time and all at once.
    import gnssacc.prepare.stationary as st
    from gnssacc.sources.sim import simulate

    imu = simulate("car", duration_s=300.0, imu_grade="industrial", seed=2).imu
    p = st.StationaryParams()
    M, c, gap_cells, dt = st._cells(imu, p)
    B = max(int(round(p.block_s / (c * dt))), 2)
    mu, se2 = st._block_stats(M, B, 11, p)
    gap_cells[100:103] = True
    whole = st._still_positions(mu, se2, gap_cells, B, p)
    monkeypatch.setattr(st, "STILL_BLOCK", 7)
    np.testing.assert_array_equal(st._still_positions(mu, se2, gap_cells, B, p), whole)
    assert 0 < whole.sum() < len(whole)  # both verdicts occur
