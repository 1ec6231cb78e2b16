"""``gnssacc run --report``: an HTML page beside ``metrics.json`` with the comparison table, the
figures, per-state 1-sigma histories and the data-quality findings. Figures are separate PNG
files referenced by relative paths, so the folder can be moved or zipped as a whole."""
from __future__ import annotations

import html
from pathlib import Path

from ..core.display import DISPLAY_SCALE, STATE_GROUPS
from ..core.recording import RecordedRun
from ..core.solution import NavSolution
from .report import failed_methods, figure, table_notes, table_rows


def plot_sigmas(run: RecordedRun, sols: dict[str, NavSolution], path: Path) -> None:
    """1-sigma of every error state vs time, one panel per state, one line per method."""
    import matplotlib.pyplot as plt

    fig, axes = figure((14, 14), 5, 3, sharex=True)
    for row, (name, cols, unit, labels) in enumerate(STATE_GROUPS):
        for c, label in enumerate(labels):
            ax = axes[row, c]
            k = cols.start + c
            for mid, sol in sols.items():
                ax.semilogy(sol.t - run.t_start, sol.sigma[:, k] * DISPLAY_SCALE[k], lw=1, label=mid)
            ax.set_title(f"{name} {label} [{unit}]", fontsize=9)
            ax.grid(alpha=0.3, which="both")
    for ax in axes[-1]:
        ax.set_xlabel("time since start [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"{run.name}: predicted 1-sigma per error state")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def observability_html(run: RecordedRun, sols: dict[str, NavSolution], cfg, replay=None) -> str:
    """Motion context and, per state, the share of predicted variance each aiding removes (EKF),
    from ``replay`` (the ``ekf-acc`` pass's own matrices), or from one more ``ekf-acc`` pass when
    the run did not have one."""
    from ..analysis.motion import classify_motion
    from ..analysis.observability import STATE_NAMES, aiding_information, replay_ekf

    ref = next((sols[m] for m in ("smoother", "smoother-acc", "ekf", "ekf-acc") if m in sols), None)
    if ref is None:
        return ""
    fractions = classify_motion(run, ref).fractions()
    motion = "".join(f"<tr><td>{html.escape(k)}</td><td>{100 * v:.1f}</td></tr>" for k, v in fractions.items())
    summary = aiding_information(replay or replay_ekf(run, cfg, "ekf-acc")).summary()
    rows = "".join(f"<tr><td>{n}</td><td>{100 * summary[n]['pos']:.2f}</td><td>{100 * summary[n]['pos_acc']:.2f}</td>"
                   f"</tr>" for n in STATE_NAMES)
    return (f"<h2>Observability</h2><p>Motion context (from the IMU and the {html.escape(ref.method)} velocity):</p>"
            f"<table><tr><th>motion</th><th>share of epochs [%]</th></tr>{motion}</table>"
            "<p>Mean share of each state's predicted variance removed at a GNSS epoch, by the position update alone "
            "and by position + GNSS-derived acceleration (the EKF's own matrices, epochs with an acceleration):</p>"
            f"<table><tr><th>state</th><th>position [%]</th><th>position + acceleration [%]</th></tr>{rows}</table>")


def comparison_html(metrics: dict) -> str:
    """The comparison table as an HTML table (numbers right-aligned, '!' cells flagged), with
    the scored window above it, a row per failed method with its reason, and the NIS legend."""
    head, rows = table_rows(metrics)
    above, below = table_notes(metrics)
    cell = lambda c, i: (f'<td class="num{" warn" if c.endswith("!") else ""}">{html.escape(c)}</td>' if i
                         else f"<td>{html.escape(c)}</td>")
    body = "".join("<tr>" + "".join(cell(c, i) for i, c in enumerate(r)) + "</tr>" for r in rows)
    body += "".join(f'<tr><td>{html.escape(m)}</td><td class="warn" colspan="{len(head) - 1}">failed: '
                    f"{html.escape(r)}</td></tr>" for m, r in failed_methods(metrics).items())
    return ("".join(f"<p>{html.escape(t)}</p>" for t in above) + "<table><tr>"
            + "".join(f"<th>{html.escape(h)}</th>" for h in head) + f"</tr>{body}</table>"
            + "".join(f'<p class="note">{html.escape(t)}</p>' for t in below))


def _fmt(x, spec: str = ".2f") -> str:
    return "-" if x is None else format(x, spec)


def consistency_html(metrics: dict) -> str:
    """Per method: NIS per update kind, innovation whiteness, fix residual ratio, and the warnings."""
    cons = metrics.get("consistency") or {}
    if not cons:
        return "<p>No consistency figures.</p>"
    rows = "".join(
        f"<tr><td>{html.escape(m)}</td>" + "".join(f"<td>{_fmt(c['nis'].get(k))}</td>" for k in ("pos", "acc", "zupt", "zaru"))
        + f"<td>{_fmt(c.get('innovation_acf1'))}</td><td>{_fmt(c.get('fix_residual_ratio'))}</td>"
        + f"<td>{'<br>'.join(html.escape(w) for w in c['warnings']) or 'none'}</td></tr>" for m, c in cons.items())
    return ("<p>1 is consistent for every NIS figure (EKF: innovations; smoother: GNSS residuals against their "
            "expectation); innovation autocorrelation near 0; fix residual ratio below 1.41 (an estimate as good as "
            "the fixes and independent of them).</p><table><tr><th>method</th><th>NIS position</th>"
            "<th>acceleration</th><th>zero velocity</th><th>zero rate</th><th>innovation autocorrelation</th>"
            f"<th>fix residual ratio</th><th>warnings</th></tr>{rows}</table>")


def tuning_html(metrics: dict) -> str:
    """The identified noise values beside their starting values, with the NIS before and after."""
    t = metrics.get("tuning")
    if not t:
        return "<p>The configuration was used as given (<code>--tune none</code>).</p>"
    back = set(t.get("from_stationary", {}).get("drawn_back", []))
    rows = "".join(f"<tr><td>{html.escape(sec)}.{html.escape(k)}</td><td>{html.escape(str(t['start'].get(f'{sec}.{k}', '-')))}"
                   f"</td><td>{html.escape(str(v))}{' (drawn back toward the start)' if f'{sec}.{k}' in back else ''}"
                   f"</td></tr>" for sec, vals in t["values"].items() for k, v in vals.items())
    return (f"<p>{t['n_evaluations']} EKF passes in {t['seconds']:.1f} s; position NIS per dof {_fmt(t['nis_before'])} "
            f"at the start, {_fmt(t['nis_after'])} tuned. Kept from the configuration: "
            f"{html.escape(', '.join(t['fixed']) or 'nothing')}. Written to <code>tuned.toml</code>.</p>"
            f"<table><tr><th>key</th><th>start</th><th>identified</th></tr>{rows}</table>")


def write_html_report(folder: Path, run: RecordedRun, sols: dict[str, NavSolution], metrics: dict, cfg=None,
                      replay=None) -> Path:
    """Write ``report.html`` (and ``sigmas.png``) into ``folder``; returns the page's path.

    With ``cfg`` the page also gets the observability section (:func:`observability_html`).
    """
    folder = Path(folder)
    plot_sigmas(run, sols, folder / "sigmas.png")
    spans = metrics.get("quality", {}).get("spans", [])
    rows = "".join(f"<tr><td>{html.escape(s['kind'])}</td><td>{s['t_start'] - run.t_start:.2f}</td>"
                   f"<td>{s['t_end'] - s['t_start']:.2f}</td><td>{html.escape(str(s['channels']))}</td>"
                   f"<td>{html.escape(str(s['note']))}</td></tr>" for s in spans)
    quality = (f"<table><tr><th>kind</th><th>start [s]</th><th>length [s]</th><th>channels</th><th>note</th></tr>"
               f"{rows}</table>" if spans else "<p>No suspect IMU spans.</p>")
    inits = html.escape(str(metrics.get("init") or next(iter(metrics["methods"].values()))["stats"].get("init", "")))
    figures = "".join(f'<h2>{title}</h2><img src="{name}" alt="{title}">' for name, title in
                      (("errors.png", "Position error"), ("trajectory.png", "Track"),
                       ("sigmas.png", "Per-state 1-sigma")) if (folder / name).exists())
    page = f"""<!doctype html>
<html><head><meta charset="utf-8"><title>gnssacc report: {html.escape(run.name)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}} img{{max-width:100%}}
table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:2px 6px;font-size:90%}}
pre{{background:#f6f6f6;padding:1em}} th{{background:#f0f0f0}}
td:first-child{{white-space:nowrap}} td.num{{text-align:right;font-variant-numeric:tabular-nums}} td.warn{{background:#fff3cd}} p.note{{font-size:85%;color:#555}}</style></head><body>
<h1>gnssacc report: {html.escape(run.name)}</h1>
<p>Source: {html.escape(run.where)}<br>Duration {run.duration_s:.1f} s, {len(run.imu)} IMU samples,
{len(run.gnss)} GNSS fixes. Configuration: {html.escape(', '.join(metrics.get('config_sources', [])))}.</p>
<h2>Comparison</h2>{comparison_html(metrics)}
<h2>Consistency</h2>{consistency_html(metrics)}
<h2>Noise identification</h2>{tuning_html(metrics)}
<h2>Initialisation</h2><p>All methods start from the same state: {inits}</p>
<h2>IMU data quality</h2>{quality}
{observability_html(run, sols, cfg, replay) if cfg is not None else ""}
{figures}
</body></html>
"""
    path = folder / "report.html"
    path.write_text(page)
    return path
