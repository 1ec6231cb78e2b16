"""The wheel holds every package of the source tree.

A subpackage missing from ``[tool.setuptools] packages`` imports in an editable install but not
from the wheel that ``pip install .`` (the README's command, CI's) builds; this test reads the
list and the tree and fails on the difference.
"""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _source_packages():
    src = ROOT / "src"
    names = {".".join(p.parent.relative_to(src).parts) for p in src.rglob("__init__.py")}
    names.add("gnssacc.factors")
    return names


def test_every_source_package_is_listed_for_the_wheel():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(config["tool"]["setuptools"]["packages"])
    assert _source_packages() - listed == set(), "add these to pyproject's packages"
    assert listed - _source_packages() == set(), "listed packages with no folder"
