"""Every real recording in ``../shared/data`` through the whole default pipeline, as a new user runs
it: no refusal, and with truth each estimate beats the raw fixes or a warning says it does not.
(``bench/bench_real_recordings.py`` prints the table; add each new recording to both.)"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import gnssacc

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from bench_real_recordings import DATA, comma, vn310  # noqa: E402

pytestmark = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"no real recordings at {DATA} (a fresh clone has none)"
)

RECORDINGS = {
    "comma2k19": lambda: comma(DATA / "comma2k19_example1"),
    "vn310-lckf": lambda: vn310(DATA / "vn310_static", "lckf"),
    "vn310-tckf": lambda: vn310(DATA / "vn310_static", "tckf"),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RECORDINGS))
def test_real_recording_runs_with_defaults(name):
    res = gnssacc.process(RECORDINGS[name]())  # default methods, checks and self-tuning
    assert set(res.solutions) >= {"ekf", "ekf-acc", "smoother", "smoother-acc"}
    assert not [f for f in res.prepared.checks if f.action in ("repaired", "applied")]
    raw = res.metrics["gnss_prmse_m"]
    if raw is None:  # no truth: nothing to beat, the figures say so
        assert "no truth" in res.table()
        return
    for mid, m in res.metrics["methods"].items():
        warned = " ".join(res.metrics["consistency"][mid]["warnings"])
        assert m["prmse_m"] < raw or "raw fixes" in warned, (mid, m["prmse_m"], raw)
