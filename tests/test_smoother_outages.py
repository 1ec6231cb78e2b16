"""The smoother through GNSS outages: a stationary span the fixes could not vet (inside an outage,
its GNSS check made from the first fixes after it) may be a cruise, and its zero-velocity factors
are gated as the EKF's updates are."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from gnssacc.core.config import load_config
from gnssacc.estimators import smoother
from gnssacc.estimators.aids import zupt
from gnssacc.estimators.settings import SmootherSettings
from gnssacc.pipeline import prepare
from gnssacc.sources.gnss_noise import apply_outages
from gnssacc.sources.sim import grade_config, simulate

OUTAGE = (100.0, 20.0)  # the ugv scenario cruises at 2 m/s over 109.6-119.6 s
FAKE = (110.0, 119.0)  # a "stationary" span over that cruise, as the detector once found it


@pytest.fixture(scope="module")
def prepared():
    run = simulate("ugv", 180.0, imu_grade="industrial", seed=0)
    run = apply_outages(run, [OUTAGE])
    cfg = load_config(overrides={"imu": grade_config("industrial"), "nhc": {"enabled": False}})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prep = prepare(run, cfg, "none", ["smoother"])
    tr = run.truth
    i = (tr.t >= FAKE[0]) & (tr.t <= FAKE[1])
    assert np.all(np.linalg.norm(tr.v_n[i], axis=1) > 1.5)  # it is a cruise
    imu_t = run.imu.t
    span = replace(
        prep.stationary.spans[0],
        t_start=FAKE[0],
        t_end=FAKE[1],
        i_start=int(np.searchsorted(imu_t, FAKE[0])),
        i_end=int(np.searchsorted(imu_t, FAKE[1])),
        gnss_checked=True,
        gnss_speed_mps=4.7,
        gnss_speed_sigma_mps=4.3,
        gnss_n_fixes=0,
    )
    spans = [s for s in prep.stationary.spans if s.t_end < FAKE[0] or s.t_start > FAKE[1]] + [span]
    report = replace(prep.stationary, spans=sorted(spans, key=lambda s: s.t_start))
    return replace(prep, stationary=report)


def test_a_span_checked_only_from_outside_is_not_vetted(prepared):
    params = prepared.stationary.params
    fake = [s for s in prepared.stationary.spans if s.t_start == FAKE[0]][0]
    assert not zupt.vetted_by_fixes(fake, params)
    assert zupt.vetted_by_fixes(replace(fake, gnss_n_fixes=5), params)
    assert not zupt.vetted_by_fixes(replace(fake, gnss_n_fixes=5, gnss_checked=False), params)


def test_unvetted_span_in_an_outage_does_not_stop_the_smoother(prepared):
    sols = smoother.estimate(prepared, SmootherSettings.from_config(prepared.cfg), "smoother")
    run = prepared.run
    for sid in ("smoother", "smoother-online"):
        sol = sols[sid]
        m = (sol.t >= FAKE[0]) & (sol.t <= FAKE[1])
        v_true = np.column_stack(
            [np.interp(sol.t[m], run.truth.t, run.truth.v_n[:, k]) for k in range(3)]
        )
        err = np.linalg.norm(sol.v_n[m] - v_true, axis=1)
        # Zero-velocity factors over the cruise pull the speed towards zero: an error of about the
        # true speed (2 m/s). Gated, the smoother keeps the speed it predicts.
        assert np.max(err) < 0.5 * np.min(np.linalg.norm(v_true, axis=1)), (sid, err)
    assert sols["smoother"].stats["n_zupt_gated"] > 0
