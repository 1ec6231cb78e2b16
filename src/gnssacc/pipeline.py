"""One comparison run: load a source, make its GNSS, run the methods, score, write outputs.

Used by the CLI (``gnssacc run``), the benchmarks and the notebooks, so that all of them
compute the same numbers the same way.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Callable

import numpy as np

from .analysis.consistency import assess, check_gm_model, check_model
from .analysis.errorstats import error_statistics, fix_statistics
from .analysis.metrics import gnss_score, score
from .core.config import RunConfig, load_config
from .core.config_docs import resolved_toml
from .core.errors import InputError, warn_data
from .core.interrupts import arrived, hold_signals, raise_if_arrived, raise_if_interrupted
from .core.memory import release_free_memory
from .core.parallel import side_by_side, usable_jobs
from .core.recording import RecordedRun
from .core.solution import NavSolution
from .estimators import kernels
from .estimators.ekf import estimate as estimate_ekf
from .estimators.settings import EkfSettings, NhcSettings
from .outputs.figures import PLOT_SETS, write_figures
from .outputs.outdir import ResultDir
from .outputs.report import (
    APPLIED,
    applied_corrections,
    clock_line,
    corrections_summary,
    format_table,
    group_warnings,
    header_line,
    metrics_dict,
    quality_line,
    write_json,
    write_trajectory_csv,
)
from .prepare.attitude_axes import AXES, attitude_axes
from .prepare.cache import PreparationCache, prepared_once
from .prepare.passes import filter_pass
from .prepare.prepared import Prepared
from .sources.gnss_noise import apply_outages, parse_outages
from .sources.simspec import is_sim_spec, load_sim


def _ekf(prep: Prepared, method: str, show_progress: bool, observer=None) -> dict[str, NavSolution]:
    return {
        method: estimate_ekf(
            prep,
            EkfSettings.from_config(prep.cfg),
            method,
            show_progress=show_progress,
            observer=observer,
            record_innovations=True,
        )
    }  # the NIS over time of nis.png


def _smoother(prep: Prepared, method: str, show_progress: bool) -> dict[str, NavSolution]:
    from .estimators.settings import SmootherSettings
    from .estimators.smoother import (
        estimate,
    )  # gtsam import only when a smoother method is asked for

    return estimate(
        prep, SmootherSettings.from_config(prep.cfg), method, show_progress=show_progress
    )


def import_estimators(methods) -> None:
    """Import the estimator modules ``methods`` run on that are imported only when used (the
    smoother's, with scipy's rotations: a tenth to half a second) now, while the methods wait for
    the kernels loading in the background (a rerun that reuses a kept preparation waits for them),
    not after that wait when the first smoother starts; a worker forked for the methods
    (:func:`methods_side_by_side`) finds them imported too."""
    if any(m.startswith("smoother") for m in methods):  # the -gm variant's base too
        from .estimators import smoother  # noqa: F401


def _gm(prep: Prepared, method: str, show_progress: bool) -> dict[str, NavSolution]:
    from .estimators.gm_variant import BASE_OF, run_gm

    return run_gm(prep, method, show_progress, METHODS[BASE_OF[method]])


def check_input(run: RecordedRun, cfg: RunConfig) -> tuple[RecordedRun, RunConfig, list]:
    """The input checks (:func:`gnssacc.checks.plausibility.check_run`) with the EKF as the clock
    offset's likelihood stage, as :func:`prepare` runs them first."""
    from .prepare.preparation import checked

    return checked(run, cfg, filter_pass)


def prepare_recording(run: RecordedRun, cfg: RunConfig, *args, **kwargs) -> Prepared:
    """:func:`gnssacc.prepare.preparation.prepare`, its module imported when first called: a rerun
    that reuses a kept preparation (:mod:`gnssacc.prepare.cache`) never loads the preparation's
    steps (the input checks, the judges of their proposals, the tuner's windows; scipy's FFT)."""
    from .prepare.preparation import prepare as prepare_steps

    return prepare_steps(run, cfg, *args, **kwargs)


def prepare(
    run: RecordedRun,
    cfg: RunConfig,
    tune: str | None = None,
    methods=(),
    on_checked=None,
    cache: PreparationCache | None = None,
    on_stage=None,
) -> Prepared:
    """The prepared recording (:func:`gnssacc.prepare.preparation.prepare`) with the EKF as its
    filter pass, and the ``-gm`` methods' setup when ``methods`` has one; ``on_checked(findings)`` is told
    the input checks' findings once they are settled, ``on_stage(name)`` each stage as it starts. With ``cache``, a stored outcome for the same
    recording and settings is reused, else the fresh one stored
    (:func:`gnssacc.prepare.cache.prepared_once`; ``on_checked`` is then also told ``reused=``)."""
    gm = any(METHODS.get(m) is _gm for m in methods)
    if cache is None:
        return prepare_recording(
            run,
            cfg,
            tune,
            filter_pass=filter_pass,
            gauss_markov=gm,
            on_checked=on_checked,
            on_stage=on_stage,
        )
    from .prepare.gauss_markov import gm_setup

    return prepared_once(
        run,
        cfg,
        tune or cfg["tune"]["mode"],
        cache,
        lambda told: prepare_recording(
            run, cfg, tune, filter_pass=filter_pass, on_checked=told, on_stage=on_stage
        ),
        (lambda p: replace(p, gauss_markov=gm_setup(p, filter_pass=filter_pass))) if gm else None,
        on_checked,
    )


def check_dicts(run: RecordedRun, findings) -> list[dict]:
    """The input checks' findings as ``metrics.json`` lists them: the repairs made as the run was
    read (``run.meta["repaired_on_load"]``: IMU stamps not in seconds) first."""
    return list(run.meta.get("repaired_on_load", [])) + [f.to_dict() for f in findings]


def state_corrections(say: Callable[[str], None] | None, header: str | None, run: RecordedRun):
    """What to do with the input checks' settled findings (``on_checked`` of :func:`prepare`):
    with ``say``, say the run's header line with the corrections the estimator proved
    (:func:`gnssacc.outputs.report.header_line`) and, when the preparation was reused, where from
    (``reused``); without (the Python API), warn of each."""

    def told(findings: list, reused: str | None = None) -> None:
        dicts = check_dicts(run, findings)
        if say is not None:
            said = f"{header}; {reused}" if header and reused else (header or reused)
            line = header_line(said, dicts)
            if line:
                say(line)
            return
        for d, text in zip(
            [d for d in dicts if d["action"] in APPLIED], applied_corrections(dicts), strict=True
        ):
            if d in run.meta.get("repaired_on_load", []):
                continue  # said as the run was read
            warn_data(d["where"], f"{d['problem']}; {text}, as the estimator proves")

    return told


#: Estimators by method id: ``(prepared, method, show_progress) -> {id: NavSolution}``.
#: A smoother method also returns its online estimate as ``<id>-online``.
METHODS = {
    "ekf": _ekf,
    "ekf-acc": _ekf,
    "ekf-accw": _ekf,
    "ekf-vacc": _ekf,
    "ekf-vaccw": _ekf,
    "smoother": _smoother,
    "smoother-acc": _smoother,
    "smoother-accw": _smoother,
    "smoother-vacc": _smoother,
    "smoother-vaccw": _smoother,
    "ekf-gm": _gm,
    "smoother-gm": _gm,
}
DEFAULT_METHODS = ("ekf", "ekf-acc", "smoother", "smoother-acc")


def parse_methods(text: str | None) -> list[str]:
    """Method ids from a comma-separated list, checked against :data:`METHODS`."""
    if not text:
        return list(DEFAULT_METHODS)
    ids = [m.strip() for m in text.split(",") if m.strip()]
    bad = [m for m in ids if m not in METHODS]
    if bad or not ids:
        raise InputError(
            "--methods",
            f"unknown method(s) {', '.join(bad) or '(none)'}; known: {', '.join(METHODS)}",
        )
    return ids


def resolve_preset(preset: str | None, source: str | None) -> str | None:
    """The preset a source runs with: KITTI uses ``kitti`` unless another (or ``"none"``) is asked for."""
    if preset is None and source in (None, "kitti"):
        preset = "kitti"
    return None if preset == "none" else preset


def is_bag(path: Path) -> bool:
    """Whether ``path`` is meant as a bag: a ``.bag``, ``.mcap`` or ``.db3`` file, or a directory with a
    ``metadata.yaml`` or, without ``imu.csv``, ROS 2 storage files (a bag that lost its metadata).

    Only the name and layout are looked at; whether the bag can be read is
    :func:`gnssacc.sources.rosbag.check_bag_path`'s business (a clear error if not).
    """
    from .sources.rosbag import MAGIC, storage_files

    if path.is_file():
        return path.suffix in MAGIC
    if not path.is_dir():
        return False
    return (path / "metadata.yaml").exists() or (
        not (path / "imu.csv").exists() and bool(storage_files(path))
    )


def load_source(
    source: str | None,
    cfg: RunConfig,
    *,
    noise: str | None = None,
    seed: int = 0,
    imu_frame: str = "frd",
    imu_topic: str | None = None,
    gnss_topic: str | None = None,
    truth_topic: str | None = None,
    time_source: str = "header",
    gnss_from_truth_hz: float | None = None,
    odom_topic: str | None = None,
    gnss: str | None = None,
) -> RecordedRun:
    """Load a run from a source spec (with ``gnss``: its fixes replaced by a file's).

    Parameters
    ----------
    source : str or None
        ``None`` or ``"kitti"``: the KITTI sequence in the gtsam wheel. ``sim:SCENARIO[,key=value...]``:
        a simulated run (:mod:`gnssacc.sources.simspec`; ``noise`` default ``white``, ``seed`` draws the IMU
        errors and the GNSS noise). A ROS 1 ``.bag``, a bare
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
    imu_topic, gnss_topic, truth_topic, time_source, gnss_from_truth_hz, odom_topic
        Bag options (see :func:`gnssacc.sources.rosbag.load_bag_run`); for a bag, ``noise``
        applies to the fixes made from the truth with ``gnss_from_truth_hz``.
    gnss : str, optional
        A GNSS file (``.pos``, NMEA, ``gnss.csv`` columns) whose fixes replace the source's
        (:func:`gnssacc.sources.gnssfile.with_gnss_file`: absolute times need an absolute IMU clock).
    """
    if gnss is not None:
        return _with_gnss_file(
            source,
            cfg,
            gnss,
            noise,
            gnss_from_truth_hz,
            seed=seed,
            imu_frame=imu_frame,
            imu_topic=imu_topic,
            gnss_topic=gnss_topic,
            truth_topic=truth_topic,
            time_source=time_source,
            odom_topic=odom_topic,
        )
    if source in (None, "kitti"):
        from .sources.kitti import load_kitti

        return load_kitti(cfg, noise or "white", seed)
    if is_sim_spec(source):
        return load_sim(source, noise, seed)
    path = Path(source)
    if not path.exists():
        raise InputError(source, "no such file or directory")
    if is_bag(path):
        from .sources.rosbag import load_bag_run

        return load_bag_run(
            path,
            cfg,
            imu_topic=imu_topic,
            gnss_topic=gnss_topic,
            truth_topic=truth_topic,
            time_source=time_source,
            gnss_from_truth_hz=gnss_from_truth_hz,
            noise=noise,
            seed=seed,
            odom_topic=odom_topic,
        )
    public = _load_public_recording(path, cfg)
    if public is not None:
        return _noisy_if_asked(public, noise, seed, path, "it has none")
    if path.is_dir():
        return _load_run_directory(path, cfg, imu_frame, noise, seed)
    raise InputError(
        source,
        "not a run: expected a CSV run directory (imu.csv, gnss.csv), a ROS 1 .bag, "
        "a .mcap file, a ROS 2 bag directory, a comma2k19 segment folder or a VectorNav "
        "export (X-imu.csv with X-gnss.csv)",
    )


def _with_gnss_file(source, cfg, gnss: str, noise, gnss_from_truth_hz, **options) -> RecordedRun:
    """:func:`load_source` of ``source`` with its fixes replaced by the GNSS file ``gnss``."""
    if noise is not None or gnss_from_truth_hz is not None:
        raise InputError(
            "--gnss",
            "the fixes come from the GNSS file: --noise and --gnss-from-truth (fixes made "
            "from the truth) do not apply",
        )
    from .sources.gnssfile import with_gnss_file

    return with_gnss_file(load_source(source, cfg, **options), gnss, cfg)


def _noisy_if_asked(
    run: RecordedRun, noise: str | None, seed: int, where: Path, lack: str
) -> RecordedRun:
    """``run`` with fixes made from its truth with ``noise`` when ``noise`` is given (else as it
    is); an :class:`InputError` naming ``where`` and ``lack`` when the run has no truth."""
    if noise is None:
        return run
    from .sources.common import with_noisy_fixes

    if run.truth is None:
        raise InputError(str(where), f"--noise makes fixes from the truth; {lack}")
    return with_noisy_fixes(run, run.truth, noise, seed)


def _load_run_directory(
    path: Path, cfg: RunConfig, imu_frame: str, noise, seed: int
) -> RecordedRun:
    """A CSV run directory (``imu.csv``, ``gnss.csv``, ...), with noisy fixes from its truth when
    ``noise`` is given; :class:`InputError` naming what it holds when it is not one."""
    from .checks.plausibility import fix_imu_time_units
    from .sources.csvdir import load_csv_run

    if not (path / "imu.csv").exists() and not any(
        (path / n).exists() for n in ("gnss.csv", "gnss.pos", "gnss.nmea")
    ):
        names = sorted(p.name for p in path.iterdir())
        held = (
            f"it holds {', '.join(names[:5])}{', ...' if len(names) > 5 else ''}"
            if names
            else "it is empty"
        )
        raise InputError(
            str(path),
            f"not a run directory: no imu.csv and gnss.csv (a CSV run) and no metadata.yaml "
            f"(a ROS 2 bag); {held}",
        )
    run = load_csv_run(path, cfg, imu_frame=imu_frame, time_units=fix_imu_time_units)
    return _noisy_if_asked(run, noise, seed, path, "the run has no truth.csv")


def _load_public_recording(path: Path, cfg: RunConfig) -> RecordedRun | None:
    """A public recording's layout read by its reader: a comma2k19 segment folder
    (:mod:`gnssacc.sources.comma2k19`) or a VectorNav CSV export
    (:mod:`gnssacc.sources.vectornav`); None for anything else (a CSV run directory holding
    ``imu.csv`` is never one)."""
    from .sources.comma2k19 import is_comma2k19, load_comma2k19
    from .sources.vectornav import load_vectornav, vectornav_pair

    if is_comma2k19(path):
        return load_comma2k19(path, cfg)
    if not (path.is_dir() and (path / "imu.csv").exists()) and vectornav_pair(path) is not None:
        return load_vectornav(path)
    return None


def with_outages(run: RecordedRun, outage: str | None, outage_every: str | None) -> RecordedRun:
    """Apply ``--outage`` / ``--outage-every`` to the run's GNSS."""
    return apply_outages(run, parse_outages(outage, outage_every, run.duration_s))


def configure(source=None, *, preset: str | None = None, config=None) -> RunConfig:
    """The configuration a source runs with.

    Parameters
    ----------
    source : str, Path, RecordedRun or None
        ``None`` or ``"kitti"`` selects the ``kitti`` preset unless ``preset`` says otherwise.
    preset : str, optional
        A packaged preset, or ``"none"`` for the defaults alone.
    config : str, Path, dict or RunConfig, optional
        A TOML file, or ``{section: {key: value}}`` overrides, applied over the preset; a
        :class:`RunConfig` is used as it is.
    """
    if isinstance(config, RunConfig):
        return config
    name = source if source is None or isinstance(source, str) else "run"
    path, overrides = (None, config) if isinstance(config, dict) else (config, None)
    return load_config(resolve_preset(preset, name), path, overrides=overrides)


def load(
    source=None,
    *,
    config=None,
    preset: str | None = None,
    noise: str | None = None,
    seed: int = 0,
    outage: str | None = None,
    outage_every: str | None = None,
    imu_frame: str = "frd",
    gnss=None,
    **bag_options,
) -> RecordedRun:
    """A recorded run, as ``gnssacc run`` loads it (see :func:`gnssacc.api.process` for the parameters)."""
    return load_configured(
        source,
        configure(source, preset=preset, config=config),
        noise,
        seed,
        outage,
        outage_every,
        imu_frame,
        gnss,
        bag_options,
    )


def load_configured(
    source, cfg, noise, seed, outage, outage_every, imu_frame, gnss, bag_options
) -> RecordedRun:
    """:func:`load` with the configuration resolved (``gnss``: a fix file replacing the source's fixes)."""
    if isinstance(source, RecordedRun):
        run = source
        if gnss is not None:
            from .sources.gnssfile import with_gnss_file

            run = with_gnss_file(run, str(gnss), cfg)
    else:
        run = load_source(
            None if source is None else str(source),
            cfg,
            noise=noise,
            seed=seed,
            imu_frame=imu_frame,
            gnss=None if gnss is None else str(gnss),
            **bag_options,
        )
    return with_outages(run, outage, outage_every)


def run_methods(
    run: RecordedRun,
    cfg: RunConfig,
    methods: list[str],
    *,
    tune: str | None = None,
    prep: Prepared | None = None,
    show_progress: bool = False,
    failures: dict[str, str] | None = None,
    observers: dict | None = None,
    say: Callable[[str], None] | None = None,
    beside: dict[str, Callable] | None = None,
) -> dict[str, NavSolution]:
    """Run each method on the same run, from the same identified start and noise.

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
    methods : list of str
        Method ids (:data:`METHODS`).
    tune : {"auto", "none"}, optional
        Noise identification (default: the configuration's ``[tune] mode``).
    prep : Prepared, optional
        A prepared recording (:func:`prepare`) to reuse (then ``run``/``cfg``/``tune`` are not looked
        at again).
    failures : dict, optional
        When given, a method whose estimator raises (any ``Exception`` but
        :class:`gnssacc.core.errors.InputError`) is recorded here as ``{method: one-line reason}``
        and the other methods still run; when omitted the exception propagates.
    observers : dict, optional
        ``{method: gnssacc.estimators.ekf.EkfObserver}`` watching an EKF method's own pass (e.g. the
        :class:`gnssacc.analysis.observability.EpochCollector` of the report's observability section).
    say : callable, optional
        ``say(line)`` is told each method's end as it happens (``ekf: done in 0.12 s``, or its failure).
    beside : dict, optional
        ``{name: call}``, calls without arguments made beside the methods: in the process with
        the lightest share when the methods run side by side (:func:`methods_side_by_side`), else
        here after them. Each call is replaced in this dict by its result; one that raises
        raises here.

    Returns
    -------
    dict of NavSolution
        By solution id (a smoother method adds ``<id>-online``); failed methods are absent. The
        attitude is the vehicle's where ``[nhc]`` turns its axes against the body's
        (:meth:`gnssacc.core.solution.NavSolution.in_vehicle_axes`, :func:`attitude_axes`).
    """
    prep = prep or prepare(run, cfg, tune, methods)
    # The attitude reported: the vehicle's axes, its sigma no less than what no measurement tells
    # of them.
    R_vb = NhcSettings.from_config(prep.cfg).R_vb
    floor = np.radians([axes_of(prep)["sigma_floor_deg"][a] for a in AXES])
    out: dict[str, NavSolution] = {}
    beside = {} if beside is None else beside
    done = methods_side_by_side(prep, methods, show_progress, observers, beside)
    for m in methods:
        try:
            extra = {"observer": observers[m]} if observers and m in observers else {}
            got = done[m] if m in done else METHODS[m](prep, m, show_progress, **extra)
            out.update({k: s.in_vehicle_axes(R_vb, floor) for k, s in got.items()})
            release_free_memory()  # one method's work arrays, before the next one's
            if say:
                say(
                    f"{m}: done in {max(s.runtime_s for s in got.values()):.2f} s"
                    + (f" ({', '.join(got)})" if len(got) > 1 else "")
                )
        except InputError:
            raise
        except Exception as exc:  # an estimator failure costs that method only
            raise_if_interrupted(exc)
            if failures is None:
                raise
            failures[m] = failure_reason(exc)
            if say:
                say(f"{m}: failed ({failures[m]})")
    for name, call in beside.items():  # made here those not made in a worker (or failed there)
        beside[name] = call.value if isinstance(call, _Made) else call()
    return out


def axes_of(prep: Prepared) -> dict:
    """:func:`attitude_axes` of a prepared run: its start and the tuner's record of the vehicle's
    axes (``vehicle_axes``, where it searched them)."""
    tuned = prep.tuning.from_stationary.get("vehicle_axes") if prep.tuning else None
    return attitude_axes(prep.cfg, prep.init, tuned)


class _Made:
    """The result of a ``beside`` call of :func:`run_methods` made in a worker."""

    def __init__(self, value):
        self.value = value


def timed_call(call: Callable, *args) -> tuple:
    """``(call(*args), seconds it took)``."""
    t = time.perf_counter()
    value = call(*args)
    return value, time.perf_counter() - t


#: Relative cost of a method, to share the methods among processes (a smoother ~4 EKF passes).
_SMOOTHER_WEIGHT = 4.0


def method_groups(methods, observers: dict | None, jobs: int) -> list[list[str]]:
    """``methods`` shared among ``jobs`` processes, the heaviest first to the lightest share (a
    smoother weighs :data:`_SMOOTHER_WEIGHT` EKF passes); the first share is this process's and
    has every method watched by an observer (it must run here). Empty shares are left out."""
    groups: list[list[str]] = [[] for _ in range(max(1, jobs))]
    load = [0.0] * len(groups)
    for m in (m for m in methods if observers and m in observers):
        groups[0].append(m)
        load[0] += 1.0
    rest = [m for m in methods if not (observers and m in observers)]
    for m in sorted(rest, key=lambda m: -method_weight(m)):
        k = int(np.argmin(load))
        groups[k].append(m)
        load[k] += method_weight(m)
    return [g for k, g in enumerate(groups) if g or k == 0]


def method_weight(method: str) -> float:
    """A method's relative cost (an EKF pass 1, a smoother :data:`_SMOOTHER_WEIGHT`)."""
    return _SMOOTHER_WEIGHT if METHODS.get(method) is _smoother else 1.0


def methods_side_by_side(
    prep: Prepared, methods, show_progress: bool, observers: dict | None, beside: dict
) -> dict[str, dict[str, NavSolution]]:
    """The methods' solutions, ``{method: its solutions}``, run side by side in processes
    (:func:`gnssacc.core.parallel.side_by_side`, shared by :func:`method_groups`) when there are
    several processes and methods; empty when they run one after the other. A method that failed
    in a worker is absent (it is run again in this process, which raises or records its failure
    as it would alone); progress bars only for this process's share. The ``beside`` calls
    (:func:`run_methods`) are made after the lightest share's methods; each made is replaced in
    ``beside`` by its result wrapped in :class:`_Made`."""
    groups = method_groups(methods, observers, usable_jobs())
    if len(groups) < 2:
        return {}
    lightest = int(np.argmin([sum(method_weight(m) for m in g) for g in groups]))

    def share(k: int) -> tuple[dict, dict]:
        got: dict = {}
        for m in groups[k]:
            extra = {"observer": observers[m]} if observers and m in observers else {}
            try:
                got[m] = METHODS[m](prep, m, show_progress and k == 0, **extra)
            except Exception:  # noqa: BLE001 (run again in this process, which says why)
                continue
            release_free_memory()
        made: dict = {}
        for name, call in beside.items() if k == lightest else ():
            try:
                made[name] = _Made(call())
            except Exception:  # noqa: BLE001 (made again in this process, which raises)
                continue
        return got, made

    done: dict = {}
    for got, made in side_by_side(share, [(k,) for k in range(len(groups))], jobs=len(groups)):
        done.update(got)
        beside.update(made)
    return done


def failure_reason(exc: BaseException, limit: int = 200) -> str:
    """One line for a method's failure: the exception type and its first sentence."""
    text = " ".join(str(exc).split())
    cut = text.find(". ")
    text = text[: cut + 1] if cut > 0 else text
    text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def common_window(run: RecordedRun, sols: dict[str, NavSolution]) -> tuple[float, float]:
    """The stretch every solution covers [s] (the whole run when they all do)."""
    starts = [float(s.t[0]) for s in sols.values() if len(s)] or [run.t_start]
    ends = [float(s.t[-1]) for s in sols.values() if len(s)] or [run.t_end]
    return max(starts), min(ends)


#: Method suffixes that fit the acceleration to the GNSS velocities (they need them).
VELOCITY_SUFFIXES = ("-vacc", "-vaccw")


def check_velocity_methods(run: RecordedRun, methods) -> None:
    """Raise :class:`InputError` naming ``--methods`` when a method fits the acceleration to GNSS
    velocities and the recording has none (before anything is computed)."""
    need = [m for m in methods if m.endswith(VELOCITY_SUFFIXES)]
    vel = run.gnss_vel
    if need and (vel is None or not vel.measured().any()):
        raise InputError(
            "--methods",
            f"{', '.join(need)} {'fits' if len(need) == 1 else 'fit'} the acceleration to GNSS "
            f"velocities, and {run.where} has none",
        )


def compare(
    run: RecordedRun,
    cfg: RunConfig,
    methods: list[str],
    *,
    tune: str | None = None,
    show_progress: bool = False,
    observers: dict | None = None,
    say: Callable[[str], None] | None = None,
    header: str | None = None,
    cache: PreparationCache | None = None,
) -> tuple[dict, dict, Prepared]:
    """Prepare the recording, run and score the methods over a common window, with consistency figures.

    A method whose estimator fails is reported (a ``gnssacc: warning:`` naming it, and
    ``status: "failed"`` with ``error`` in the metrics) without costing the others; it is up
    to the caller what to do when every method failed. ``observers`` (``{method: observer}``)
    watch EKF methods' own passes (:func:`run_methods`). ``say(line)``, when given, is told the
    preparation's findings (IMU data quality, stationary spans, start, tuning) as soon as they are
    known and each method's end (:func:`run_methods`), so a caller can print results as they come;
    the first line it is told is ``header`` (the run's header line), once the input checks are
    settled, with the corrections the estimator proved (:func:`state_corrections`; without
    ``say`` each is a warning). ``cache``: reuse or store the preparation (:func:`prepare`).

    Returns
    -------
    metrics : dict
        The content of ``metrics.json``; each method has ``status`` ``"ok"`` or ``"failed"``.
    solutions : dict of NavSolution
        Of the methods that succeeded.
    prep : Prepared
        The shared start, stationary spans and (tuned) configuration.
    """
    from .core.progress import StageProgress

    check_velocity_methods(run, methods)
    told = state_corrections(say, header, run)

    stages = StageProgress(
        3 if (tune or cfg["tune"]["mode"]) == "auto" else 2, say is not None, show_progress
    )
    try:
        prep = prepare(run, cfg, tune, methods, on_checked=told, on_stage=stages, cache=cache)
    finally:
        stages.close()
    for line in preparation_lines(prep) if say else ():
        say(line)
    import_estimators(methods)  # while the kernels may still be loading
    # The kernels' compile (or load) time, in the background, and the wait for the kernels of
    # the methods (not inside their wall times).
    jit_s = kernels.warm_up() + kernels.ready(methods)
    run = prep.run  # as the input checks left it: repaired units, the measured clock offset applied
    failed: dict[str, str] = {}
    # The final noise model against the recording: one EKF pass, made beside the methods.
    beside: dict = {"model": lambda: timed_call(check_model, prep)}
    sols = run_methods(
        run,
        cfg,
        methods,
        prep=prep,
        show_progress=show_progress,
        failures=failed,
        observers=observers,
        say=say,
        beside=beside,
    )
    model, model_s = beside["model"]
    models = {"": model}
    seconds = {**prep.seconds, "model_check_s": model_s}
    window = scored_window(run, sols)
    raw = gnss_score(run, window)
    raw.errors = fix_statistics(run, window)
    scores, cons = score_solutions(prep, sols, window, models, failed)
    for who, text in group_warnings([(m, w) for m, c in cons.items() for w in c.warnings]):
        warn_data(who, text)
    for m, reason in failed.items():
        warn_data(m, f"failed: {reason}; the other methods' results are kept")
    extra = {
        "jit_compile_s": jit_s,
        "identify_s": seconds,
        **_run_facts(prep, sols, window, cons, models, str(cfg["checks"]["on_proof"])),
    }
    return metrics_dict(run, sols, scores, raw, extra, failed), sols, prep


def score_solutions(prep: Prepared, sols: dict, window, models: dict, failed: dict):
    """Each solution's score and error statistics over ``window`` and its consistency
    (:func:`gnssacc.analysis.consistency.assess`), ``(scores, consistency)`` by solution id; a
    solution whose scoring fails is moved from ``sols`` to ``failed`` (it costs no other)."""
    run = prep.run
    scores, cons = {}, {}
    for m, s in list(sols.items()):
        try:
            scores[m] = score(run, s, window)
            scores[m].errors = error_statistics(run, s, window)
            fixes = scores[m].errors.get("at_fixes") or {}
            judged, model = _noise_model_of(prep, m, sols, models)
            cons[m] = assess(
                judged.modelled_run,  # the fixes' noise the estimate was made with
                s,
                fixes.get("prmse_m"),
                fixes.get("gnss_prmse_m"),
                model,
                judged.cfg.gnss_gm_sigma,
                errors=scores[m].errors,
                n_fixes=fixes.get("n"),
                tuned=prep.tuning is not None,
            )
        except Exception as exc:
            raise_if_interrupted(exc)
            failed[m] = failure_reason(exc)
            del sols[m]
            scores.pop(m, None)
    return scores, cons


def _run_facts(prep: Prepared, sols: dict, window, cons: dict, models: dict, on_proof: str) -> dict:
    """The run's part of ``metrics.json`` beside the methods': preparation, start, checks,
    coverage, consistency, model checks and tuning."""
    run = prep.run
    checks = check_dicts(run, prep.checks)
    return {
        "quality": prep.quality.to_dict(),
        "config_sources": prep.cfg.sources,
        "scored_window_s": [window[0], window[1]],
        "truth_coverage": truth_coverage(run),
        "coverage": {m: _coverage(run, s) for m, s in sols.items()},
        "consistency": {m: c.to_dict() for m, c in cons.items()},
        "init": prep.init.how,
        "start": start_dict(prep.init),
        "stationary": prep.stationary.to_dict(),
        "input_checks": checks,
        "input_corrections": corrections_summary(checks, on_proof),
        "model_check": models[""].to_dict(),
        "model_check_gm": models["gm"].to_dict() if "gm" in models else None,
        "tuning": prep.tuning.to_dict() if prep.tuning is not None else None,
        "preparation_cache": prep.cache,
        "attitude_axes": axes_of(prep),
    }


def start_dict(init) -> dict:
    """The start's yaw and what it rests on (``metrics.json`` ``start``; the table says when it is
    undetermined)."""
    why = (
        "the vehicle never turned or accelerated enough to tell it"
        if init.yaw_evidence == "undetermined"
        else ""
    )
    return {
        "yaw_deg": float(np.degrees(init.rpy[2])),
        "yaw_sigma_deg": float(np.degrees(init.sigma_att_rad[2])),
        "yaw_evidence": init.yaw_evidence,
        "yaw_determined": bool(init.yaw_determined),
        "why": why,
    }


def _noise_model_of(prep: Prepared, sid: str, sols: dict, models: dict):
    """The prepared recording whose run (fix sigmas) and configuration (Gauss-Markov sigmas) a
    solution used, and the check of its noise model: the ``-gm`` methods' own (from ``ekf-gm``'s
    pass when ``sols`` has it; made once, kept in ``models``), else the run's."""
    if METHODS.get(sid.removesuffix("-online")) is _gm:
        if "gm" not in models:
            models["gm"] = check_gm_model(prep, models[""], sols.get("ekf-gm"))
        return prep.gauss_markov[0], models["gm"]
    return prep, models[""]


#: Truth may miss this much of the recording before :func:`scored_window` warns [s].
TRUTH_SHORT_TOLERANCE_S = 2.0


#: A step of the truth longer than this many times its median interval is a gap: the scores
#: interpolate the truth across it, and the table says so.
TRUTH_GAP_FACTOR = 2.0


def truth_coverage(run: RecordedRun) -> dict | None:
    """The part of the recording (first to last IMU sample) the truth spans, from the start [s],
    its sample interval [s] and its gaps (steps above :data:`TRUTH_GAP_FACTOR` intervals)."""
    if run.truth is None:
        return None
    a = max(float(run.truth.t[0]), run.t_start) - run.t_start
    b = min(float(run.truth.t[-1]), run.t_end) - run.t_start
    span = max(b - a, 0.0)
    dt = np.diff(run.truth.t)
    interval = float(np.median(dt)) if len(dt) else 0.0
    gaps = dt[dt > TRUTH_GAP_FACTOR * interval] if len(dt) else dt
    return {
        "first_s": a,
        "last_s": b,
        "fraction": span / run.duration_s if run.duration_s > 0 else 1.0,
        "interval_s": interval,
        "gaps": {"n": int(len(gaps)), "longest_s": float(gaps.max()) if len(gaps) else 0.0},
    }


def scored_window(run: RecordedRun, sols: dict[str, NavSolution]) -> tuple[float, float]:
    """:func:`common_window` within the truth's span, warning when the truth misses part of the run.

    The solutions still cover the whole run; only the scores are limited to where truth exists.
    """
    a, b = common_window(run, sols)
    cov = truth_coverage(run)
    if cov is None:
        return a, b
    span = max(cov["last_s"] - cov["first_s"], 0.0)
    if run.duration_s - span > TRUTH_SHORT_TOLERANCE_S:
        warn_data(
            f"{run.where} (truth)",
            f"the truth covers only {span:.1f} of {run.duration_s:.1f} s of the run "
            f"(t = {cov['first_s']:.1f} .. {cov['last_s']:.1f} s from the start); "
            f"the outputs cover the whole run, the scores only that part",
        )
    return max(a, run.t_start + cov["first_s"]), min(b, run.t_start + cov["last_s"])


def _coverage(run: RecordedRun, sol: NavSolution) -> dict:
    """How much of the recording (first to last IMU sample) a solution's epochs span."""
    if not len(sol):
        return {"first_s": None, "last_s": None, "fraction": 0.0}
    a, b = float(sol.t[0]) - run.t_start, float(sol.t[-1]) - run.t_start
    return {
        "first_s": a,
        "last_s": b,
        "fraction": (b - a) / run.duration_s if run.duration_s > 0 else 1.0,
    }


def preparation_lines(prep: Prepared) -> list[str]:
    """What the preparation found, one line each: IMU data quality, stationary spans, the start and
    (``--tune auto``) the identified noise."""
    clock = clock_line([f.to_dict() for f in prep.checks])
    lines = ([clock] if clock else []) + [
        quality_line(prep.quality.to_dict()),
        prep.stationary.summary(),
        f"start: {prep.init.how}",
    ]
    tuned = [prep.tuning.line()] if prep.tuning is not None else []
    win = prep.tuning.from_stationary.get("windows") if prep.tuning is not None else None
    if win:
        tuned.append(
            f"tuned on {len(win['spans_s'])} windows, {win['imu_seconds_per_pass']:.0f} of "
            f"{win['run_seconds']:.0f} s per pass (kept where the run rests and turns as a whole); "
            f"confirmed over the whole run: log-likelihood {win['whole_run_loglik_gain']:+.0f} "
            "against the configured noise"
        )
    return lines + tuned


def compare_and_write(
    run: RecordedRun,
    cfg: RunConfig,
    methods: list[str],
    target: ResultDir,
    *,
    tune: str | None = None,
    plots: bool = True,
    report: bool = False,
    export: tuple = (),
    extra_files: Callable[[dict], dict[str, str]] | None = None,
    show_progress: bool = False,
    cache: PreparationCache | None = None,
    jobs: int | None = None,
) -> tuple[dict, dict, Prepared, Path | None]:
    """:func:`compare`, then :func:`write_result` (what each ``gnssacc batch`` task does;
    ``cache``: see :func:`compare`; ``jobs``: see :func:`write_result`).

    Returns
    -------
    metrics, solutions, prep
        As from :func:`compare`.
    out : Path or None
        As from :func:`write_result`.
    """
    metrics, sols, prep, replay = compare_observed(
        run, cfg, methods, tune=tune, show_progress=show_progress, observe=report, cache=cache
    )
    return (
        metrics,
        sols,
        prep,
        write_result(
            target,
            prep.run,
            sols,
            metrics,
            prep,
            plots=plots,
            report=report,
            export=export,
            extra_files=extra_files,
            replay=replay,
            jobs=jobs,
        ),
    )


def compare_observed(
    run: RecordedRun,
    cfg: RunConfig,
    methods: list[str],
    *,
    tune: str | None = None,
    show_progress: bool = False,
    observe: bool = True,
    say: Callable[[str], None] | None = None,
    header: str | None = None,
    cache: PreparationCache | None = None,
):
    """:func:`compare`, keeping (with ``observe``, when ``ekf-acc`` runs) that pass's matrices at
    every GNSS epoch for the report's observability section.

    Returns
    -------
    metrics, solutions, prep
        As from :func:`compare`.
    replay : gnssacc.analysis.observability.EkfReplay or None
    """
    collector = None
    if observe and "ekf-acc" in methods:
        from .analysis.observability import EpochCollector

        collector = EpochCollector(False)
    metrics, sols, prep = compare(
        run,
        cfg,
        methods,
        tune=tune,
        show_progress=show_progress,
        observers={"ekf-acc": collector} if collector else None,
        say=say,
        header=header,
        cache=cache,
    )
    replay = (
        collector.replay("ekf-acc", sols["ekf-acc"]) if collector and "ekf-acc" in sols else None
    )
    return metrics, sols, prep, replay


def write_result(
    target: ResultDir,
    run: RecordedRun,
    sols: dict[str, NavSolution],
    metrics: dict,
    prep: Prepared,
    *,
    plots: bool = True,
    report: bool = False,
    export: tuple = (),
    extra_files: Callable[[dict], dict[str, str]] | None = None,
    replay=None,
    jobs: int | None = None,
) -> Path | None:
    """Write a complete result through ``target`` (all or nothing).

    Parameters
    ----------
    target : ResultDir
        The locked output folder (inside its ``with`` block).
    run, sols, metrics, prep
        As :func:`compare` returned them (``run``: ``prep.run``).
    plots, report, export
        As for :func:`write_result_files`.
    extra_files : callable, optional
        ``extra_files(metrics) -> {file name: text}``: more files written into the folder beside
        the result.
    replay : EkfReplay, optional
        For the report (:func:`write_result_files`).
    jobs : int, optional
        Processes the figures may be drawn in (:func:`draw_figures`; a campaign task: 1).

    Returns
    -------
    Path or None
        The folder written; ``None`` when every method failed (then nothing is written and the
        folder keeps what it held).
    """
    if not sols:
        return None
    tuned = prep.tuning.to_toml(prep.cfg) if prep.tuning is not None else None

    def fill(folder: Path) -> None:
        write_result_files(
            folder,
            run,
            sols,
            metrics,
            prep.cfg,
            plots=plots,
            report=report,
            export=export,
            tuned_toml=tuned,
            replay=replay,
            jobs=jobs,
            stationary=prep.stationary,
        )
        for name, text in (extra_files(metrics) if extra_files else {}).items():
            (folder / name).write_text(text)

    return target.replace(fill)


def figure_jobs() -> int:
    """Processes the figures may be drawn in (:func:`gnssacc.core.parallel.usable_jobs`)."""
    return usable_jobs()


def draw_figures(
    folder: Path, run, sols, metrics, which: str, jobs: int | None = None, cfg=None
) -> dict:
    """:func:`gnssacc.outputs.figures.write_figures`, the plot set split over ``jobs`` processes
    (default :func:`figure_jobs`; forked after matplotlib is imported, each drawing every
    ``jobs``-th figure, this process one share): what each drew, in the set's order. The figures of
    a process that died, or did not end in time (:data:`SHARE_WAIT_FACTOR`), are drawn here."""
    names = PLOT_SETS[which]
    jobs = min(figure_jobs() if jobs is None else int(jobs), len(names))
    if jobs < 2:
        return write_figures(folder, run, sols, metrics, which, cfg=cfg)
    import multiprocessing

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401  (imported once, before the fork)

    ctx = multiprocessing.get_context("fork")
    queue = ctx.SimpleQueue()
    shares = [names[k::jobs] for k in range(jobs)]
    args = (folder, run, sols, metrics, cfg)
    sys.stdout.flush()  # a child must not write this process's buffers again
    sys.stderr.flush()
    procs = [ctx.Process(target=_draw_share, args=(queue, share, *args)) for share in shares[1:]]
    for p in procs:
        p.start()
    try:
        t = time.perf_counter()
        got = _figure_share(shares[0], *args)
        wait = max(SHARE_WAIT_MIN_S, SHARE_WAIT_FACTOR * (time.perf_counter() - t))
        for p in procs:
            p.join(timeout=max(0.0, wait - (time.perf_counter() - t)))
        while not queue.empty():
            got.update(queue.get())
        _pass_on_interruption(got.pop(_INTERRUPTED, None), got)
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
    missing = [n for n in names if n not in got]  # a process that died or hung: drawn here
    if missing:
        got.update(_figure_share(missing, *args))
    return {n: got[n] for n in names}


#: How long the drawing processes get, from the start of this process's own share: that share's
#: time this many times over, at least :data:`SHARE_WAIT_MIN_S` [s]; then their figures are drawn
#: here.
SHARE_WAIT_FACTOR = 10.0
SHARE_WAIT_MIN_S = 60.0


def _figure_share(names, folder, run, sols, metrics, cfg=None) -> dict:
    """:func:`write_figures` of the figures ``names`` (a plot set of their own, for this call)."""
    key = f"share-{os.getpid()}"
    PLOT_SETS[key] = tuple(names)
    try:
        return write_figures(folder, run, sols, metrics, key, cfg=cfg)
    finally:
        PLOT_SETS.pop(key, None)


#: Key of a drawing process's answer that carries the signal it was interrupted by.
_INTERRUPTED = "__interrupted__"


def _draw_share(queue, names, folder, run, sols, metrics, cfg=None) -> None:
    """A drawing process: its figures, and what it drew on ``queue``, with the signal that
    interrupted it (even one that compiled code swallowed) under :data:`_INTERRUPTED`."""
    try:
        got = _figure_share(names, folder, run, sols, metrics, cfg)
    except BaseException as exc:  # noqa: BLE001 (reported by name, never raised in a child)
        got = {n: f"not drawn: {type(exc).__name__}" for n in names}
    finally:
        hold_signals()  # the answer goes out whole: a signal from here on is recorded, not raised
    queue.put({**got, _INTERRUPTED: arrived()} if arrived() is not None else got)


def _pass_on_interruption(signum: int | None, got: dict) -> None:
    """A drawing process was interrupted: so is this one, by the same signal, as if compiled code
    had swallowed it here (its handler records it; the run's next checkpoint raises it, after the
    result is written when every figure was drawn); at once when the interruption cut a figure
    (``got``: what each figure came to), as a figure cut in this process would."""
    if signum is None:
        return
    try:
        os.kill(os.getpid(), signum)
    except BaseException:  # noqa: BLE001 (the interruption itself: recorded, raised below or later)
        pass
    cut = {"not drawn: Terminated", "not drawn: KeyboardInterrupt"}
    if any(isinstance(v, str) and v in cut for v in got.values()):
        raise_if_arrived()


def default_out_dir(run: RecordedRun) -> Path:
    return Path("gnssacc-out") / f"{run.name}-{datetime.now().strftime('%Y%m%d-%H%M%S')}"


def write_outputs(
    out_dir: Path,
    run: RecordedRun,
    sols: dict[str, NavSolution],
    metrics: dict,
    cfg: RunConfig,
    plots: bool = True,
    report: bool = False,
    export: tuple = (),
    tuned_toml: str | None = None,
    overwrite: bool = False,
) -> Path:
    """Replace ``out_dir`` as a whole by a complete result (:class:`gnssacc.outputs.outdir.ResultDir`).

    Takes the folder's lock for the time of writing; the CLI instead holds a
    :class:`~gnssacc.outputs.outdir.ResultDir` over the whole run and calls :func:`write_result_files`
    through it. ``overwrite`` also replaces a folder that is not a gnssacc result. The other
    parameters are those of :func:`write_result_files`.
    """
    with ResultDir(out_dir, overwrite=overwrite) as target:
        return target.replace(
            lambda folder: write_result_files(
                folder,
                run,
                sols,
                metrics,
                cfg,
                plots=plots,
                report=report,
                export=export,
                tuned_toml=tuned_toml,
            )
        )


def plot_set(plots: bool | str | None, report: bool = False) -> str:
    """The ``--plots`` choice (:data:`gnssacc.outputs.figures.PLOT_SETS`) from ``plots``: a name, or
    ``True``/``None`` for the default (``basic``; ``all`` with the report), ``False`` for ``none``."""
    if plots is False:
        return "none"
    if plots is True or plots is None:
        return "all" if report else "basic"
    if plots not in PLOT_SETS:
        raise InputError("--plots", f"{plots!r}: expected one of {', '.join(PLOT_SETS)}")
    return plots


def write_result_files(
    folder: Path,
    run: RecordedRun,
    sols: dict[str, NavSolution],
    metrics: dict,
    cfg: RunConfig,
    plots: bool | str = True,
    report: bool = False,
    export: tuple = (),
    tuned_toml: str | None = None,
    replay=None,
    jobs: int | None = None,
    stationary=None,
) -> None:
    """Write every output file into ``folder`` (a fresh folder; see :func:`write_outputs`).

    ``trajectory_<id>.csv`` per solution, ``config.toml``, ``table.txt``, ``metrics.json`` (with
    the failed methods too); ``plots`` (``"none"``, ``"basic"``, ``"all"``, or a bool: :func:`plot_set`)
    the figures of :mod:`gnssacc.outputs.figures`; ``report`` adds ``report.html``; ``export`` may hold ``"tum"``
    (``trajectory_<id>.tum`` and the truth's, for ``evo``), ``"bag"`` (``trajectories/``, a ROS 2
    bag of ``nav_msgs/Odometry``) and ``"ros1bag"`` (``trajectories.bag``); ``tuned_toml`` is written as
    ``tuned.toml`` (the identified noise, reusable with ``--config``); ``replay`` is the
    ``ekf-acc`` pass's :class:`gnssacc.analysis.observability.EkfReplay` for the report (``None``: the
    report runs that filter once more); ``jobs``: see :func:`draw_figures`.
    """
    folder = Path(folder)
    for mid, sol in sols.items():
        write_trajectory_csv(sol, folder / f"trajectory_{mid}.csv")
    (folder / "config.toml").write_text(resolved_toml(cfg))
    if tuned_toml is not None:
        (folder / "tuned.toml").write_text(tuned_toml)
    drawn = draw_figures(folder, run, sols, metrics, plot_set(plots, report), jobs, cfg=cfg)
    if "tum" in export:
        from .outputs.export import write_truth_tum, write_tum

        for mid, sol in sols.items():
            write_tum(sol, run, folder / f"trajectory_{mid}.tum")
        if run.truth is not None:
            write_truth_tum(run, folder, sols, metrics.get("scored_window_s"))
    for kind in set(export) & {"bag", "ros1bag"}:
        from .outputs.odombag import BAG_EXPORTS, write_odometry_bag

        write_odometry_bag(sols, run, folder / BAG_EXPORTS[kind])
    if report:
        from .outputs.htmlreport import write_html_report

        write_html_report(
            folder, run, sols, metrics, cfg, replay=replay, figures=drawn, stationary=stationary
        )
    (folder / "table.txt").write_text(format_table(metrics) + "\n")
    write_json(metrics, folder / "metrics.json")
