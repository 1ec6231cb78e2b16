"""One comparison run: load a source, make its GNSS, run the methods, score, write outputs.

Used by the CLI (``gnssacc run``), the benchmarks and the notebooks, so that all of them
compute the same numbers the same way.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from datetime import datetime
from pathlib import Path


from . import mechanization
from .config import RunConfig
from .consistency import assess
from .ekf import run_ekf
from .errors import InputError, warn_data
from .gnss_noise import apply_outages, fixes_from_truth, parse_outages
from .identify import Identified, identify
from .metrics import gnss_score, score
from .report import format_table, metrics_dict, plot_errors, plot_trajectory, write_json, write_trajectory_csv
from .run import RecordedRun
from .solution import NavSolution

def _ekf(ident: Identified, method: str, show_progress: bool) -> dict[str, NavSolution]:
    return {method: run_ekf(ident.run, ident.cfg, method, quality=ident.quality, init=ident.init,
                            stationary=ident.stationary, show_progress=show_progress)}


def _smoother(ident: Identified, method: str, show_progress: bool) -> dict[str, NavSolution]:
    from .smoother import run_smoother  # gtsam import only when a smoother method is asked for
    return run_smoother(ident.run, ident.cfg, method, quality=ident.quality, init=ident.init,
                        stationary=ident.stationary, show_progress=show_progress)


#: Estimators by method id: ``(identified, method, show_progress) -> {id: NavSolution}``.
#: A smoother method also returns its online estimate as ``<id>-online``.
METHODS = {"ekf": _ekf, "ekf-acc": _ekf, "smoother": _smoother, "smoother-acc": _smoother}
DEFAULT_METHODS = ("ekf", "ekf-acc", "smoother", "smoother-acc")


def parse_methods(text: str | None) -> list[str]:
    """Method ids from a comma-separated list, checked against :data:`METHODS`."""
    if not text:
        return list(DEFAULT_METHODS)
    ids = [m.strip() for m in text.split(",") if m.strip()]
    bad = [m for m in ids if m not in METHODS]
    if bad or not ids:
        raise InputError("--methods", f"unknown method(s) {', '.join(bad) or '(none)'}; known: {', '.join(METHODS)}")
    return ids


def is_bag(path: Path) -> bool:
    """ROS 1 ``.bag``, bare ``.mcap``, or a ROS 2 bag directory (with ``metadata.yaml``)."""
    return (path.is_file() and path.suffix in (".bag", ".mcap")) or (path.is_dir() and (path / "metadata.yaml").exists())


def load_source(source: str | None, cfg: RunConfig, *, noise: str | None = None, seed: int = 0,
                imu_frame: str = "frd", imu_topic: str | None = None, gnss_topic: str | None = None,
                truth_topic: str | None = None, time_source: str = "header",
                gnss_from_truth_hz: float | None = None) -> RecordedRun:
    """Load a run from a source spec.

    Parameters
    ----------
    source : str or None
        ``None`` or ``"kitti"``: the KITTI sequence in the gtsam wheel. A ROS 1 ``.bag``, a bare
        ``.mcap`` or a ROS 2 bag directory: read through rosbags. Another directory: a CSV run
        directory (``imu.csv``, ``gnss.csv``, optional ``truth.csv``, ``init.json``).
    cfg : RunConfig
    noise : str, optional
        GNSS noise profile. For KITTI it defaults to ``white``. For a CSV directory, giving it
        replaces ``gnss.csv`` with truth + noise at the truth epochs (needs ``truth.csv``).
    seed : int
        Noise seed.
    imu_frame : {"frd", "flu"}
        Axes of a CSV directory's ``imu.csv``.
    imu_topic, gnss_topic, truth_topic, time_source, gnss_from_truth_hz
        Bag options (see :func:`gnssacc.sources.rosbag.load_bag_run`); for a bag, ``noise``
        applies to the fixes made from the truth with ``gnss_from_truth_hz``.
    """
    if source in (None, "kitti"):
        from .sources.kitti import load_kitti
        return load_kitti(cfg, noise or "white", seed)
    path = Path(source)
    if not path.exists():
        raise InputError(source, "no such file or directory")
    if is_bag(path):
        from .sources.rosbag import load_bag_run
        return load_bag_run(path, cfg, imu_topic=imu_topic, gnss_topic=gnss_topic, truth_topic=truth_topic,
                            time_source=time_source, gnss_from_truth_hz=gnss_from_truth_hz,
                            noise=noise, seed=seed)
    if path.is_dir():
        from .sources.csvdir import load_csv_run
        run = load_csv_run(path, cfg, imu_frame=imu_frame)
        if noise is not None:
            if run.truth is None:
                raise InputError(str(path), "--noise makes fixes from the truth, but the run has no truth.csv")
            run = run.with_gnss(fixes_from_truth(run, run.truth, noise, seed), noise=noise, seed=seed)
        return run
    raise InputError(source, "not a run: expected a CSV run directory (imu.csv, gnss.csv), a ROS 1 .bag, "
                             "a .mcap file or a ROS 2 bag directory")


def with_outages(run: RecordedRun, outage: str | None, outage_every: str | None) -> RecordedRun:
    """Apply ``--outage`` / ``--outage-every`` to the run's GNSS."""
    return apply_outages(run, parse_outages(outage, outage_every, run.duration_s))


def run_methods(run: RecordedRun, cfg: RunConfig, methods: list[str], *, tune: str | None = None,
                ident: Identified | None = None, show_progress: bool = False) -> dict[str, NavSolution]:
    """Run each method on the same run, from the same identified start and noise.

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
    methods : list of str
        Method ids (:data:`METHODS`).
    tune : {"auto", "none"}, optional
        Noise identification (default: the configuration's ``[tune] mode``).
    ident : Identified, optional
        A result of :func:`gnssacc.identify.identify` to reuse (then ``run``/``cfg``/``tune`` are
        not looked at again).
    """
    ident = ident or identify(run, cfg, tune)
    out: dict[str, NavSolution] = {}
    for m in methods:
        out.update(METHODS[m](ident, m, show_progress))
    return out


def common_window(run: RecordedRun, sols: dict[str, NavSolution]) -> tuple[float, float]:
    """The stretch every solution covers [s] (the whole run when they all do)."""
    starts = [float(s.t[0]) for s in sols.values() if len(s)] or [run.t_start]
    ends = [float(s.t[-1]) for s in sols.values() if len(s)] or [run.t_end]
    return max(starts), min(ends)


def compare(run: RecordedRun, cfg: RunConfig, methods: list[str], *, tune: str | None = None,
            show_progress: bool = False) -> tuple[dict, dict, Identified]:
    """Identify, run and score the methods over a common window, with consistency figures.

    Returns
    -------
    metrics : dict
        The content of ``metrics.json``.
    solutions : dict of NavSolution
    ident : Identified
        The shared start, stationary spans and (tuned) configuration.
    """
    jit_s = mechanization.warm_up()
    ident = identify(run, cfg, tune)
    sols = run_methods(run, cfg, methods, ident=ident, show_progress=show_progress)
    window = common_window(run, sols)
    scores = {m: score(run, s, window) for m, s in sols.items()}
    raw = gnss_score(run, window)
    cons = {m: assess(ident.run, s, scores[m].prmse_m, raw.prmse_m, ident.model, ident.cfg.gnss_gm_sigma)
            for m, s in sols.items()}
    for m, c in cons.items():
        for text in c.warnings:
            warn_data(m, text)
    extra = {"jit_compile_s": jit_s, "identify_s": ident.seconds, "quality": ident.quality.to_dict(),
             "config_sources": ident.cfg.sources, "scored_window_s": [window[0], window[1]],
             "coverage": {m: _coverage(run, s) for m, s in sols.items()},
             "consistency": {m: c.to_dict() for m, c in cons.items()},
             "init": ident.init.how, "stationary": ident.stationary.to_dict(),
             "model_check": ident.model.to_dict() if ident.model is not None else None,
             "tuning": ident.tuning.to_dict() if ident.tuning is not None else None}
    return metrics_dict(run, sols, scores, raw, extra), sols, ident


def _coverage(run: RecordedRun, sol: NavSolution) -> dict:
    """How much of the recording (first to last IMU sample) a solution's epochs span."""
    if not len(sol):
        return {"first_s": None, "last_s": None, "fraction": 0.0}
    a, b = float(sol.t[0]) - run.t_start, float(sol.t[-1]) - run.t_start
    return {"first_s": a, "last_s": b, "fraction": (b - a) / run.duration_s if run.duration_s > 0 else 1.0}


def default_out_dir(run: RecordedRun) -> Path:
    return Path("gnssacc-out") / f"{run.name}-{datetime.now().strftime('%Y%m%d-%H%M%S')}"


def write_outputs(out_dir: Path, run: RecordedRun, sols: dict[str, NavSolution], metrics: dict, cfg: RunConfig,
                  plots: bool = True, report: bool = False, export: tuple = (), tuned_toml: str | None = None) -> Path:
    """Write all outputs into ``out_dir`` atomically.

    Files are first written to a temporary folder beside ``out_dir`` and moved in only when
    all of them exist, so an interrupted run never leaves a half-written result.

    ``report`` adds ``report.html`` (with ``sigmas.png``); ``export=("tum",)`` adds
    ``trajectory_<id>.tum`` (and ``truth.tum``) for ``evo``; ``tuned_toml`` is written as
    ``tuned.toml`` (the identified noise, reusable with ``--config``).
    """
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".gnssacc-partial-", dir=out_dir.parent))
    try:
        for mid, sol in sols.items():
            write_trajectory_csv(sol, tmp / f"trajectory_{mid}.csv")
        (tmp / "config.toml").write_text(cfg.to_toml())
        if tuned_toml is not None:
            (tmp / "tuned.toml").write_text(tuned_toml)
        if plots:
            if run.truth is not None:  # errors need a reference
                plot_errors(run, sols, tmp / "errors.png")
            plot_trajectory(run, sols, tmp / "trajectory.png")
        if "tum" in export:
            from .export import write_truth_tum, write_tum
            for mid, sol in sols.items():
                write_tum(sol, run, tmp / f"trajectory_{mid}.tum")
            if run.truth is not None:
                write_truth_tum(run, tmp / "truth.tum")
        if report:
            from .htmlreport import write_html_report
            write_html_report(tmp, run, sols, metrics, cfg)
        (tmp / "table.txt").write_text(format_table(metrics) + "\n")
        write_json(metrics, tmp / "metrics.json")  # last: its presence marks a complete result
        if out_dir.exists():
            for f in sorted(tmp.iterdir()):
                os.replace(f, out_dir / f.name)
            tmp.rmdir()
        else:
            os.replace(tmp, out_dir)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out_dir
