"""Every example in the README and docs/ that a user might copy: each TOML block loads as a
configuration, each Python block runs, each ``gnssacc`` command is accepted by the command line,
and the commands that need none of the user's own files (and take under a minute) run.

Commands on the user's own files (``run.bag``, ``runs/*.bag``, a Dask cluster) are checked by
the argument parser only: the recipes' options must exist and parse. Examples that take longer
than a minute belong to bench/ and are listed in :data:`BENCH` with the bench that runs them."""

import os
import re
import shlex
from pathlib import Path

import pytest

from gnssacc.cli import _parser, main
from gnssacc.core.config import load_config

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
#: Documented commands that run longer than a minute: the bench that runs them instead.
BENCH = {}
#: Inline code that names a command's option in a sentence, not a command to copy.
FRAGMENTS = {"gnssacc batch --resume"}


def _blocks(lang: str) -> list[tuple[str, str]]:
    """``(where, text)`` of every fenced block of language ``lang`` ("" for untagged blocks)."""
    out = []
    for path in DOCS:
        text = path.read_text()
        for m in FENCE.finditer(text):
            if m.group(1) == lang:
                line = text[: m.start()].count("\n") + 1
                out.append((f"{path.relative_to(ROOT)}:{line}", m.group(2)))
    return out


def _commands() -> list[tuple[str, str]]:
    """``(where, command)`` of every complete ``gnssacc`` command in a bash or untagged block,
    or in inline code with arguments (a bare ``gnssacc run`` in a sentence names the command):
    synopses (``[--opt ...]``, ``a|b`` choices, ``...``, ``BAG``) are not commands."""
    found = []
    for lang in ("bash", ""):
        for where, text in _blocks(lang):
            for line in text.splitlines():
                for part in line.split("#")[0].split("&&"):
                    found.append((where, part.strip()))
    for path in DOCS:
        for m in re.finditer(r"`(gnssacc [^`]+)`", path.read_text()):
            command = " ".join(m.group(1).split())
            if len(command.split()) > 2:
                found.append((str(path.relative_to(ROOT)), command))
    seen = {}
    for where, command in found:
        if command.startswith("gnssacc ") and not re.search(
            r"[\[|]|\.\.\.|(^|\s)[A-Z_]{3,}(\s|$)", command
        ):
            if command not in FRAGMENTS:
                seen.setdefault(command, where)
    return sorted((w, c) for c, w in seen.items())


def _needs_no_user_file(command: str) -> bool:
    """A ``gnssacc run`` of the embedded KITTI or a ``sim:`` source, ``gnssacc config``,
    ``gnssacc sim``."""
    argv = shlex.split(command.split(">")[0])[1:]
    if argv[0] in ("config", "sim"):
        return True
    source = next((a for a in argv[1:] if not a.startswith("-")), None)
    return argv[0] == "run" and (source is None or source == "kitti" or source.startswith("sim:"))


COMMANDS = _commands()


def test_the_docs_have_examples():
    assert len(_blocks("toml")) >= 2 and len(_blocks("python")) >= 2 and len(COMMANDS) >= 10


@pytest.mark.parametrize("where, text", _blocks("toml"), ids=lambda x: str(x)[:40])
def test_every_toml_example_loads_as_a_configuration(where, text, tmp_path):
    path = tmp_path / "example.toml"
    path.write_text(text)
    load_config(None, path)  # raises InputError naming the problem


@pytest.mark.parametrize("where, command", COMMANDS, ids=lambda x: str(x)[:60])
def test_every_documented_command_parses(where, command):
    argv = shlex.split(command.split(">")[0])[1:]
    _parser().parse_args(argv)  # SystemExit(2) on an option that does not exist


def _runnable() -> list[tuple[str, str]]:
    return [(w, c) for w, c in COMMANDS if _needs_no_user_file(c) and c not in BENCH]


@pytest.mark.slow
@pytest.mark.parametrize("where, command", _runnable(), ids=lambda x: str(x)[:60])
def test_documented_commands_that_need_no_user_files_run(where, command, tmp_path, capsys):
    os.chdir(tmp_path)
    head, _, redirect = command.partition(">")
    argv = shlex.split(head)[1:]
    if argv[0] == "run" and "--out" not in argv:
        argv += ["--out", str(tmp_path / "out"), "--no-plots"]
    if argv[0] == "sim":
        argv = [a if a != "OUT_DIR" else str(tmp_path / "sim") for a in argv]
    code = main(argv)
    out = capsys.readouterr()
    assert code == 0, out.err
    if redirect.strip():  # e.g. "gnssacc config --template > my.toml": the file it makes loads
        (tmp_path / redirect.strip()).write_text(out.out)
        load_config(None, tmp_path / redirect.strip())


def _python_blocks() -> list[tuple[str, str]]:
    """Each distinct Python block once (the README repeats the API page's)."""
    seen = {}
    for where, text in _blocks("python"):
        seen.setdefault(text, where)
    return [(w, t) for t, w in seen.items()]


@pytest.mark.slow
@pytest.mark.parametrize("where, text", _python_blocks(), ids=lambda x: str(x)[:40])
def test_every_python_example_runs(where, text, tmp_path):
    """The README's (and the API page's) example, in a folder where its ``run.bag`` exists (a
    simulated drive with its IMU on ``/imu/data``, as the example names it): about 50 s on a
    quiet 2-core machine (KITTI with two methods, a 600 s simulated run with the tuner)."""
    import gnssacc
    from gnssacc.sources.bagwrite import write_bag

    os.chdir(tmp_path)
    sim = gnssacc.simulate("car", 30.0, seed=1)
    write_bag(sim, tmp_path / "run.bag", "ros1-rooad", imu_topic="/imu/data")
    exec(compile(text, where, "exec"), {"__name__": "__example__"})
    assert (tmp_path / "out" / "metrics.json").is_file()
