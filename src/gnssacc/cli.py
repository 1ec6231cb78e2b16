"""The ``gnssacc`` command.

Exit codes: 0 success (for ``run``: at least one method succeeded), 1 every method failed, 2 bad
input (one line on stderr naming the file and the problem; also a locked or foreign ``--out``),
130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from .core.config import PRESETS, load_config
from .core.errors import DataWarning, InputError
from .core.interrupts import Terminated, raise_if_interrupted
from .core.version import __version__
from .sources.gnss_noise import PROFILES
from .sources.sim_scenarios import SCENARIOS


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gnssacc", description="INS/GNSS estimation with GNSS-derived acceleration aiding."
    )
    p.add_argument("--version", action="version", version=f"gnssacc {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    _run_parser(sub)
    _bench_parser(sub)
    _batch_parser(sub)
    _tool_parsers(sub)
    return p


def _run_parser(sub) -> None:
    r = sub.add_parser(
        "run",
        help="run and compare estimators on a recorded run",
        description="Run the estimators on a run and print a comparison table. SOURCE: omitted or "
        "'kitti' for the KITTI sequence inside the gtsam wheel, a ROS 1 .bag, a .mcap, a "
        "ROS 2 bag directory, or a CSV run directory.",
    )
    r.add_argument(
        "source", nargs="?", default=None, help="'kitti' (default), a bag, or a CSV run directory"
    )
    r.add_argument(
        "--methods",
        default=None,
        help="comma-separated method ids (default: ekf,ekf-acc,smoother,smoother-acc); each smoother "
        "method also reports its online estimate as <id>-online",
    )
    r.add_argument("--seed", type=int, default=0, help="GNSS noise seed (default 0)")
    r.add_argument(
        "--noise",
        choices=list(PROFILES),
        default=None,
        help="GNSS noise profile for sources with truth (KITTI default: white); for a CSV run it "
        "replaces gnss.csv by truth + noise",
    )
    r.add_argument(
        "--outage",
        default=None,
        metavar="START:LEN[,START:LEN...]",
        help="drop GNSS over these spans (seconds from the run start)",
    )
    r.add_argument(
        "--outage-every",
        default=None,
        metavar="PERIOD:LEN",
        help="drop GNSS for LEN s at the end of every PERIOD s",
    )
    _estimation_arguments(r)
    _recording_arguments(r)
    _output_arguments(r)


def _estimation_arguments(r: argparse.ArgumentParser) -> None:
    """``run``'s configuration, tuning, aid switches and input-check policy."""
    r.add_argument(
        "--config", default=None, help="run configuration TOML (see 'gnssacc config --show')"
    )
    r.add_argument(
        "--preset",
        default=None,
        choices=PRESETS + ("none",),
        help="named configuration preset: an IMU grade (consumer, industrial, tactical: starting points "
        "for --tune auto) or kitti (the KITTI source uses 'kitti' unless told otherwise; 'none': "
        "built-in defaults)",
    )
    r.add_argument(
        "--tune",
        choices=["auto", "none"],
        default=None,
        help="auto (default): identify every IMU noise key the config does not set (and the GNSS sigma "
        "scale) from the recording itself, write tuned.toml; none: use the configuration as given",
    )
    r.add_argument(
        "--retune",
        action="store_true",
        help="prepare the recording afresh (input checks, start, tuned noise) instead of reusing "
        "the outcome kept from an earlier run of the same recording and settings "
        "($GNSSACC_CACHE_DIR, default ~/.cache/gnssacc/prepared; 'none' keeps nothing)",
    )
    r.add_argument(
        "--imu-frame", choices=["frd", "flu"], default="frd", help="axes of a CSV run's imu.csv"
    )
    r.add_argument(
        "--nhc",
        choices=["on", "off"],
        default=None,
        help="the non-holonomic constraint in every method (default: [nhc] enabled, on); off: IMU-only "
        "bridging of GNSS outages, for comparison",
    )
    r.add_argument(
        "--velocity",
        choices=["on", "off"],
        default=None,
        help="the GNSS (Doppler) velocity updates and factors in every method where the recording "
        "has velocities (default: [velocity] enabled, on); off: positions only, for comparison",
    )
    r.add_argument(
        "--strict",
        action="store_true",
        help="refuse the run instead of applying a correction the estimator proves (a clock "
        "offset, a mounting, a unit), naming the setting that makes the data right: [checks] "
        'on_proof = "refuse"',
    )


def _recording_arguments(r: argparse.ArgumentParser) -> None:
    """``run``'s options of how a recording is read: a GNSS file, bag topics, time stamps."""
    _gnss_argument(r)
    _bag_arguments(r)
    r.add_argument(
        "--time-source",
        choices=["header", "receive"],
        default="header",
        help="bag time stamps: message header (default) or bag receive time",
    )
    r.add_argument(
        "--gnss-from-truth",
        type=float,
        default=None,
        metavar="RATE_HZ",
        help="bag whose only GNSS is an RTK reference: make the estimators' fixes by subsampling it at "
        "RATE_HZ and adding --noise (default white); the reference stays the truth",
    )


def _output_arguments(r: argparse.ArgumentParser) -> None:
    """``run``'s outputs: folder, figures, report, trajectory exports."""
    r.add_argument(
        "--out", default=None, help="output folder (default ./gnssacc-out/<source>-<timestamp>/)"
    )
    r.add_argument(
        "--overwrite",
        action="store_true",
        help="let --out replace a file or a non-empty folder that is not a gnssacc result (and everything "
        "in it); a previous gnssacc result is always replaced as a whole",
    )
    r.add_argument(
        "--plots",
        choices=["all", "basic", "none"],
        default=None,
        help="PNG figures: basic (default: summary, trajectory, errors), all (also velocity/attitude, "
        "NIS, biases, sigmas; the default with --report), none",
    )
    r.add_argument(
        "--no-plots",
        action="store_const",
        const="none",
        dest="plots",
        help="the same as --plots none",
    )
    r.add_argument(
        "--report",
        action="store_true",
        help="also write report.html (table, figures, statistics, consistency, data-quality findings)",
    )
    r.add_argument(
        "--export",
        type=_export_list,
        action="append",
        default=[],
        metavar="tum,bag,ros1bag",
        help="also export trajectories (a comma list, or the option repeated): 'tum' writes "
        "trajectory_<id>.tum and truth.tum for evo (x east, y north, z up); 'bag' a ROS 2 bag "
        "(trajectories/) and 'ros1bag' a ROS 1 bag (trajectories.bag) of nav_msgs/Odometry with "
        "covariance, one topic per method",
    )


def _bench_parser(sub) -> None:
    bch = sub.add_parser(
        "bench",
        help="Monte-Carlo comparison over GNSS noise seeds",
        description="Run every method over noise seeds on one run and print the paper-style "
        "table with mean, spread and a paired significance test of each -acc gain.",
    )
    bch.add_argument(
        "source",
        nargs="?",
        default=None,
        help="'kitti' (default) or a CSV run directory with truth",
    )
    bch.add_argument("--seeds", default="0-9", help="e.g. 0-19 or 1,4,7 (default 0-9)")
    bch.add_argument(
        "--methods", default=None, help="comma-separated method ids (default: all four)"
    )
    bch.add_argument(
        "--noise",
        choices=[p for p in PROFILES if p != "none"],
        default="white",
        help="GNSS noise profile made from the truth (default white)",
    )
    bch.add_argument("--outage", default=None, metavar="START:LEN[,START:LEN...]")
    bch.add_argument("--outage-every", default=None, metavar="PERIOD:LEN")
    bch.add_argument("--config", default=None)
    bch.add_argument("--preset", default=None, choices=PRESETS + ("none",))
    bch.add_argument(
        "--tune",
        choices=["auto", "none"],
        default=None,
        help="noise identification per seed (default auto)",
    )
    bch.add_argument("--imu-frame", choices=["frd", "flu"], default="frd")
    _gnss_argument(bch)
    bch.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="worker processes of a local Dask cluster (default 1: in this process, without Dask)",
    )
    bch.add_argument(
        "--out", default=None, help="also write the per-seed results and the summary as JSON"
    )


def _tool_parsers(sub) -> None:
    """``inspect``, ``config`` and ``sim``."""
    ins = sub.add_parser(
        "inspect", help="list a bag's topics and which ones gnssacc would use, and why"
    )
    ins.add_argument("bag", help="ROS 1 .bag, .mcap, or ROS 2 bag directory")
    _bag_arguments(ins)
    ins.add_argument(
        "--config", default=None, help="configuration TOML (for [bag] fix_mappings of custom types)"
    )

    c = sub.add_parser("config", help="show the resolved run configuration")
    c.add_argument(
        "--show",
        action="store_true",
        help="print the resolved configuration as TOML, each key with its documentation (default)",
    )
    c.add_argument(
        "--template",
        action="store_true",
        help="print a commented starting file: every key documented and commented out",
    )
    c.add_argument("--config", default=None)
    c.add_argument("--preset", default=None, choices=PRESETS)

    s = sub.add_parser("sim", help="write a simulated run (with truth) as a CSV run directory")
    s.add_argument("out", help="output directory")
    s.add_argument("--scenario", default="car", help=f"{', '.join(SCENARIOS)} (default car)")
    s.add_argument("--duration", type=float, default=300.0, help="seconds (default 300)")
    s.add_argument(
        "--grade", default="industrial", help="IMU grade: perfect, consumer, industrial, tactical"
    )
    s.add_argument("--imu-rate", type=float, default=100.0, help="Hz (default 100)")
    s.add_argument("--gnss-rate", type=float, default=1.0, help="Hz (default 1)")
    s.add_argument("--noise", choices=list(PROFILES), default="white")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument(
        "--odom-rate",
        type=float,
        default=None,
        metavar="HZ",
        help="also write wheel odometry at this rate as odom.csv (scale-factor error, noise, slip)",
    )
    s.add_argument(
        "--gnss-format",
        choices=["csv", "pos", "nmea", "ubx"],
        default="csv",
        help="write the fixes as gnss.csv (default), gnss.pos (RTKLIB, GPST), gnss.nmea (NMEA 0183) "
        "or gnss.ubx (u-blox NAV-PVT); the last three hold absolute times, so the run is then "
        "stamped in UNIX seconds from --t-start",
    )
    s.add_argument(
        "--t-start",
        type=float,
        default=None,
        metavar="UNIX_S",
        help="time of the first IMU sample [s] (default 0, or 1709294400 = 2024-03-01 12:00 UTC for "
        "--gnss-format pos, nmea or ubx)",
    )


def _batch_parser(sub) -> None:
    b = sub.add_parser(
        "batch",
        help="a campaign: every method on many recordings, seeds and outage patterns",
        description="Run a campaign: every (recording, seed, outage pattern) is a task that writes "
        "the folder 'gnssacc run' writes, under OUT/<recording>/<seed>/; OUT/summary.csv "
        "and OUT/summary.md are rewritten as results arrive. Runs on a local Dask "
        "cluster (all cores), --jobs N processes, or an existing cluster (--scheduler). "
        "Resumable: 'gnssacc batch --resume OUT' runs what is missing.",
    )
    b.add_argument(
        "sources",
        nargs="*",
        metavar="SOURCE",
        help="'kitti', simulated runs 'sim:SCENARIO[,key=value...]' (e.g. sim:ugv,duration=300), "
        "bags, CSV run directories",
    )
    b.add_argument("--methods", default=None, help="comma-separated method ids (default: all four)")
    b.add_argument("--seeds", default=None, help="GNSS noise seeds, e.g. 0-9 or 1,4,7 (default 0)")
    b.add_argument(
        "--noise",
        choices=list(PROFILES),
        default=None,
        help="GNSS noise made from the truth (as for 'run'); a seed changes nothing without it, "
        "except for KITTI (white by default)",
    )
    b.add_argument(
        "--outage",
        action="append",
        default=None,
        metavar="START:LEN[,START:LEN...]|none",
        help="an outage pattern (repeatable; 'none': no outage); each pattern is a task per seed",
    )
    b.add_argument(
        "--outage-every",
        action="append",
        default=None,
        metavar="PERIOD:LEN",
        help="a periodic outage pattern (repeatable)",
    )
    _batch_run_arguments(b)
    _batch_campaign_arguments(b)


def _batch_run_arguments(b: argparse.ArgumentParser) -> None:
    """``batch``'s per-task options, as for ``run``."""
    b.add_argument("--config", default=None)
    b.add_argument("--preset", default=None, choices=PRESETS + ("none",))
    b.add_argument("--tune", choices=["auto", "none"], default=None)
    b.add_argument("--imu-frame", choices=["frd", "flu"], default=None)
    _gnss_argument(b)
    _bag_arguments(b)
    b.add_argument("--time-source", choices=["header", "receive"], default=None)
    b.add_argument("--gnss-from-truth", type=float, default=None, metavar="RATE_HZ")
    b.add_argument("--no-plots", action="store_true", default=None, help="skip the PNG figures")
    b.add_argument(
        "--report", action="store_true", default=None, help="also write report.html per task"
    )
    b.add_argument(
        "--export",
        type=_export_list,
        action="append",
        default=None,
        metavar="tum,bag,ros1bag",
        help="trajectory exports per task, as for 'run' (a comma list, or repeated)",
    )


def _batch_campaign_arguments(b: argparse.ArgumentParser) -> None:
    """``batch``'s campaign options: folder, resume, workers, cluster."""
    b.add_argument(
        "--out", default=None, help="campaign folder (default ./gnssacc-out/campaign-<timestamp>/)"
    )
    b.add_argument(
        "--resume",
        default=None,
        metavar="CAMPAIGN",
        help="finish a campaign: run the tasks without a result (its settings are stored in it; "
        "options given must agree with them)",
    )
    b.add_argument(
        "--retry-failed", action="store_true", help="with --resume: also run the failed tasks again"
    )
    b.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="local worker processes (default: every core; 1: in this process, without Dask)",
    )
    b.add_argument(
        "--scheduler",
        default=None,
        metavar="tcp://HOST:8786",
        help="run on this Dask cluster (it must see the recordings and the campaign folder)",
    )


EXPORTS = ("tum", "bag", "ros1bag")


def _export_list(text: str) -> list[str]:
    """``--export``'s value: one kind or a comma list of them (argparse's error names a bad one)."""
    kinds = [k.strip() for k in text.split(",") if k.strip()]
    bad = [k for k in kinds if k not in EXPORTS]
    if bad or not kinds:
        raise argparse.ArgumentTypeError(
            f"{', '.join(bad) or repr(text)}: expected {', '.join(EXPORTS)} "
            f"(a comma list, or the option repeated)"
        )
    return kinds


def flat_exports(values) -> list[str]:
    """The kinds of ``--export``'s values (each a list from :func:`_export_list`), once each, in order."""
    return list(dict.fromkeys(k for v in values or () for k in ([v] if isinstance(v, str) else v)))


def _bag_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--imu-topic", default=None, help="bag topic with sensor_msgs/Imu (default: auto-detect)"
    )
    p.add_argument(
        "--gnss-topic", default=None, help="bag topic with the GNSS fixes (default: auto-detect)"
    )
    p.add_argument(
        "--truth-topic",
        default=None,
        help="bag topic with a reference trajectory (default: a geo-referenced topic that agrees with the "
        "fixes; given here it is used, with a warning if it disagrees)",
    )
    p.add_argument(
        "--odom-topic",
        default=None,
        help="bag topic with wheel odometry, nav_msgs/Odometry or geometry_msgs/TwistStamped (default: "
        "the only such topic not taken as the truth)",
    )


def _gnss_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--gnss",
        default=None,
        metavar="FILE",
        help="replace the source's GNSS fixes by a file's: an RTKLIB .pos, an NMEA log (.nmea) or a CSV "
        "with gnss.csv's columns (times on the IMU's clock; absolute .pos/NMEA times need the IMU "
        "stamped in UNIX or GPS seconds)",
    )


def _cmd_inspect(args) -> int:
    from .sources.rosbag import inspect_bag

    path = Path(args.bag)
    if not path.exists():
        raise InputError(args.bag, "no such file or directory")
    cfg = load_config(None, args.config)
    text = inspect_bag(
        path,
        imu_topic=args.imu_topic,
        gnss_topic=args.gnss_topic,
        truth_topic=args.truth_topic,
        odom_topic=args.odom_topic,
        fix_mappings=cfg["bag"]["fix_mappings"],
    )
    listing, _, problem = text.partition("\ngnssacc cannot pick the topics: ")
    print(listing)
    if problem:  # the listing helps choose; the run would be refused: say so and exit 2
        raise InputError(args.bag, f"cannot pick the topics: {problem}")
    return 0


def _cmd_run(args) -> int:
    """``gnssacc run``. The output folder is locked from the start (:mod:`gnssacc.outputs.outdir`); Ctrl-C
    or SIGTERM leave its old or its new complete result, say which, and exit 130 or 143."""
    import contextlib

    from .core.interrupts import signals_raise

    held: list = []  # the locked output folder (a ResultDir), once there is one
    with signals_raise():
        try:
            with contextlib.ExitStack() as stack:
                try:
                    return _run_locked(args, stack, held)
                except Exception as exc:  # a signal inside compiled code may come as another error
                    raise_if_interrupted(exc)
                    raise
        except (KeyboardInterrupt, Terminated) as exc:
            print(
                f"gnssacc: interrupted: {held[0].kept() if held else 'nothing written'}",
                file=sys.stderr,
            )
            return 130 if isinstance(exc, KeyboardInterrupt) else 143


def _lock_out(path, args, stack, held):
    """Lock and check the output folder (refused at once: :class:`InputError`); hold it in ``stack``."""
    from .outputs.outdir import ResultDir

    keep = [args.source] if args.source not in (None, "kitti") else []  # never replace the input
    held.append(stack.enter_context(ResultDir(path, overwrite=args.overwrite, keep_out=keep)))
    return held[-1]


def _run_locked(args, stack, held) -> int:
    """Compute and write; exit code 0 when at least one method succeeded, 1 when none did."""
    from .api import evaluate
    from .core.interrupts import raise_if_arrived
    from .outputs.report import failed_methods
    from .pipeline import default_out_dir, parse_methods
    from .prepare.cache import open_cache

    target = _lock_out(args.out, args, stack, held) if args.out else None
    methods = parse_methods(args.methods)
    cfg = _run_config(args)
    run = _load_run(args, cfg)
    target = target or _lock_out(default_out_dir(run), args, stack, held)
    console = _Console()
    header = (
        f"{run.name}: {run.duration_s:.1f} s, {len(run.imu)} IMU samples, {len(run.gnss)} GNSS fixes"
        + (f", noise {run.meta['noise']} seed {run.meta['seed']}" if "noise" in run.meta else "")
        + f"; config: {', '.join(cfg.sources)}"
    )
    res = evaluate(  # the header is said once the input checks settle, with their corrections
        run,
        cfg,
        methods,
        tune=args.tune,
        show_progress=True,
        observe=args.report,
        say=console.say,
        header=header,
        cache=open_cache(True, retune=args.retune),
    )
    raise_if_arrived()  # a signal that compiled code swallowed interrupts all the same
    if not res.solutions:  # nothing to show or write
        reasons = "; ".join(f"{m}: {r}" for m, r in failed_methods(res.metrics).items())
        print(f"gnssacc: error: every method failed ({reasons}); {target.kept()}", file=sys.stderr)
        return 1
    console.show(
        _print_summary, res.metrics, res.prepared.cfg
    )  # the table first; then the files and figures
    out = res.write(
        target, plots=args.plots or True, report=args.report, export=flat_exports(args.export)
    )
    raise_if_arrived()
    console.say(
        f"results: {out}" + (" (replaced the earlier result there)" if target.had_result else "")
    )
    return console.gone


def _run_config(args):
    """The configuration of ``run``: ``--config``/``--preset`` with the switches ``--nhc``,
    ``--velocity`` and ``--strict`` over them."""
    from .api import configure

    cfg = configure(args.source, preset=args.preset, config=args.config)
    if args.nhc is not None:
        cfg = cfg.with_values({"nhc": {"enabled": args.nhc == "on"}}, f"--nhc {args.nhc}")
    if args.velocity is not None:
        cfg = cfg.with_values(
            {"velocity": {"enabled": args.velocity == "on"}}, f"--velocity {args.velocity}"
        )
    if args.strict:
        cfg = cfg.with_values({"checks": {"on_proof": "refuse"}}, "--strict")
    return cfg


def _load_run(args, cfg):
    """The recording ``run`` names, loaded with ``cfg`` and its source options."""
    from .api import load

    return load(
        args.source,
        config=cfg,
        noise=args.noise,
        seed=args.seed,
        outage=args.outage,
        outage_every=args.outage_every,
        imu_frame=args.imu_frame,
        gnss=args.gnss,
        imu_topic=args.imu_topic,
        gnss_topic=args.gnss_topic,
        truth_topic=args.truth_topic,
        time_source=args.time_source,
        gnss_from_truth_hz=args.gnss_from_truth,
        odom_topic=args.odom_topic,
    )


class _Console:
    """The run's lines on stdout, each printed at once (results as they come). A reader that went
    away (``| head``) ends the printing, not the run: its results are still written, and
    :attr:`gone` is the exit code to report then (141, as a shell reports SIGPIPE; else 0)."""

    def __init__(self):
        self.gone = 0

    def show(self, printer, *args) -> None:
        """``printer(*args)``, which prints, unless the reader went away (before or now)."""
        if self.gone:
            return
        try:
            printer(*args)
            sys.stdout.flush()
        except BrokenPipeError:
            self.gone = _stdout_gone()

    def say(self, line: str) -> None:
        """One line."""
        self.show(print, line)


def _print_summary(metrics: dict, cfg) -> None:
    """The ground-vehicle aids' line (``cfg``: the tuned configuration), the table, and the
    compile time when something was compiled (before the files are written: where they went is
    printed after them)."""
    from .estimators.kernels import start_background
    from .outputs.aids import aids_line
    from .outputs.report import format_table

    print(aids_line(metrics, cfg))
    print()
    print(format_table(metrics))
    if start_background(
        notice=None
    ).compiling:  # a first run: the kernels were compiled, not loaded
        print(
            f"\n(one-off JIT compilation {metrics['jit_compile_s']:.2f} s, not included in wall times)"
        )


def _cmd_bench(args) -> int:
    """``gnssacc bench``: a one-source campaign (:func:`gnssacc.campaign.batch.bench`) and its table."""
    import json

    from .analysis.montecarlo import format_summary, summarise
    from .argcheck import seeds as parse_seeds
    from .campaign.batch import bench
    from .pipeline import parse_methods, resolve_preset

    methods = parse_methods(args.methods)
    seeds = parse_seeds(args.seeds)
    load_config(
        resolve_preset(args.preset, args.source), args.config
    )  # fail early on a bad configuration
    results = bench(
        args.source,
        methods,
        seeds,
        noise=args.noise,
        outage=args.outage,
        outage_every=args.outage_every,
        preset=args.preset,
        config=args.config,
        tune=args.tune,
        imu_frame=args.imu_frame,
        jobs=max(args.jobs, 1),
        gnss=args.gnss,
    )
    table = summarise(results)
    title = f"{args.source or 'kitti'}: {len(results)} seeds, noise {args.noise}" + (
        f", outages {args.outage or ''}{args.outage_every or ''}"
        if args.outage or args.outage_every
        else ""
    )
    print(format_summary(table, title))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(
            json.dumps(
                {"summary": table, "per_seed": {str(k): v for k, v in results.items()}}, indent=2
            )
            + "\n"
        )
    return 0


def _cmd_batch(args) -> int:
    """``gnssacc batch``: exit 0 when every task succeeded, 1 when some failed (all recorded),
    130/143 when interrupted (the finished tasks stay; ``--resume`` runs the rest)."""
    from .campaign.batch import open_executor, run_campaign
    from .campaign_args import campaign_from_args
    from .core.interrupts import signals_raise

    camp = campaign_from_args(args)
    executor = open_executor(args.jobs, args.scheduler)
    with signals_raise():
        try:
            with camp:
                print(
                    f"campaign: {camp.root} ({len(camp.tasks())} tasks, settings hash {camp.hash})",
                    flush=True,
                )
                ledger = run_campaign(camp, executor, retry_failed=args.retry_failed)
        except (KeyboardInterrupt, Terminated) as exc:
            print(
                f"gnssacc: interrupted: the finished tasks are kept in {camp.root}; "
                f"finish with: gnssacc batch --resume {camp.root}",
                file=sys.stderr,
            )
            return 130 if isinstance(exc, KeyboardInterrupt) else 143
    print(ledger.markdown().replace("```\n", "").replace("```", ""))
    failed = ledger.count("failed")
    print(
        f"results: {camp.root}/summary.csv, summary.md ({ledger.count('ok')} ok, {failed} failed)"
    )
    return 1 if failed else 0


def _cmd_config(args) -> int:
    from .core.config_docs import resolved_toml, template_toml

    cfg = load_config(args.preset, args.config)
    if args.template:
        print(template_toml(cfg), end="")
    else:
        print(resolved_toml(cfg), end="")
    return 0


def _cmd_sim(args) -> int:
    from .sources.csvdir import write_csv_run
    from .sources.sim import dense_truth_rate, simulate

    t_start = (
        args.t_start
        if args.t_start is not None
        else (0.0 if args.gnss_format == "csv" else SIM_UNIX_START_S)
    )
    run = simulate(
        scenario=args.scenario,
        duration_s=args.duration,
        imu_grade=args.grade,
        imu_rate_hz=args.imu_rate,
        gnss_rate_hz=args.gnss_rate,
        noise=args.noise,
        seed=args.seed,
        t_start_s=t_start,
        odom_hz=args.odom_rate,
        velocity=True,  # the receiver's Doppler velocities, written where the format has them
        truth_rate_hz=dense_truth_rate(args.imu_rate),  # never interpolated across a turn
    )
    path = write_csv_run(run, args.out, gnss_format=args.gnss_format)
    extra = f", {len(run.odometry)} odometry samples" if run.odometry is not None else ""
    print(
        f"wrote {path}: {run.duration_s:.0f} s {args.scenario}, {len(run.imu)} IMU samples, {len(run.gnss)} fixes "
        f"(gnss.{args.gnss_format}){extra}"
    )
    return 0


#: First IMU sample of ``gnssacc sim`` when it writes absolute fix times: 2024-03-01 12:00:00 UTC [s].
SIM_UNIX_START_S = 1709294400.0


def _show_warning(message, category, filename, lineno, file=None, line=None):
    if issubclass(category, DataWarning):
        print(f"gnssacc: warning: {message}", file=sys.stderr)
    else:
        print(
            warnings.formatwarning(message, category, filename, lineno, line),
            file=sys.stderr,
            end="",
        )


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code.

    Bad input (:class:`InputError`, or an operating-system error on a named file) is one line
    ``gnssacc: error: <where>: <problem>`` and exit code 2; anything else unexpected is a bug:
    one line ``gnssacc: internal error: ...`` naming a crash file with the traceback, exit code 1.
    """
    from .argcheck import check_args

    args = _parser().parse_args(argv)
    warnings.showwarning = _show_warning
    if args.command == "run" or (args.command == "bench" and args.jobs <= 1):
        from .estimators.kernels import start_background

        # At once: the kernels the methods need compile (first run, with a one-line notice) or
        # load in the background while the arguments are checked, the modules imported and the
        # data loaded (unknown method ids are refused later, with the other arguments).
        start_background(args.methods.split(",") if args.methods else None)
    try:
        check_args(args)  # every argument's syntax and range, before anything is loaded
        commands = {
            "run": _cmd_run,
            "inspect": _cmd_inspect,
            "config": _cmd_config,
            "sim": _cmd_sim,
            "bench": _cmd_bench,
            "batch": _cmd_batch,
        }
        return commands[args.command](args)
    except InputError as exc:
        print(f"gnssacc: error: {exc.where}: {exc.problem}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gnssacc: interrupted; no results written", file=sys.stderr)
        return 130
    except Terminated:  # a command without its own handling, or a SIGTERM as a block of it ends
        print("gnssacc: terminated", file=sys.stderr)
        return 143
    except BrokenPipeError:  # the reader of stdout went away (``| head``): not a bug
        return _stdout_gone()
    except OSError as exc:
        if exc.filename is None:
            return _internal_error(exc, argv)
        print(f"gnssacc: error: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug: one line for the user, the traceback in a file for us
        return _internal_error(exc, argv)


def entry() -> None:
    """The ``gnssacc`` command: :func:`main`, then, after ``run``, exit at once. The results are
    written and the output flushed by then; what is skipped is the interpreter's teardown of
    gtsam's, numba's and matplotlib's objects (tenths of a second the user would wait for nothing).
    Other commands exit as usual (``batch`` closes a cluster through its exit handlers)."""
    code = main()
    if sys.argv[1:2] == ["run"]:
        import os

        from .estimators.kernels import stop_background

        stop_background()  # compiling children of a first run that ended early (bad input)
        _end_workers()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (BrokenPipeError, ValueError):  # the reader went away; a closed stream
                pass
        os._exit(code)
    sys.exit(code)


def _end_workers() -> None:
    """End the worker processes still alive (the ones a signal cut off from their pool while it
    was being shut down). A worker forked from this process holds its stdout and stderr and both
    ends of its task queue, so it would wait for tasks for ever after ``os._exit``, and whoever
    reads the command's output would wait with it."""
    multiprocessing = sys.modules.get("multiprocessing")
    if multiprocessing is not None:
        for child in multiprocessing.active_children():
            child.terminate()


def _stdout_gone() -> int:
    """Point stdout at the null device, so that the interpreter's last flush does not fail again;
    return 141 (128 + SIGPIPE, as a shell reports a writer its reader left). Results already
    written stay; ``gnssacc run``, which prints its table before it writes, still writes them."""
    import os

    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 141


def _internal_error(exc: Exception, argv: list[str] | None) -> int:
    """Print one line for an unexpected exception, write its traceback to a crash file; return 1."""
    import platform
    import shlex
    import tempfile
    import traceback
    from datetime import datetime

    words = sys.argv[1:] if argv is None else [str(a) for a in argv]
    text = (
        f"gnssacc {__version__}, Python {platform.python_version()}, {platform.platform()}\n"
        f"command: gnssacc {shlex.join(words)}\n\n" + "".join(traceback.format_exception(exc))
    )
    try:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        fd, path = tempfile.mkstemp(prefix=f"gnssacc-crash-{stamp}-", suffix=".txt")
        with open(fd, "w") as fh:
            fh.write(text)
        details = f"details written to {path}"
    except OSError as err:
        details = f"could not write the details: {err}"
    message = " ".join(str(exc).split())
    message = message if len(message) <= 300 else message[:297] + "..."
    print(
        f"gnssacc: internal error: {type(exc).__name__}: {message} (a bug; {details})",
        file=sys.stderr,
    )
    return 1


if __name__ == "__main__":
    entry()
