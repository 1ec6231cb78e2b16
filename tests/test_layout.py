"""The package's layout is its pipeline: imports point down the stages, never in a circle, and
nothing private crosses a module boundary.

Stages, lowest first (a module may import from its own stage, a lower one, or ``core``):
``core`` < ``sources`` < ``checks`` < ``estimators`` (with ``gnssacc.factors``) < ``prepare``
< ``analysis`` < ``outputs`` < ``pipeline`` (one run, end to end) < ``campaign`` (many runs)
< the public face (``api``, ``cli`` and its argument checks ``argcheck``, ``campaign_args``,
``__main__``, the package ``__init__``). Every import counts, also one made inside a
function: a deferred import is still a dependency.
"""

from __future__ import annotations

import ast
from pathlib import Path

import gnssacc

PACKAGE = Path(gnssacc.__file__).resolve().parent
FACTORS = PACKAGE / "factors" if (PACKAGE / "factors").is_dir() else PACKAGE.parents[1] / "factors"
STAGES = (
    "core",
    "sources",
    "checks",
    "estimators",
    "prepare",
    "analysis",
    "outputs",
    "pipeline",
    "campaign",
)
PACKAGES = tuple(s for s in STAGES if s != "pipeline")
RANK = {name: i for i, name in enumerate(STAGES)} | {"factors": STAGES.index("estimators")}
TOP = len(STAGES)


def _modules() -> dict[str, Path]:
    """``{dotted name: file}`` of every module of the package, ``gnssacc.factors`` included."""
    out = {}
    for root, prefix in ((PACKAGE, "gnssacc"), (FACTORS, "gnssacc.factors")):
        for path in root.rglob("*.py"):
            if prefix == "gnssacc" and path.is_relative_to(PACKAGE / "factors"):
                continue
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([prefix, *parts])] = path
    return out


def _imports(name: str, path: Path, modules: dict) -> list[tuple[str, list[str]]]:
    """``(module imported, [names taken from it])`` for every import in the file."""
    is_pkg = path.name == "__init__.py"
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names if a.name.startswith("gnssacc")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("gnssacc"):
                continue
            for a in node.names:  # `from pkg import module` imports that module
                sub = f"{target}.{a.name}"
                out.append((sub, []) if sub in modules else (target, [a.name]))
    return out


def _rank(module: str) -> int:
    parts = module.split(".")
    return (
        RANK.get(parts[1], TOP) if len(parts) > 2 or (len(parts) == 2 and parts[1] in RANK) else TOP
    )


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {
        m: {t for t, _ in _imports(m, p, modules) if t in modules and t != m}
        for m, p in modules.items()
    }


def test_every_stage_is_a_package_that_says_what_it_is_for():
    for stage in PACKAGES:
        doc = ast.get_docstring(ast.parse((PACKAGE / stage / "__init__.py").read_text())) or ""
        assert "Input" in doc and "Output" in doc, (
            f"gnssacc.{stage}: its docstring must state inputs and outputs"
        )


def test_imports_point_down_the_stages():
    upward = [
        f"{m} -> {t}"
        for m, deps in _graph().items()
        for t in deps
        if _rank(t) > _rank(m) and not (m == "gnssacc" and t == "gnssacc.api")
    ]
    assert upward == []


def test_no_import_circles():
    graph, state, cycles = _graph(), {}, []

    def visit(m, stack):
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycles.append(" -> ".join(stack[stack.index(t) :] + [t]))
            elif t not in state:
                visit(t, stack + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert cycles == []


def test_nothing_private_is_imported_across_modules():
    modules = _modules()
    private = [
        f"{m}: {t}.{n}"
        for m, p in modules.items()
        for t, names in _imports(m, p, modules)
        for n in names
        if n.startswith("_") and not n.startswith("__") and t != m
    ]
    assert private == []
