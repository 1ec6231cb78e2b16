"""The Python API: what ``gnssacc run`` does, from a notebook or a script.

::

    import gnssacc
    res = gnssacc.process("run.bag", methods=["ekf", "ekf-acc"])   # or "kitti", a CSV run directory
    print(res.table())                   # the table gnssacc run prints
    df = res.to_dataframe("ekf")         # the trajectory as a pandas DataFrame (pandas installed)
    res.save("out/")                     # the folder gnssacc run writes

Settings are resolved exactly as ``gnssacc run`` resolves them (the command line is a layer over
this module): KITTI runs with the ``kitti`` preset unless another (or ``"none"``) is asked for;
``noise`` makes fixes from the truth; the input checks, self-tuning and scoring are those of
:func:`gnssacc.pipeline.compare`. A run made in Python (:func:`simulate`, or a
:class:`gnssacc.core.recording.RecordedRun` of your own) can be given instead of a source.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .core.config import RunConfig
from .core.recording import RecordedRun
from .core.solution import NavSolution
from .outputs.report import TRAJECTORY_COLUMNS, format_table, ok_methods, trajectory_table
from .pipeline import (
    compare_observed,
    configure,
    load,
    load_configured,
    parse_methods,
    write_result,
)
from .prepare.cache import PreparationCache, open_cache
from .prepare.prepared import Prepared
from .sources.simspec import known_noise_config

#: The public face (``configure`` and ``load`` are :mod:`gnssacc.pipeline`'s, shared with the campaigns).
__all__ = ["process", "run", "load", "simulate", "configure", "evaluate", "Result"]


def simulate(scenario: str = "car", duration_s: float = 300.0, **options) -> RecordedRun:
    """A simulated run with known truth (:func:`gnssacc.sources.sim.simulate`; ``imu_grade``,
    ``noise``, ``seed``, rates ...), ready for :func:`process`."""
    from .sources.sim import simulate as _simulate

    return _simulate(scenario, duration_s, **options)


def process(
    source=None,
    *,
    methods=None,
    config=None,
    preset: str | None = None,
    tune: str | None = None,
    noise: str | None = None,
    seed: int = 0,
    outage: str | None = None,
    outage_every: str | None = None,
    imu_frame: str = "frd",
    gnss=None,
    show_progress: bool = False,
    cache=None,
    **bag_options,
) -> "Result":
    """Run the estimators on a source and score them: ``gnssacc run`` without the files.

    Parameters
    ----------
    source : str, Path, RecordedRun or None
        ``"kitti"`` (or ``None``), a ROS 1 ``.bag``, an ``.mcap``, a ROS 2 bag directory, a CSV run
        directory, a simulated run ``"sim:SCENARIO[,key=value...]"`` (:mod:`gnssacc.sources.simspec`; with
        ``tune="none"`` it runs with the simulator's IMU noise), or a run made in Python.
    methods : list of str or str, optional
        Method ids (default: ``ekf, ekf-acc, smoother, smoother-acc``).
    config, preset
        See :func:`configure`.
    tune : {"auto", "none"}, optional
        Noise identification from the recording (default: as ``[tuning] mode`` says, ``auto``).
    noise : str, optional
        GNSS noise made from the truth, a profile of :data:`gnssacc.sources.gnss_noise.PROFILES` (``white``,
        ``gm``, ``precise``, ``rtk``, ``none``; KITTI and ``sim:`` sources: ``white`` by default).
    seed : int
        Noise seed.
    outage, outage_every : str, optional
        GNSS outages, ``"START:LEN[,...]"`` and ``"PERIOD:LEN"`` [s].
    imu_frame : {"frd", "flu"}
        Axes of a CSV run's ``imu.csv``.
    gnss : str or Path, optional
        A GNSS file whose fixes replace the source's: an RTKLIB ``.pos``, an NMEA log or a CSV
        with ``gnss.csv``'s columns (:mod:`gnssacc.sources.gnssfile`; absolute fix times need the
        IMU stamped in UNIX or GPS seconds).
    show_progress : bool
        Progress bars on a terminal.
    cache : bool, str or Path, optional
        Keep the preparation (checks, start, tuned noise) for a rerun of the same recording and
        settings, and reuse it when kept: ``True`` in the default folder, or in this folder
        (:mod:`gnssacc.prepare.cache`); default none (``gnssacc run`` uses the default folder).
    **bag_options
        ``imu_topic``, ``gnss_topic``, ``truth_topic``, ``odom_topic``, ``time_source``,
        ``gnss_from_truth_hz``.

    Returns
    -------
    Result

    Raises
    ------
    gnssacc.core.errors.InputError
        Bad input, naming the file or option and the problem.
    """
    ids = parse_methods(
        methods if methods is None or isinstance(methods, str) else ",".join(methods)
    )
    cfg = configure(source, preset=preset, config=config)
    run = load_configured(
        source, cfg, noise, seed, outage, outage_every, imu_frame, gnss, bag_options
    )
    return evaluate(run, cfg, ids, tune=tune, show_progress=show_progress, cache=cache)


def evaluate(
    run: RecordedRun,
    cfg: RunConfig,
    methods: list[str],
    *,
    tune: str | None = None,
    show_progress: bool = False,
    observe: bool = True,
    say=None,
    header: str | None = None,
    cache=None,
) -> "Result":
    """Check, prepare, run and score ``methods`` on a loaded run (:func:`gnssacc.pipeline.compare`).

    ``observe``: keep the ``ekf-acc`` pass's matrices for the report's observability section
    (:attr:`Result.replay`), so that ``save(report=True)`` does not run the filter again.
    ``say(line)``: told the run's ``header`` line once the input checks are settled (with the
    corrections the estimator proved), then the preparation's findings and each method's end as
    they happen. ``cache``: as for :func:`process`, or a
    :class:`gnssacc.prepare.cache.PreparationCache`.
    """
    cfg = known_noise_config(
        cfg, run, tune
    )  # a sim: source with --tune none: the simulator's IMU noise
    metrics, sols, prep, replay = compare_observed(
        run,
        cfg,
        methods,
        tune=tune,
        show_progress=show_progress,
        observe=observe,
        say=say,
        header=header,
        cache=cache if isinstance(cache, PreparationCache) else open_cache(cache),
    )
    return Result(prep.run, cfg, metrics, sols, prep, replay)


#: ``gnssacc.run(...)``, named like the command: the same as :func:`process`.
run = process


@dataclass
class Result:
    """What :func:`process` found.

    Attributes
    ----------
    run : RecordedRun
        The run as the input checks left it (repaired units, a measured clock offset applied).
    config : RunConfig
        The configuration given (the tuned one is ``prepared.cfg``).
    metrics : dict
        The content of ``metrics.json`` (scores, consistency, tuning, failures).
    solutions : dict of NavSolution
        Per method that succeeded (``<id>-online`` too for the smoothers).
    prepared : gnssacc.prepare.prepared.Prepared
        The prepared recording: the shared start, stationary spans, input findings and tuned
        configuration (also as ``ident``, its earlier name).
    replay : gnssacc.analysis.observability.EkfReplay or None
        The ``ekf-acc`` pass's matrices at every GNSS epoch (for the report's observability
        section and :func:`gnssacc.analysis.observability.aiding_information`).
    """

    run: RecordedRun
    config: RunConfig
    metrics: dict
    solutions: dict[str, NavSolution]
    prepared: Prepared
    replay: object = None

    @property
    def ident(self) -> Prepared:
        """The prepared recording under its earlier name."""
        return self.prepared

    def table(self) -> str:
        """The comparison table ``gnssacc run`` prints."""
        return format_table(self.metrics)

    def prmse(self) -> dict[str, float | None]:
        """PRMSE [m] per method that succeeded (``None`` without truth), and ``"gnss"`` for the fixes."""
        out = {m: v["prmse_m"] for m, v in ok_methods(self.metrics).items()}
        return {**out, "gnss": self.metrics["gnss_prmse_m"]}

    def to_dataframe(self, method: str):
        """One method's trajectory as a pandas DataFrame, with the columns (and units, degrees at
        this edge) of ``trajectory_<id>.csv``."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError(
                "Result.to_dataframe needs pandas (pip install pandas); Result.solutions holds "
                "the same numbers as numpy arrays"
            ) from None
        if method not in self.solutions:
            raise KeyError(f"{method!r}: no solution (have: {', '.join(self.solutions) or 'none'})")
        return pd.DataFrame(trajectory_table(self.solutions[method]), columns=TRAJECTORY_COLUMNS)

    def save(
        self,
        folder,
        *,
        plots: bool = True,
        report: bool = False,
        export: tuple = (),
        overwrite: bool = False,
    ) -> Path:
        """Write the folder ``gnssacc run --out folder`` writes (all or nothing); return its path.

        Raises
        ------
        gnssacc.core.errors.InputError
            The folder holds something else (without ``overwrite``), or another writer holds it.
        """
        from .outputs.outdir import ResultDir

        with ResultDir(Path(folder), overwrite=overwrite) as target:
            return self.write(target, plots=plots, report=report, export=export)

    def write(
        self,
        target,
        *,
        plots: bool = True,
        report: bool = False,
        export: tuple = (),
        extra_files=None,
    ) -> Path | None:
        """Write into a locked :class:`gnssacc.outputs.outdir.ResultDir` (``None`` when every method failed:
        nothing is written)."""
        return write_result(
            target,
            self.run,
            self.solutions,
            self.metrics,
            self.prepared,
            plots=plots,
            report=report,
            export=tuple(export),
            extra_files=extra_files,
            replay=self.replay,
        )
