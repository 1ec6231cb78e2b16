"""Up-front checks of the command-line arguments, before anything is loaded or computed.

Every check raises :class:`gnssacc.core.errors.InputError` naming the option (or the path) and the
problem with the range expected, so a bad argument costs the user nothing but one line.
The same parsers serve the Python API (:func:`gnssacc.sources.gnss_noise.parse_outages`,
:func:`gnssacc.analysis.montecarlo.parse_seeds`, :func:`gnssacc.pipeline.parse_methods`).
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

from .core.config_check import MAX_SEED, Bound, number_problem
from .core.errors import InputError
from .sources.simspec import SIM_DURATION_S, SIM_IMU_RATE_HZ, SIM_MAX_GNSS_RATE_HZ, SIM_MAX_SAMPLES

#: Ranges of the numeric options.
SEED = Bound(0, MAX_SEED)
JOBS = Bound(1, 256)
RATE_FROM_TRUTH_HZ = Bound(0.0, 1000.0, lo_open=True)


def check_option(value, flag: str, bound: Bound, integer: bool = False) -> None:
    """Raise :class:`InputError` unless ``value`` is a finite number (whole if ``integer``) in ``bound``."""
    problem = number_problem(value, integer, bound)
    if problem:
        raise InputError(
            flag, f"{problem} (expected {'a whole' if integer else 'a'} number {bound})"
        )


def check_input_file(path: str, flag: str) -> None:
    """Raise :class:`InputError` unless ``path`` is an existing file."""
    p = Path(path)
    if not p.exists():
        raise InputError(flag, f"{path}: no such file")
    if p.is_dir():
        raise InputError(flag, f"{path} is a directory, expected a file")


def check_source(source: str | None) -> None:
    """Raise :class:`InputError` unless ``source`` is omitted, ``"kitti"``, a valid ``sim:`` spec
    (:func:`gnssacc.sources.simspec.parse_sim_spec`) or an existing path."""
    from .sources.simspec import is_sim_spec, parse_sim_spec

    if is_sim_spec(source):
        parse_sim_spec(source)
    elif source not in (None, "kitti") and not os.path.lexists(source):
        raise InputError(source, "no such file or directory")


def check_output(path: str, where: str, folder: bool = True, overwrite: bool = False) -> None:
    """Raise :class:`InputError` unless ``path`` can be written as an output folder (or file).

    A folder output must not be an existing file (unless ``overwrite``), a file output not an
    existing folder, and the nearest existing folder above it must be writable (tried with a
    temporary file: permissions, read-only file systems and special file systems all show).
    """
    p = Path(os.path.abspath(path))
    if p.is_file() and folder and not overwrite:
        raise InputError(
            where, f"{path} exists and is a file, not a folder; choose another output folder"
        )
    if p.is_dir() and not folder:
        raise InputError(where, f"{path} is a folder; give a file name")
    above = p.parent
    while not os.path.lexists(above) and above != above.parent:
        above = above.parent
    if not above.is_dir():
        raise InputError(where, f"cannot create {path}: {above} is a file, not a folder")
    for d in [above, p] if p.is_dir() else [above]:
        if not writable(d):
            raise InputError(
                where, f"cannot write in {d} (no permission, or a read-only file system)"
            )


def writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder`` (one is created and deleted to find out)."""
    if not os.access(folder, os.W_OK | os.X_OK):
        return False
    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".gnssacc-probe-"):
            pass
    except OSError:
        return False
    return True


def seeds(text: str) -> list[int]:
    """``--seeds`` as a list (:func:`gnssacc.analysis.montecarlo.parse_seeds`), or :class:`InputError`."""
    from .analysis.montecarlo import MAX_SEEDS, parse_seeds

    try:
        return parse_seeds(text)
    except ValueError as exc:
        raise InputError(
            "--seeds",
            f"{exc}; expected non-negative whole numbers such as 0-19 or 1,4,7 (at most "
            f"{MAX_SEEDS} seeds)",
        ) from None


def check_args(args) -> None:
    """Check the parsed arguments of any command (see the module docstring)."""
    if getattr(args, "config", None):
        check_input_file(args.config, "--config")
    if getattr(args, "seed", None) is not None:
        check_option(args.seed, "--seed", SEED, integer=True)
    if getattr(args, "gnss", None):
        check_input_file(args.gnss, "--gnss")
    checks = {
        "run": _run,
        "bench": _bench,
        "batch": _batch,
        "sim": _sim,
        "inspect": lambda a: check_source(a.bag),
    }
    checks.get(args.command, lambda a: None)(args)


def _estimation(args) -> None:
    """What ``run`` and ``bench`` share: the source, the methods and the outages."""
    from .pipeline import parse_methods
    from .sources.gnss_noise import parse_outages

    check_source(args.source)
    parse_methods(args.methods)
    parse_outages(args.outage, args.outage_every, None)


def _run(args) -> None:
    _estimation(args)
    if args.gnss_from_truth is not None:
        check_option(args.gnss_from_truth, "--gnss-from-truth", RATE_FROM_TRUTH_HZ)
    where = "--out" if args.out else "output folder (default ./gnssacc-out; choose one with --out)"
    check_output(
        args.out or "gnssacc-out/run",
        where,
        folder=True,
        overwrite=getattr(args, "overwrite", False),
    )


def _bench(args) -> None:
    _estimation(args)
    seeds(args.seeds)
    check_option(args.jobs, "--jobs", JOBS, integer=True)
    if args.out:
        check_output(args.out, "--out", folder=False)


def _batch(args) -> None:
    """``gnssacc batch``: every source, pattern and option, before a campaign folder is touched."""
    from .pipeline import parse_methods
    from .sources.gnss_noise import parse_outages

    if not args.sources and args.resume is None:
        raise InputError(
            "SOURCE",
            "give the recordings to process ('kitti', bags, CSV run directories), or "
            "--resume CAMPAIGN to finish a campaign",
        )
    for flag, bad in (
        ("--out", args.out is not None and args.resume is not None),
        ("--retry-failed", args.retry_failed and args.resume is None),
        ("--jobs", args.jobs is not None and args.scheduler is not None),
    ):
        if bad:
            other = {
                "--out": "with --resume (the campaign's folder is given there)",
                "--retry-failed": "only with --resume CAMPAIGN",
                "--jobs": "not with --scheduler (the cluster has its workers)",
            }
            raise InputError(flag, other[flag])
    for source in args.sources:
        check_source(source)
    if args.methods:
        parse_methods(args.methods)
    for spec in args.outage or []:
        if spec != "none":
            parse_outages(spec, None, None)
    for spec in args.outage_every or []:
        parse_outages(None, spec, None)
    if args.seeds:
        seeds(args.seeds)
    if args.jobs is not None:
        check_option(args.jobs, "--jobs", JOBS, integer=True)
    if args.gnss_from_truth is not None:
        check_option(args.gnss_from_truth, "--gnss-from-truth", RATE_FROM_TRUTH_HZ)
    if args.scheduler is not None and not re.fullmatch(
        r"([a-z0-9]+://)?[^\s/]+:\d+/?", args.scheduler
    ):
        raise InputError(
            "--scheduler", f"{args.scheduler!r} is not a scheduler address such as tcp://host:8786"
        )
    if args.resume is not None and not os.path.isdir(args.resume):
        raise InputError("--resume", f"{args.resume}: no such folder")
    if args.out is not None:
        check_output(args.out, "--out", folder=True)


def _sim(args) -> None:
    from .sources.sim_imu_errors import IMU_GRADES
    from .sources.sim_scenarios import SCENARIOS

    if args.scenario not in SCENARIOS:
        raise InputError(
            "--scenario", f"unknown scenario {args.scenario!r} (known: {', '.join(SCENARIOS)})"
        )
    if args.grade not in IMU_GRADES:
        raise InputError(
            "--grade", f"unknown IMU grade {args.grade!r} (known: {', '.join(IMU_GRADES)})"
        )
    check_option(args.duration, "--duration", SIM_DURATION_S)
    check_option(args.imu_rate, "--imu-rate", SIM_IMU_RATE_HZ)
    check_option(
        args.gnss_rate,
        "--gnss-rate",
        Bound(0.0, min(args.imu_rate, SIM_MAX_GNSS_RATE_HZ), lo_open=True),
    )
    if args.duration * args.gnss_rate < 1.0:
        raise InputError(
            "--duration",
            f"{args.duration:g} s at --gnss-rate {args.gnss_rate:g} Hz gives fewer than two "
            f"GNSS fixes",
        )
    if args.duration * args.imu_rate > SIM_MAX_SAMPLES:
        raise InputError(
            "--duration",
            f"{args.duration:g} s at --imu-rate {args.imu_rate:g} Hz makes "
            f"{args.duration * args.imu_rate:.3g} IMU samples, more than {SIM_MAX_SAMPLES}: "
            f"shorten the run or lower the rate",
        )
    if args.odom_rate is not None:
        check_option(args.odom_rate, "--odom-rate", Bound(0.0, args.imu_rate, lo_open=True))
    if args.t_start is not None:
        check_option(args.t_start, "--t-start", Bound(0.0, 4.1e9))
        if args.gnss_format != "csv" and args.t_start < 1e8:
            raise InputError(
                "--t-start",
                f"{args.t_start:g} s is not a UNIX time: gnss.{args.gnss_format} holds "
                f"absolute times, so the run must start at one (e.g. 1709294400)",
            )
    check_output(args.out, "output folder", folder=True)
