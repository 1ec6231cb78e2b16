"""One preparation pass: in a default run the IMU quality check, the stationary detection and the
yaw bank each run once (the bank once per noise model: with the configured noise for the tuner's
start, and again with the tuned noise, whose hypotheses' filters differ), and every estimator
reads the prepared recording instead of repeating them."""

from __future__ import annotations

import pytest

import gnssacc
import gnssacc.prepare.start as start


@pytest.fixture
def counted(monkeypatch):
    calls = {"check_imu": 0, "detect_stationary": 0, "select_yaw": 0}
    for name in calls:
        real = getattr(start, name)

        def wrapped(*args, _name=name, _real=real, **kwargs):
            calls[_name] += 1
            return _real(*args, **kwargs)

        monkeypatch.setattr(start, name, wrapped)
    return calls


@pytest.mark.parametrize("tune, banks", [("none", 1), ("auto", 2)])
def test_default_run_prepares_once(counted, tune, banks):
    """KITTI, every default method: its clock offset is proposed (the accelerations and the turns put
    it 0.4 s off), judged by the EKF from the run's own start, and refuted, without a second start."""
    res = gnssacc.process("kitti", tune=tune)
    assert set(res.solutions) >= {"ekf", "ekf-acc", "smoother", "smoother-acc"}
    assert counted == {"check_imu": 1, "detect_stationary": 1, "select_yaw": banks}
    offset = [f for f in res.prepared.checks if f.check == "time_offset"]
    assert [f.action for f in offset] == ["refuted", "bound"]
    assert offset[0].details["verdict"]["refuted"]
    # The clock's bound comes from that verdict's sigma: no pass of its own.
    assert offset[1].details["sigma_s"] == offset[0].details["sigma_s"]


def test_an_estimator_reads_the_prepared_recording(counted):
    from gnssacc.core.config import load_config
    from gnssacc.estimators import ekf
    from gnssacc.estimators.settings import EkfSettings
    from gnssacc.pipeline import prepare

    run = gnssacc.simulate("car", 90.0, seed=3)
    cfg = load_config()
    prep = prepare(run, cfg, "none")
    before = dict(counted)
    ekf.estimate(prep, EkfSettings.from_config(prep.cfg), "ekf-acc")
    assert counted == before


def test_the_estimator_is_asked_only_when_the_data_propose_something(monkeypatch):
    """A clean drive whose views agree with the stamps and axes as given costs no verdict pass:
    the clock-offset search and the judge's passes run only for a proposal; how large an offset
    could go unseen costs a few passes of the likelihood at the stamps as given (at most 9)."""
    import gnssacc.prepare.judge as judge
    import gnssacc.prepare.settle as settle

    monkeypatch.setenv("GNSSACC_JOBS", "1")  # every pass made here, where it is counted
    calls = {"evaluate": 0, "innovations": 0}
    real_eval, real_inn = settle._evaluate, judge.innovations

    def evaluate(*a, **k):
        calls["evaluate"] += 1
        return real_eval(*a, **k)

    def innovations(*a, **k):
        calls["innovations"] += 1
        return real_inn(*a, **k)

    import gnssacc.prepare.clock as clock

    monkeypatch.setattr(settle, "_evaluate", evaluate)
    monkeypatch.setattr(judge, "innovations", innovations)
    monkeypatch.setattr(clock, "innovations", innovations)
    res = gnssacc.process("sim:car,duration=120", methods=["ekf"], tune="none", seed=4)
    assert [f.action for f in res.prepared.checks] == ["bound"]
    assert calls["evaluate"] == 0 and 3 <= calls["innovations"] <= 9, calls
