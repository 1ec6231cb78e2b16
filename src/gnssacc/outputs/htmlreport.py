"""``gnssacc run --report``: an HTML page beside ``metrics.json``.

The answer comes first (the comparison table, the warnings and ``summary.png``: which method, how
good, how sure), then the figures, one question each (:mod:`gnssacc.outputs.figures`), then the
details: the evo-style statistics, consistency, noise identification, start, IMU data quality and
observability. Each section is made on its own: one that fails is one line in its place, never the
end of the run. Figures are separate PNG files and every path is relative (the source's too), so the
folder can be moved or zipped as a whole."""

from __future__ import annotations

import html
import os
from pathlib import Path

from ..core.recording import RecordedRun
from ..core.solution import NavSolution
from .report import failed_methods, group_warnings, table_notes, table_rows, verdict_line


def observability_html(
    run: RecordedRun, sols: dict[str, NavSolution], cfg, replay=None, stationary=None
) -> str:
    """Motion context and, per state, the share of predicted variance each aiding removes (EKF),
    from ``replay`` (the ``ekf-acc`` pass's own matrices), or from one more ``ekf-acc`` pass when
    the run did not have one. ``stationary``: the spans the estimators stood still in
    (:class:`gnssacc.prepare.stationary.StationaryReport`; detected again, without the run's
    configuration, when omitted)."""
    from ..analysis.motion import classify_motion
    from ..analysis.observability import STATE_NAMES, aiding_information, replay_ekf

    ref = next((sols[m] for m in ("smoother", "smoother-acc", "ekf", "ekf-acc") if m in sols), None)
    if ref is None:
        return ""
    fractions = classify_motion(run, ref, stationary=stationary).fractions()
    motion = "".join(
        f"<tr><td>{html.escape(k)}</td><td>{100 * v:.1f}</td></tr>" for k, v in fractions.items()
    )
    summary = aiding_information(replay or replay_ekf(run, cfg, "ekf-acc")).summary()
    rows = "".join(
        f"<tr><td>{n}</td><td>{100 * summary[n]['pos']:.2f}</td><td>{100 * summary[n]['pos_acc']:.2f}</td>"
        f"</tr>"
        for n in STATE_NAMES
    )
    return (
        f"<p>Motion context (from the IMU and the {html.escape(ref.method)} velocity):</p>"
        f"<table><tr><th>motion</th><th>share of epochs [%]</th></tr>{motion}</table>"
        "<p>Mean share of each state's predicted variance removed at a GNSS epoch, by the position update alone "
        "and by position + GNSS-derived acceleration (the EKF's own matrices, epochs with an acceleration):</p>"
        f"<table><tr><th>state</th><th>position [%]</th><th>position + acceleration [%]</th></tr>{rows}</table>"
    )


def comparison_html(metrics: dict) -> str:
    """The verdict, then the comparison table as an HTML table (numbers right-aligned, '!' cells
    flagged), with the scored window above it, a row per failed method with its reason, and the
    NIS legend."""
    head, rows = table_rows(metrics)
    above, below = table_notes(metrics)
    verdict = verdict_line(metrics) if metrics.get("consistency") else None
    first = f'<p class="verdict">{html.escape(verdict)}</p>' if verdict else ""
    cell = lambda c, i: (
        f'<td class="num{" warn" if c.endswith("!") else ""}">{html.escape(c)}</td>'
        if i
        else f"<td>{html.escape(c)}</td>"
    )
    body = "".join("<tr>" + "".join(cell(c, i) for i, c in enumerate(r)) + "</tr>" for r in rows)
    body += "".join(
        f'<tr><td>{html.escape(m)}</td><td class="warn" colspan="{len(head) - 1}">failed: '
        f"{html.escape(r)}</td></tr>"
        for m, r in failed_methods(metrics).items()
    )
    return (
        first
        + "".join(f"<p>{html.escape(t)}</p>" for t in above)
        + "<table><tr>"
        + "".join(f"<th>{html.escape(h)}</th>" for h in head)
        + f"</tr>{body}</table>"
        + "".join(f'<p class="note">{html.escape(t)}</p>' for t in below)
    )


def _fmt(x, spec: str = ".2f") -> str:
    return "-" if x is None else format(x, spec)


def consistency_html(metrics: dict) -> str:
    """Per method: NIS per update kind, innovation whiteness, fix residual ratio, and the warnings."""
    cons = metrics.get("consistency") or {}
    if not cons:
        return "<p>No consistency figures.</p>"
    head = ["method", "NIS position", "velocity", "acceleration", "zero velocity", "zero rate"]
    head += ["innovation autocorrelation", "fix residual ratio", "warnings"]
    rows = [
        [html.escape(m)]
        + [_fmt(c["nis"].get(k)) for k in ("pos", "vel", "acc", "zupt", "zaru")]
        + [_fmt(c.get("innovation_acf1")), _fmt(c.get("fix_residual_ratio"))]
        + ["<br>".join(html.escape(w) for w in c["warnings"]) or "none"]
        for m, c in cons.items()
    ]
    return (
        "<p>1 is consistent for every NIS figure (EKF: innovations; smoother: GNSS residuals against their "
        "expectation); innovation autocorrelation near 0; fix residual ratio below 1.41 (an estimate as good as "
        "the fixes and independent of them).</p>" + html_table(head, rows)
    )


def html_table(head: list[str], rows: list[list[str]], numeric: bool = False) -> str:
    """An HTML table of ready-escaped cells without the columns (after the first) whose every
    cell is ``-`` (nothing drawn for data that do not exist)."""
    keep = [0] + [i for i in range(1, len(head)) if any(r[i] != "-" for r in rows)]
    td = '<td class="num">' if numeric else "<td>"
    return (
        "<table><tr>"
        + "".join(f"<th>{html.escape(head[i])}</th>" for i in keep)
        + "</tr>"
        + "".join(
            "<tr>" + "".join(f"{'<td>' if i == 0 else td}{r[i]}</td>" for i in keep) + "</tr>"
            for r in rows
        )
        + "</table>"
    )


def tuning_html(metrics: dict) -> str:
    """The identified noise values beside their starting values, with the NIS before and after."""
    t = metrics.get("tuning")
    if not t:
        return "<p>The configuration was used as given (<code>--tune none</code>).</p>"
    back = set(t.get("from_stationary", {}).get("drawn_back", []))
    rows = "".join(
        f"<tr><td>{html.escape(sec)}.{html.escape(k)}</td><td>{html.escape(str(t['start'].get(f'{sec}.{k}', '-')))}"
        f"</td><td>{html.escape(str(v))}{' (drawn back toward the start)' if f'{sec}.{k}' in back else ''}"
        f"</td></tr>"
        for sec, vals in t["values"].items()
        for k, v in vals.items()
    )
    return (
        f"<p>{t['n_evaluations']} EKF passes in {t['seconds']:.1f} s; position NIS per dof {_fmt(t['nis_before'])} "
        f"at the start, {_fmt(t['nis_after'])} tuned. Kept from the configuration: "
        f"{html.escape(', '.join(t['fixed']) or 'nothing')}. Written to <code>tuned.toml</code>.</p>"
        f"<table><tr><th>key</th><th>start</th><th>identified</th></tr>{rows}</table>"
    )


#: The figures in the report, with the question each one answers.
CAPTIONS = {
    "accel_effect": "What the GNSS-derived acceleration changes: with minus without, per epoch "
    "and as a distribution, with the 95 % interval of its mean",
    "trajectory": "Where: the track coloured by horizontal error (without truth: by the stated 1-sigma), x east, "
    "y north (a straight track: along and across its line), start, end and outages marked",
    "errors": "How the position error evolves, per axis, against each method's +-3 sigma",
    "velocity_attitude": "Velocity and attitude errors against +-3 sigma",
    "nis": "Is each method consistent over time? NIS and distance to the fixes",
    "biases": "What the filters learnt about the IMU: bias estimates with +-3 sigma",
    "sigmas": "How uncertain each state is over time (predicted 1-sigma)",
}


def shown_path(where: str, folder: Path) -> str:
    """A source path as the report shows it: inside an installed package, from the package on
    (``gtsam/Data/...``, never an absolute venv path); otherwise relative to the report's folder."""
    text = str(where)
    head, sep, tail = text.partition(" (")
    parts = Path(head).parts
    if "site-packages" in parts:
        rest = Path(*parts[parts.index("site-packages") + 1 :])
        return f"{rest} (in the installed package){' (' + tail if sep else ''}"
    if os.path.isabs(head):
        try:
            return os.path.relpath(head, folder) + (f" ({tail}" if sep else "")
        except ValueError:  # another drive
            return Path(head).name + (f" ({tail}" if sep else "")
    return text


def _section(title: str, make, anchor: str) -> str:
    """``<h2 id=anchor>title</h2>`` and ``make()``'s HTML; a failure is one line in its place."""
    from ..core.interrupts import raise_if_interrupted

    try:
        body = make()
    except Exception as exc:
        raise_if_interrupted(exc)
        body = (
            f'<p class="failed">This section could not be made ({html.escape(type(exc).__name__)}: '
            f"{html.escape(' '.join(str(exc).split())[:200])}); the rest of the report is complete.</p>"
        )
    return f'<h2 id="{anchor}">{html.escape(title)}</h2>\n{body}\n' if body else ""


def warnings_html(metrics: dict) -> str:
    """The warnings about the methods, grouped as ``gnssacc run`` prints them."""
    cons = metrics.get("consistency") or {}
    items = group_warnings([(m, w) for m, c in cons.items() for w in c.get("warnings", [])])
    failed = [(m, f"failed: {r}") for m, r in failed_methods(metrics).items()]
    if not items and not failed:
        return "<p>No warnings: every figure is within its band.</p>"
    return (
        '<ul class="warnings">'
        + "".join(
            f"<li><b>{html.escape(who)}</b>: {html.escape(text)}</li>"
            for who, text in items + failed
        )
        + "</ul>"
    )


def _img(name: str, caption: str) -> str:
    return (
        f'<figure><img src="{name}.png" alt="{html.escape(caption)}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


def answer_html(metrics: dict, figures: dict) -> str:
    """The verdict and comparison, the warnings, ``summary.png`` and ``accel_effect.png``."""
    out = comparison_html(metrics) + "<h3>Warnings</h3>" + warnings_html(metrics)
    truth = metrics.get("gnss_prmse_m") is not None
    if figures.get("summary", "not drawn") is None:
        out += _img(
            "summary",
            "Which method, how good, how sure: horizontal error CDF and consistency per method"
            if truth
            else "No truth: each method's distance to the raw fixes (agreement, not accuracy) and "
            "its consistency (NIS)",
        )
    if "accel_effect" in figures:
        out += _figure("accel_effect", figures)
    return out


def _figure(name: str, figures: dict) -> str:
    """A drawn figure with its caption, or one line saying why it was not drawn."""
    if figures[name] is None:
        return _img(name, CAPTIONS[name])
    return f'<p class="note">{html.escape(name)}.png not drawn: {html.escape(figures[name])}.</p>'


def figures_html(figures: dict) -> str:
    """Every other figure with its question, and a line for each one not drawn."""
    parts = [_figure(n, figures) for n in CAPTIONS if n in figures and n != "accel_effect"]
    return "".join(parts) or "<p>No figures (<code>--plots none</code>).</p>"


def _stat(x, spec=".2f") -> str:
    return "-" if x is None else format(x, spec)


def statistics_html(metrics: dict) -> str:
    """Per method, evo's statistics of the position error and the per-axis, velocity, attitude and
    NEES figures (:mod:`gnssacc.analysis.errorstats`); without truth the distance to the fixes."""
    from .report import ok_methods

    ok = ok_methods(metrics)
    truth = any((m.get("errors") or {}).get("position") for m in ok.values())
    if not truth:
        return _fix_residual_html(ok)
    head = [
        "method",
        "RMSE",
        "mean",
        "median",
        "std",
        "max",
        "CEP50",
        "CEP95",
        "N RMSE",
        "E RMSE",
        "D RMSE",
        "vel RMSE [m/s]",
        "roll [deg]",
        "pitch [deg]",
        "yaw [deg]",
        "NEES pos",
        "NEES att",
    ]
    rows = [
        [html.escape(mid)] + [_stat(c) for c in _error_cells(m.get("errors") or {})]
        for mid, m in list(ok.items())
        + [("gnss (raw fixes)", {"errors": metrics.get("gnss_errors") or {}})]
    ]
    return (
        "<p>Position error norm [m] over the scored epochs with evo's statistics (<code>evo_ape "
        "--pose_relation trans_part</code>, no alignment), horizontal CEP50/CEP95 [m], per-axis RMSE [m], velocity "
        "and attitude RMSE (where the truth has them), NEES per dof (1 = consistent). The raw "
        "fixes are scored at their own epochs.</p>" + html_table(head, rows, numeric=True)
    )


def _fix_residual_html(ok: dict) -> str:
    """Without truth: each method's distance to the raw fixes [m] (agreement, not accuracy)."""
    rows = "".join(
        f"<tr><td>{html.escape(mid)}</td>"
        + "".join(
            f'<td class="num">{_stat(((m.get("errors") or {}).get("fix_residual") or {}).get(k))}</td>'
            for k in ("rmse", "mean", "median", "std", "max")
        )
        + "</tr>"
        for mid, m in ok.items()
    )
    return (
        "<p>No truth: accuracy cannot be scored. Distance from each method to the raw fixes [m] "
        "(agreement with them, not accuracy):</p><table><tr><th>method</th><th>RMS</th><th>mean</th>"
        f"<th>median</th><th>std</th><th>max</th></tr>{rows}</table>"
    )


def _error_cells(e: dict) -> list:
    """The statistics row of one solution's error statistics ``e``: position norm (RMSE, mean,
    median, std, max), CEP50/95, N/E/D RMSE [m], velocity RMSE [m/s], roll/pitch/yaw RMSE [deg],
    position and attitude NEES (``None`` where absent)."""
    p, h, ax = e.get("position") or {}, e.get("horizontal") or {}, e.get("position_axes") or {}
    att = e.get("attitude_axes") or {}
    return (
        [p.get(k) for k in ("rmse", "mean", "median", "std", "max")]
        + [h.get("cep50"), h.get("cep95")]
        + [(ax.get(a) or {}).get("rmse") for a in "NED"]
        + [(e.get("velocity") or {}).get("rmse")]
        + [(att.get(a) or {}).get("rmse") for a in ("roll", "pitch", "yaw")]
        + [
            (e.get("nees_position") or {}).get("value"),
            (e.get("nees_attitude") or {}).get("value"),
        ]
    )


def input_checks_html(metrics: dict) -> str:
    """The input checks' proposals and the estimator's verdicts: the corrections applied, those
    tested and left (the data used as given), a truth set aside, and how well the clock is told."""
    c = metrics.get("input_corrections")
    if not c:
        return ""

    def rows(entries: list) -> str:
        return "".join(
            f"<tr><td>{html.escape(e['check'])}</td><td>{html.escape(e['proposal'])}</td>"
            f"<td>{html.escape(e['correction'])}</td><td>{html.escape(e['verdict'])}</td>"
            f"<td>{html.escape(e['evidence'])}</td></tr>"
            for e in entries
        )

    head = (
        "<tr><th>check</th><th>what the data show</th><th>correction</th><th>verdict</th>"
        "<th>the estimator's evidence</th></tr>"
    )
    entries = c["applied"] + c["not_applied"]
    out = (
        f"<p>Policy: a correction the estimator proves is "
        f"{'applied' if c['on_proof'] == 'apply' else 'refused'} "
        f'(<code>[checks] on_proof = "{html.escape(c["on_proof"])}"</code>); refuted and '
        f"undecided proposals leave the data as given.</p>"
    )
    out += f"<table>{head}{rows(entries)}</table>" if entries else "<p>Nothing was proposed.</p>"
    if c.get("truth_not_scored"):
        out += f"<p>Truth not scored: {html.escape(c['truth_not_scored'])}</p>"
    if c.get("clock"):
        out += f"<p>Clock: {html.escape(c['clock']['text'])}</p>"
    return out


def _quality_html(metrics: dict, run: RecordedRun) -> str:
    spans = metrics.get("quality", {}).get("spans", [])
    rows = "".join(
        f"<tr><td>{html.escape(s['kind'])}</td><td>{s['t_start'] - run.t_start:.2f}</td>"
        f"<td>{s['t_end'] - s['t_start']:.2f}</td><td>{html.escape(str(s['channels']))}</td>"
        f"<td>{html.escape(str(s['note']))}</td></tr>"
        for s in spans
    )
    return (
        f"<table><tr><th>kind</th><th>start [s]</th><th>length [s]</th><th>channels</th><th>note</th></tr>"
        f"{rows}</table>"
        if spans
        else "<p>No suspect IMU spans.</p>"
    )


def _init_html(metrics: dict) -> str:
    first = next(iter(metrics["methods"].values()), {})
    inits = metrics.get("init") or (first.get("stats") or {}).get("init", "")
    return f"<p>All methods start from the same state: {html.escape(str(inits))}</p>"


_STYLE = """body{font-family:sans-serif;max-width:1200px;margin:1.5em auto;padding:0 1em} img{max-width:100%}
table{border-collapse:collapse;margin:0.5em 0} td,th{border:1px solid #ccc;padding:2px 6px;font-size:90%}
th{background:#f0f0f0} td:first-child{white-space:nowrap} td.num{text-align:right;font-variant-numeric:tabular-nums}
td.warn{background:#fff3cd} p.note,figcaption{font-size:85%;color:#555} p.failed{color:#a00}
ul.warnings li{margin-bottom:0.3em;font-size:92%}
p.verdict{font-size:110%;font-weight:bold} figure{margin:1em 0} nav a{margin-right:1em}"""


def write_html_report(
    folder: Path,
    run: RecordedRun,
    sols: dict[str, NavSolution],
    metrics: dict,
    cfg=None,
    replay=None,
    figures: dict | None = None,
    stationary=None,
) -> Path:
    """Write ``report.html`` into ``folder``; returns the page's path.

    ``figures``: what :func:`gnssacc.outputs.figures.write_figures` drew (``{name: None or reason}``).
    With ``cfg`` the page also gets the observability section (:func:`observability_html`, with
    the run's ``stationary`` spans).
    """
    folder = Path(folder)
    figures = figures or {}
    where = shown_path(run.where, folder)
    sections = [
        ("Answer: which method, how good, how sure", lambda: answer_html(metrics, figures)),
        ("Figures", lambda: figures_html(figures)),
        ("Statistics", lambda: statistics_html(metrics)),
        ("Consistency", lambda: consistency_html(metrics)),
        ("Noise identification", lambda: tuning_html(metrics)),
        ("Input checks: what was proposed and proven", lambda: input_checks_html(metrics)),
        ("Initialisation", lambda: _init_html(metrics)),
        ("IMU data quality", lambda: _quality_html(metrics, run)),
    ]
    if cfg is not None:
        sections.append(
            ("Observability", lambda: observability_html(run, sols, cfg, replay, stationary))
        )
    body = "".join(_section(t, f, f"s{i}") for i, (t, f) in enumerate(sections))
    nav = "".join(
        f'<a href="#s{i}">{html.escape(t.split(":")[0])}</a>' for i, (t, _) in enumerate(sections)
    )
    caveat = run.truth.caveat if run.truth is not None else ""
    caveat_html = f"<p><b>Truth:</b> {html.escape(caveat)}</p>" if caveat else ""
    page = f"""<!doctype html>
<html><head><meta charset="utf-8"><title>gnssacc report: {html.escape(run.name)}</title>
<style>{_STYLE}</style></head><body>
<h1>gnssacc report: {html.escape(run.name)}</h1>
<p>Source: {html.escape(where)}; {run.duration_s:.1f} s, {len(run.imu)} IMU samples, {len(run.gnss)} GNSS fixes;
configuration: {html.escape(", ".join(metrics.get("config_sources", [])))}.</p>
{caveat_html}<nav>{nav}</nav>
{body}</body></html>
"""
    path = folder / "report.html"
    path.write_text(page)
    return path
