"""What a campaign found: the rows of ``summary.csv`` and the paper-style ``summary.md``.

``summary.csv`` has one row per (recording, seed, outage pattern, method), in the campaign's
task order, with the columns of :data:`COLUMNS`:

* ``source`` (the recording's name in the campaign), ``seed``, ``outages`` (``none``,
  ``120:30,300:10``, ``every 60:20``), ``method`` (a method id, ``<id>-online`` for a smoother's
  online estimate, ``gnss`` for the raw fixes);
* the truth figures of :func:`gnssacc.analysis.metrics.truth_figures` (``tilt_rms_deg``, ``yaw_rms_deg``,
  ``bias_a_rms_mg``, ``bias_g_rms_deg_h``, ``nees_pos``, ``nees_att``; empty where the truth
  lacks what they need);
* ``status`` ``ok`` or ``failed``, ``error`` the one-line reason of a failure;
* ``prmse_m``, ``hrmse_m``, ``prmse_outage_m`` [m], ``nis`` (position NIS per dof, or the
  smoother's normalised GNSS residual), ``improvement_pct`` of an ``-acc`` method over its baseline;
* ``runtime_s`` (the method's wall time [s]), ``realtime_factor`` (run length / wall time),
  ``task_s`` (the whole task's wall time [s]); these three are measured, so they differ from run to
  run; every other column is the same wherever the campaign runs;
* ``warnings`` (how many data warnings the task raised) and ``folder`` (the task's folder,
  relative to the campaign).

Numbers are written with every digit (Python's shortest round-trip form); empty means none.
``summary.md`` holds, per outage pattern, the table of :func:`gnssacc.analysis.montecarlo.format_summary`
for each recording and for all recordings together (each (recording, seed) one pair of the
paired test), then the failed tasks.
"""

from __future__ import annotations

import csv
import io
from datetime import datetime

from ..analysis.metrics import TRUTH_FIGURES
from ..analysis.montecarlo import format_summary, summarise
from ..outputs.report import failed_methods, ok_methods

COLUMNS = [
    "source",
    "seed",
    "outages",
    "method",
    "status",
    "error",
    "prmse_m",
    "hrmse_m",
    "prmse_outage_m",
    "nis",
    "improvement_pct",
    *TRUTH_FIGURES,
    "runtime_s",
    "realtime_factor",
    "task_s",
    "warnings",
    "folder",
]
#: The measured columns (wall times): they differ between two runs of the same campaign.
TIMING_COLUMNS = ("runtime_s", "realtime_factor", "task_s")
#: The raw GNSS fixes' row.
GNSS_ROW = "gnss"


def _num(x) -> float | None:
    return None if x is None else float(x)


def task_rows(
    task: dict, metrics: dict | None, error: str | None = None, methods: list[str] = ()
) -> list[dict]:
    """The ``summary.csv`` rows of one task.

    Parameters
    ----------
    task : dict
        ``source``, ``seed``, ``outages``, ``folder``, ``task_s``, ``warnings`` (see :data:`COLUMNS`).
    metrics : dict or None
        The task's ``metrics.json`` content; ``None`` when the task failed as a whole.
    error : str, optional
        The task's one-line error (with ``metrics`` ``None``): one failed row per method of ``methods``.
    """
    base = {c: task.get(c) for c in ("source", "seed", "outages", "task_s", "warnings", "folder")}
    if metrics is None:
        return [{**base, "method": m, "status": "failed", "error": error} for m in methods]
    cons = metrics.get("consistency") or {}
    rows = []
    for mid, m in ok_methods(metrics).items():
        nis = (cons.get(mid) or {}).get("nis", {}).get("pos")
        rows.append(
            {
                **base,
                "method": mid,
                "status": "ok",
                "prmse_m": _num(m["prmse_m"]),
                "hrmse_m": _num(m["hrmse_m"]),
                "prmse_outage_m": _num(m["prmse_outage_m"]),
                "nis": _num(nis),
                "improvement_pct": _num(m["improvement_pct"]),
                "runtime_s": _num(m["runtime_s"]),
                "realtime_factor": _num(m["realtime_factor"]),
                **{k: _num(m.get(k)) for k in TRUTH_FIGURES},
            }
        )
    rows += [
        {**base, "method": mid, "status": "failed", "error": reason}
        for mid, reason in failed_methods(metrics).items()
    ]
    rows.append(
        {
            **base,
            "method": GNSS_ROW,
            "status": "ok",
            "prmse_m": _num(metrics.get("gnss_prmse_m")),
            "hrmse_m": _num(metrics.get("gnss_hrmse_m")),
        }
    )
    return rows


def _cell(value) -> str:
    if value is None:
        return ""
    return repr(value) if isinstance(value, float) else str(value)


def csv_text(records: list[dict]) -> str:
    """``summary.csv`` from the task records (in task order), header first."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for rec in records:
        for row in rec["rows"]:
            w.writerow([_cell(row.get(c)) for c in COLUMNS])
    return buf.getvalue()


def bench_results(records: list[dict]) -> dict:
    """``{unit: {method: (prmse_m, prmse_outage_m)}}`` of the tasks that can be compared, as
    :func:`gnssacc.analysis.montecarlo.summarise` takes them; a unit is a record's ``seed`` when the records
    are of one recording and pattern, else ``(source, seed)``.

    A task is left out when it failed, a method of it failed, or it has no truth (no PRMSE).
    """
    one = len({(r["task"]["source"], r["task"]["outages"]) for r in records}) <= 1
    out = {}
    for rec in records:
        rows = rec["rows"]
        if rec["status"] != "ok" or any(r["status"] != "ok" or r["prmse_m"] is None for r in rows):
            continue
        unit = rec["task"]["seed"] if one else (rec["task"]["source"], rec["task"]["seed"])
        out[unit] = {r["method"]: (r["prmse_m"], r.get("prmse_outage_m")) for r in rows}
    return out


class SummaryMarkdown:
    """``summary.md``, rebuilt as results arrive; each group's table is recomputed only when
    its records changed (the paired test of 20 seeds evaluates 2^20 sign patterns)."""

    def __init__(self):
        self._cache: dict = {}

    def text(self, records: list[dict], total: int, header: str = "") -> str:
        """The whole file from the records so far; ``total`` is the number of tasks in the campaign."""
        ok = sum(r["status"] == "ok" for r in records)
        lines = [
            "# gnssacc batch: summary",
            "",
            header,
            f"{len(records)} of {total} tasks finished: {ok} ok, {len(records) - ok} failed "
            f"(written {datetime.now().isoformat(timespec='seconds')}).",
            "",
        ]
        previous, self._cache = self._cache, {}
        for pattern in dict.fromkeys(r["task"]["outages"] for r in records):
            in_pattern = [r for r in records if r["task"]["outages"] == pattern]
            lines += [f"## outages: {pattern}", ""]
            sources = list(dict.fromkeys(r["task"]["source"] for r in in_pattern))
            groups = [(s, [r for r in in_pattern if r["task"]["source"] == s]) for s in sources]
            if len(sources) > 1:
                groups.append(("all recordings", in_pattern))
            for title, group in groups:
                lines += ["```", self._table(title, pattern, group, previous), "```", ""]
        failed = [r for r in records if r["status"] != "ok"]
        if failed:
            lines += (
                ["## failed tasks", ""]
                + [f"- `{r['task']['folder']}`: {r['error']}" for r in failed]
                + [""]
            )
        return "\n".join(lines)

    def _table(self, title: str, pattern: str, records: list[dict], previous: dict) -> str:
        """One group's table, from ``previous`` (the last call's tables) when its records are the same."""
        key = (title, pattern, tuple((r["task"]["folder"], r["status"]) for r in records))
        if key not in previous:
            results = bench_results(records)
            head = f"{title}: {len(results)} of {len(records)} tasks compared, outages {pattern}"
            previous[key] = (
                format_summary(summarise(results), head) if results else f"{head} (none yet)"
            )
        self._cache[key] = previous[key]
        return previous[key]
