"""False-alarm rate of every input check on clean recordings (target 0).

Each clean case (``tests/clean_cases.py``: simulated cars, city cars, UGVs, slow UGVs with long
parks, a slow rover with 10 Hz receiver-filtered fixes without sigmas, figure-of-eight, straight,
parked; three IMU grades; white, Gauss-Markov, precise and filtered fixes; several seeds), the
KITTI sequence and the real recordings of ``../shared/data`` go through the input checks with the
default configuration (``gnssacc.pipeline.check_input``: the checks, the estimator's verdicts
on what they propose, and the truth against the fixes). A false alarm is anything a user would
read or suffer on clean data: a refusal, a correction applied, a truth set aside, a warning, or
a proposal the estimator could not decide (recorded in ``metrics.json`` and the report, not
warned of since issue 32, but counted here all the same). Proposals the estimator refuted are
counted apart (they cost EKF passes, nobody reads them).

    python bench/bench_false_alarms.py [--seeds 6]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections import Counter
from pathlib import Path

from gnssacc.core.config import load_config
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.pipeline import check_input, load_source

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from clean_cases import cases, issue32_cases  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_recordings import DATA, comma, vn310  # noqa: E402


def verdicts(run, cfg=None) -> tuple[list[str], list[str]]:
    """``(alarms, refuted)``: ``check:what`` of each refusal, correction or warning on a run, and of
    each proposal the estimator refuted."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            _, _, findings = check_input(run, cfg or load_config())
        except InputError as exc:
            return [f"refused:{exc.problem[:90]}"], []
    alarms = [
        f"{f.check}:{f.action}"
        for f in findings
        if f.action in ("repaired", "applied", "not confirmed", "noted", "not scored")
    ]
    alarms += [
        f"warning:{str(w.message)[:90]}"
        for w in caught
        if issubclass(w.category, DataWarning)
        and not any(str(w.message).find(f.problem[:40]) >= 0 for f in findings)
    ]
    return alarms, [f"{f.check}:refuted" for f in findings if f.action == "refuted"]


def real_runs():
    """KITTI and, where present, the shared real recordings."""
    yield "kitti", load_source(None, load_config("kitti"))
    if DATA.is_dir():
        yield "comma2k19", comma(DATA / "comma2k19_example1")
        for log in ("lckf", "tckf"):
            yield f"vn310-{log}", vn310(DATA / "vn310_static", log)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    a = ap.parse_args()
    counts, refuted, n, t0 = Counter(), Counter(), 0, time.perf_counter()
    for name, run in list(real_runs()) + list(cases(a.seeds)) + list(issue32_cases()):
        alarms, ref = verdicts(run, load_config("kitti") if name == "kitti" else None)
        n += 1
        counts.update(a.split(":")[0] for a in alarms)
        refuted.update(r.split(":")[0] for r in ref)
        if alarms:
            print(f"FALSE ALARM {name}: {alarms}", flush=True)
    print(f"\n{n} clean cases in {time.perf_counter() - t0:.0f} s")
    print(f"{'check':16s} {'false alarms':>12s} {'rate':>6s} {'refuted proposals':>18s}")
    for check in sorted(
        set(counts) | set(refuted) | {"time_offset", "mounting", "gyro_units", "latlon"}
    ):
        print(f"{check:16s} {counts[check]:12d} {counts[check] / n:6.1%} {refuted[check]:18d}")
    print(
        f"{'all':16s} {sum(counts.values()):12d} {sum(counts.values()) / n:6.1%} {sum(refuted.values()):18d}"
    )
    print("0 of n false alarms bounds the rate below 3/n at 95 % confidence (rule of three)")


if __name__ == "__main__":
    main()
