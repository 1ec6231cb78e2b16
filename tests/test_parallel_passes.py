"""Independent work side by side (:mod:`gnssacc.core.parallel`): the same results as one call
after the other, in forked processes when the run may use several, in this one alone with
``GNSSACC_JOBS=1``; the tuner's search with its points evaluated ahead ends where it ends
without; the methods run side by side give the solutions they give one after the other."""

from __future__ import annotations

import os

import numpy as np
import pytest

import gnssacc
import gnssacc.pipeline as pipeline
from gnssacc.core import parallel
from gnssacc.prepare.tuning import ml_search


def _pid_and_square(x):
    return os.getpid(), x * x


def _fails_on_three(x):
    if x == 3:
        raise ValueError(f"three: {x}")
    return x


def test_results_in_call_order_from_forked_workers(monkeypatch):
    monkeypatch.setenv(parallel.JOBS_ENV, "2")
    got = parallel.side_by_side(_pid_and_square, [(k,) for k in range(6)])
    assert [v for _, v in got] == [k * k for k in range(6)]
    pids = {p for p, _ in got}
    assert os.getpid() in pids and len(pids) == 2  # this process and one worker


def test_one_job_runs_everything_here(monkeypatch):
    monkeypatch.setenv(parallel.JOBS_ENV, "1")
    got = parallel.side_by_side(_pid_and_square, [(k,) for k in range(4)])
    assert {p for p, _ in got} == {os.getpid()}
    assert parallel.usable_jobs() == 1


def test_the_first_failing_call_raises_as_in_a_loop(monkeypatch):
    monkeypatch.setenv(parallel.JOBS_ENV, "2")
    with pytest.raises(ValueError, match="three: 3"):
        parallel.side_by_side(_fails_on_three, [(k,) for k in (1, 3, 5, 3)])


def test_a_kept_pool_serves_the_same_function_again(monkeypatch):
    monkeypatch.setenv(parallel.JOBS_ENV, "2")
    try:
        a = parallel.side_by_side(_pid_and_square, [(1,), (2,)], keep=True)
        b = parallel.side_by_side(_pid_and_square, [(3,), (4,)], keep=True)
        assert a[1][0] == b[1][0] != os.getpid()  # the same worker
    finally:
        parallel.close_pool()
    c = parallel.side_by_side(_pid_and_square, [(3,), (4,)])
    assert c[1][0] != a[1][0]  # a new one after the pool was ended


class _Squares(parallel.KeptWorkers):
    def __init__(self):
        self.kept_for = self.square

    def square(self, x):
        return os.getpid(), x * x


def test_workers_kept_for_a_method_end_with_its_with_block(monkeypatch):
    monkeypatch.setenv(parallel.JOBS_ENV, "2")
    other = parallel.side_by_side(_pid_and_square, [(1,), (2,)], keep=True)  # another's pool
    with _Squares() as squares:
        a = parallel.side_by_side(squares.square, [(1,), (2,)], keep=True)
        b = parallel.side_by_side(squares.square, [(3,), (4,)], keep=True)
        assert a[1][0] == b[1][0] != other[1][0]  # kept for the method, the other's ended
        worker = a[1][0]
    assert [v for _, v in b] == [9, 16]
    with pytest.raises(ProcessLookupError):  # ended with the block (and reaped)
        os.kill(worker, 0)
    parallel.close_pool()


class _Bowl:
    """A bumpy negative log-likelihood with ``ahead`` (evaluated side by side, as the tuner's
    objective does); counts what was evaluated where."""

    def __init__(self):
        self.done: dict = {}
        self.here = 0

    def value(self, theta):
        return float(np.sum((theta - 0.37) ** 2 * 40.0) + 3.0 * np.sum(np.sin(7.0 * theta)))

    def __call__(self, theta):
        key = np.asarray(theta, float).tobytes()
        if key not in self.done:
            self.here += 1
            self.done[key] = self.value(np.asarray(theta, float))
        return self.done[key]

    def ahead(self, thetas):
        new = [
            np.asarray(t, float) for t in thetas if np.asarray(t, float).tobytes() not in self.done
        ]
        for t, v in zip(new, parallel.side_by_side(self.value, [(t,) for t in new]), strict=True):
            self.done[t.tobytes()] = v


@pytest.mark.parametrize("jobs", ["2", "4"])
@pytest.mark.parametrize("budget", [9, 20, 60])
def test_search_with_points_evaluated_ahead_ends_where_it_ends_without(monkeypatch, jobs, budget):
    monkeypatch.setenv(parallel.JOBS_ENV, jobs)
    plain = _Bowl()
    expected = ml_search(lambda th: plain.value(np.asarray(th, float)), 5, budget, 1.0)
    bowl = _Bowl()
    got = ml_search(bowl, 5, budget, 1.0)
    np.testing.assert_array_equal(got[0], expected[0])
    assert got[1:] == expected[1:]
    assert bowl.here < got[2]  # some of the passes were made ahead, by the workers


@pytest.fixture(scope="module")
def prepared():
    run = gnssacc.simulate("car", 60.0, seed=3)
    cfg = pipeline.configure()
    return pipeline.prepare(run, cfg, "none")


def test_methods_side_by_side_give_the_same_solutions(monkeypatch, prepared):
    methods = ["ekf", "smoother", "ekf-acc"]
    monkeypatch.setenv(parallel.JOBS_ENV, "1")
    alone = pipeline.run_methods(prepared.run, prepared.cfg, methods, prep=prepared)
    monkeypatch.setenv(parallel.JOBS_ENV, "2")
    assert pipeline.method_groups(methods, None, 2) == [["smoother"], ["ekf", "ekf-acc"]]
    said: list = []
    both = pipeline.run_methods(prepared.run, prepared.cfg, methods, prep=prepared, say=said.append)
    assert list(both) == list(alone)  # the same solutions, in the same order
    for sid, sol in alone.items():
        for name in ("lat", "lon", "h", "v_n", "rpy"):
            np.testing.assert_array_equal(getattr(both[sid], name), getattr(sol, name))
    assert [line.split(":")[0] for line in said] == methods


def test_a_method_failing_in_a_worker_is_reported_as_alone(monkeypatch, prepared):
    monkeypatch.setenv(parallel.JOBS_ENV, "2")

    def broken(prep, method, show_progress, **kw):
        raise RuntimeError("no convergence")

    monkeypatch.setitem(pipeline.METHODS, "ekf-acc", broken)
    failures: dict = {}
    got = pipeline.run_methods(
        prepared.run, prepared.cfg, ["smoother", "ekf-acc"], prep=prepared, failures=failures
    )
    assert "smoother" in got and "ekf-acc" not in got
    assert "no convergence" in failures["ekf-acc"]


def test_the_yaw_bank_side_by_side_chooses_as_alone(monkeypatch):
    from gnssacc.estimators.ekf import run_ekf
    from gnssacc.prepare.stationary import detect_stationary
    from gnssacc.prepare.yawbank import select_yaw

    run = gnssacc.simulate("car", 90.0, seed=5)
    cfg = pipeline.configure()
    report = detect_stationary(run.imu, run.gnss, run.origin)
    banks = {}
    for jobs in ("1", "2"):
        monkeypatch.setenv(parallel.JOBS_ENV, jobs)
        banks[jobs] = select_yaw(run, cfg, report, filter_pass=run_ekf)
    alone, side = banks["1"], banks["2"]
    assert parallel._POOL["executor"] is None  # the bank's workers ended with it
    np.testing.assert_array_equal(side.posterior, alone.posterior)
    np.testing.assert_array_equal(side.init.rpy, alone.init.rpy)
    np.testing.assert_array_equal(side.init.sigma_att_rad, alone.init.sigma_att_rad)
    assert side.t_decided == alone.t_decided and side.init.how == alone.init.how
    err = (alone.init.rpy[2] - run.truth.rpy[0, 2] + np.pi) % (2 * np.pi) - np.pi
    assert abs(err) < 3.0 * alone.init.sigma_att_rad[2]  # and it is the right yaw


def test_no_fork_while_a_thread_holds_them(monkeypatch):
    # a child forked while the kernels' thread compiles inherits its locks held and waits for
    # ever on the first one it needs: the calls are made here until the thread is done
    monkeypatch.setenv(parallel.JOBS_ENV, "2")
    parallel.hold_forks()
    try:
        got = parallel.side_by_side(_pid_and_square, [(x,) for x in range(4)])
    finally:
        parallel.release_forks()
    assert [r[1] for r in got] == [0, 1, 4, 9]
    assert {r[0] for r in got} == {os.getpid()}
    assert not parallel.forks_held()
    again = parallel.side_by_side(_pid_and_square, [(x,) for x in range(4)])
    assert len({r[0] for r in again}) == 2  # released: the workers take their share again


def test_the_kernels_thread_holds_forks_until_it_is_done(monkeypatch):
    import threading

    from gnssacc.estimators import kernels

    go = threading.Event()
    monkeypatch.setattr(kernels, "compile_groups", lambda groups: go.wait(10.0))
    warm = kernels.BackgroundWarmUp(groups=(), processes=False)
    assert not parallel.forks_held()
    warm.start()
    assert parallel.forks_held()  # the thread is loading: no fork now
    go.set()
    warm.wait_all()
    assert not parallel.forks_held()
