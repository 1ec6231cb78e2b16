"""A simulated run's true biases, drawn again on demand instead of kept per IMU sample.

* They are the biases the simulator's sweep added to the IMU, recorded as it adds them (every
  source on: turn-on, Gauss-Markov with blocks shorter than the sweep's, drift), for any sweep
  block size and any block size of the redraw.
* ``at`` is ``np.interp`` over every sample, bit for bit, at any epochs (on samples, between
  them, at block edges, outside the run, unsorted, on a shifted clock).
* The run holds no per-sample bias array: what it keeps does not grow with the run beyond the
  drift's one-second walk.
* A run's bias errors as scored (:func:`gnssacc.analysis.observability.state_errors`) are the estimate
  minus the interpolated per-sample truth.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gnssacc.analysis.observability import state_errors
from gnssacc.core.solution import NavSolution
from gnssacc.sources import sim, sim_path
from gnssacc.sources.sim_true_bias import TrueBias
from gnssacc.estimators.layout import BA, BG

FULL = dict(
    imu_grade="consumer",
    seed=5,
    noise="none",
    imu_overrides={"bias_correlation_time_s": 0.2, "vib_engine_wander_time_s": 0.5},
)


def _interp(t, t_samples, b):
    return np.column_stack([np.interp(t, t_samples, b[:, i]) for i in range(3)])


@pytest.mark.parametrize("sweep_block", [250, 10**9])
def test_redrawn_biases_are_those_the_sweep_added(monkeypatch, sweep_block):
    added = []
    with_drift = TrueBias.with_drift

    def record(self, b_a, b_g, rows):
        out = with_drift(self, b_a, b_g, rows)
        added.append((rows.start, rows.stop) + out)
        return out

    monkeypatch.setattr(sim_path, "IMU_BLOCK", sweep_block)
    monkeypatch.setattr(TrueBias, "with_drift", record)
    run = sim.simulate("car", 30.0, **FULL)
    monkeypatch.setattr(TrueBias, "with_drift", with_drift)
    assert [a[0] for a in added] == [0] + [a[1] for a in added[:-1]] and added[-1][1] == len(
        run.imu
    )
    assert len(added) == (
        1 if sweep_block > len(run.imu) else pytest.approx(len(run.imu) / sweep_block, abs=1)
    )
    b_a, b_g = np.concatenate([a[2] for a in added]), np.concatenate([a[3] for a in added])
    assert b_a.shape == (len(run.imu), 3) and np.any(run.sim.imu_error_draws["gyro_warmup"] != 0)
    for size in (1, 7, 8192):
        monkeypatch.setattr(sim_path, "IMU_BLOCK", size)
        np.testing.assert_array_equal(run.sim.true_bias_a, b_a)
        np.testing.assert_array_equal(run.sim.true_bias_g, b_g)
    # ... and not a constant: turn-on + Gauss-Markov (tau 0.2 s) + drift.
    assert np.all(b_g.std(axis=0) > 0) and np.all(
        np.abs(b_a[0] - run.sim.imu_error_draws["accel_turn_on_bias"]) > 0
    )


def test_at_is_interp_over_every_sample_bit_for_bit(monkeypatch):
    monkeypatch.setattr(sim_path, "IMU_BLOCK", 64)
    run = sim.simulate("car", 20.0, **FULL)
    t_imu, bias = run.imu.t, run.sim.bias
    full_a, full_g = bias.samples()
    rng = np.random.default_rng(1)
    t = np.concatenate(
        [
            rng.uniform(t_imu[0] - 1.0, t_imu[-1] + 1.0, 300),  # unsorted, outside too
            t_imu[[0, 1, 63, 64, 65, 127, 128, -2, -1]],  # samples, block edges
            t_imu[[63, 127]] + 0.5 * (t_imu[[64, 128]] - t_imu[[63, 127]]),
            [t_imu[-1] + 5.0, t_imu[0] - 5.0],
        ]
    )
    for q in (t, t[:1], np.array([t_imu[-1] + 1.0]), np.array([t_imu[0] - 1.0]), np.zeros(0)):
        for clock in (t_imu, t_imu + 0.0123):
            a, g = bias.at(q, clock)
            np.testing.assert_array_equal(a, _interp(q, clock, full_a).reshape(len(q), 3))
            np.testing.assert_array_equal(g, _interp(q, clock, full_g).reshape(len(q), 3))


def test_the_run_keeps_no_per_sample_bias():
    short, long = (sim.simulate("car", d, imu_grade="industrial", seed=2) for d in (60.0, 600.0))
    for run in (short, long):
        assert run.sim.bias.t is run.imu.t  # the run's own sample times, not a copy
    kept = [
        sum(
            np.asarray(v).nbytes
            for v in (*vars(r.sim.bias.seed).values(), *vars(r.sim.bias.drift).values())
            if isinstance(v, np.ndarray)
        )
        for r in (short, long)
    ]
    # Only the drift's 1-s random walk (6 floats and its time per second) grows with the run.
    assert kept[1] - kept[0] == 7 * 8 * 540
    assert kept[1] < 0.05 * long.imu.f_b.nbytes  # per-sample biases would be 2x f_b
    assert [r.sim.bias.nbytes for r in (short, long)] == kept


def test_scored_bias_errors_are_estimate_minus_interpolated_truth():
    run = sim.simulate("car", 30.0, **FULL)
    t = np.linspace(run.t_start + 0.005, run.t_end - 0.3, 41)
    n = len(t)
    b_a, b_g = np.full((n, 3), 1e-3), np.full((n, 3), -2e-5)
    sol = NavSolution(
        "x",
        t,
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        b_a,
        b_g,
        np.ones((n, 15)),
        0.0,
        {},
    )
    err = state_errors(run, sol)
    np.testing.assert_array_equal(err[:, BA], b_a - _interp(t, run.imu.t, run.sim.true_bias_a))
    np.testing.assert_array_equal(err[:, BG], b_g - _interp(t, run.imu.t, run.sim.true_bias_g))
    # Another IMU record (e.g. samples dropped) is not the one the biases belong to: not scored.
    cut = run.imu.select(slice(1, None))
    assert np.all(np.isnan(state_errors(replace(run, imu=cut), sol)[:, 9:15]))
