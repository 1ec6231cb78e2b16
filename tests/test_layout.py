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


# --- The estimators: their loops name no aid, the state is indexed by name, no preparation ---

ESTIMATORS = PACKAGE / "estimators"
#: The estimators' loops and what they run on: they loop over the aids they are handed.
LOOPS = (
    "ekf.py",
    "ekf_record.py",
    "smoother.py",
    "smoother_graph.py",
    "kalman.py",
    "mechanization.py",
    "fixed_lag.py",
    "window_marginals.py",
    "state.py",
)
#: Words that name an aid in an identifier (besides the registered aids' names). Not the IMU's
#: words (``accel`` is the accelerometer's too), nor the stationary spans a pass is given (the
#: recording's, which the stationary aid reads).
AID_WORDS = {
    "gnss", "gps", "fix", "fixes", "acceleration", "accw", "zupt", "zaru", "nhc", "holonomic",
    "odometry", "odo", "wheel",
}  # fmt: skip
#: ... and in a string (a ``stats`` key, a kind): the update kinds too (not ``pos``: also the
#: ``[init]`` position key).
KIND_WORDS = {"acc", "zupt", "zaru", "nhc", "odo"}
#: Literal slices that index no state (expression: why).
NOT_STATES = {
    "FIGURES[:6]": "the first six figure names of the study table",
    "rest_R[:3]": "the attitude held at rest, rows 0-2 of its carrier (mechanization.propagate)",
}
#: Modules that define the layouts (and may index by number).
LAYOUT_MODULES = {ESTIMATORS / "layout.py", PACKAGE / "core" / "states.py"}
#: Stages whose arrays hold states (sources, checks and core index other things by number).
STATE_STAGES = ("estimators", "prepare", "analysis", "outputs", "campaign")
#: Block boundaries of the states, the node and the prior (multiples of three up to 18).
BOUNDARIES = set(range(0, 19, 3))


def _words(name: str) -> set[str]:
    """The lower-case words of an identifier or a string (snake_case, CamelCase, punctuation)."""
    import re

    parts = re.split(r"[^A-Za-z0-9]+|(?<=[a-z0-9])(?=[A-Z])", name)
    return {p.lower() for p in parts if p}


def _aid_vocabulary() -> set[str]:
    """The words of :data:`AID_WORDS` and of the registered aids' names (the position, the
    velocity and the acceleration are states and IMU words too)."""
    from gnssacc.estimators.aids import REGISTRY

    words = set(AID_WORDS)
    for spec in REGISTRY:
        words |= _words(spec.name)
    return words - {"position", "velocity", "accel"}


def _layout_names() -> set[str]:
    """The names the layout modules define (the state's vocabulary: allowed everywhere)."""
    names = set()
    for path in LAYOUT_MODULES:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                for t in targets:
                    for n in ast.walk(t):
                        if isinstance(n, ast.Name):
                            names.add(n.id)
            elif isinstance(node, (ast.ClassDef, ast.FunctionDef)):
                names.add(node.name)
    return names


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the docstring nodes of a module, its classes and functions."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


def aid_names_in(source: str, vocabulary: set[str], allowed: set[str]) -> list[str]:
    """``line: name`` of every identifier, attribute, import or string (not a docstring, not a
    comment) of ``source`` with a word of ``vocabulary``, names in ``allowed`` excepted."""
    tree = ast.parse(source)
    docs = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Name):
            names = [node.id]
        elif isinstance(node, ast.Attribute):
            names = [node.attr]
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)):
            names = [node.name]
        elif isinstance(node, ast.arg):
            names = [node.arg]
        elif isinstance(node, ast.alias):
            names = [node.name, node.asname or ""]
        elif isinstance(node, ast.ImportFrom):
            names = [node.module or ""]
        elif isinstance(node, ast.keyword):
            names = [node.arg or ""]
        elif (
            isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
        ):
            names = [node.value]
        words = vocabulary | (KIND_WORDS if isinstance(node, ast.Constant) else set())
        for name in names:
            if name in allowed:
                continue
            hit = _words(name) & words
            if hit:
                found.append(f"{getattr(node, 'lineno', '?')}: {name!r} ({', '.join(sorted(hit))})")
    return found


def test_the_estimators_loops_name_no_aid():
    vocabulary, allowed = _aid_vocabulary(), _layout_names()
    found = [
        f"estimators/{name}:{hit}"
        for name in LOOPS
        for hit in aid_names_in((ESTIMATORS / name).read_text(), vocabulary, allowed)
    ]
    assert found == []


def literal_state_indices(source: str) -> list[str]:
    """``line: expression`` of every subscript of ``source`` by a literal slice on block
    boundaries (``[6:9]``, ``[:, 12:15]``, ``[:15]``, ``[15:]``): a state, covariance, H or F
    indexed by number instead of by its layout name."""
    tree = ast.parse(source)
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Subscript):
            continue
        parts = node.slice.elts if isinstance(node.slice, ast.Tuple) else [node.slice]
        for part in parts:
            if not isinstance(part, ast.Slice) or part.step is not None:
                continue
            lo, hi = part.lower, part.upper
            if not all(
                b is None or (isinstance(b, ast.Constant) and type(b.value) is int)
                for b in (lo, hi)
            ):
                continue
            a = 0 if lo is None else lo.value
            b = None if hi is None else hi.value
            if (lo, hi) == (None, None) or a not in BOUNDARIES:
                continue
            if (b is None and a >= 15) or (b in BOUNDARIES and b - a in (3, 6, 9, 12, 15)):
                if ast.unparse(node) not in NOT_STATES:
                    found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def _state_modules() -> list[Path]:
    paths = [p for stage in STATE_STAGES for p in (PACKAGE / stage).rglob("*.py")]
    paths += [PACKAGE / n for n in ("pipeline.py", "api.py")] + list(FACTORS.glob("*.py"))
    return [p for p in paths if p not in LAYOUT_MODULES]


def test_states_are_indexed_by_their_layout_names():
    found = [
        f"{p.relative_to(p.parents[1])}:{hit}"
        for p in _state_modules()
        for hit in literal_state_indices(p.read_text())
    ]
    assert found == []


def test_no_estimator_imports_the_preparation():
    modules = _modules()
    found = [
        f"{m} -> {t}"
        for m, p in modules.items()
        if m.startswith(("gnssacc.estimators", "gnssacc.factors"))
        for t, _ in _imports(m, p, modules)
        if t.startswith(("gnssacc.prepare", "gnssacc.pipeline"))
    ]
    assert found == []


def test_the_checks_catch_what_they_are_for():
    """The three checks above on small examples: they fail on what they are meant to catch."""
    vocabulary = _aid_vocabulary()
    assert aid_names_in("def f(s):\n    return s.nhc_epochs\n", vocabulary, set())
    assert aid_names_in("x = stats['n_acc_updates']\n", vocabulary, set())
    assert aid_names_in("from .aids.zupt import EkfZupt\n", vocabulary, set())
    assert not aid_names_in(
        'def f(s):\n    """GNSS and odometry."""\n    return s.P\n', vocabulary, set()
    )
    assert not aid_names_in("x = GNSS_ERROR\n", vocabulary, {"GNSS_ERROR"})
    assert literal_state_indices("H[:, 6:9] = d\n") and literal_state_indices("v = P[:15, :15]\n")
    assert literal_state_indices("g = x[15:]\n")
    assert not literal_state_indices("H[:, ATT] = d\nw = words[1:3]\n")
