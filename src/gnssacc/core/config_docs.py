"""The documentation of every configuration key, read from the comments above it in
:data:`gnssacc.core.config.DEFAULTS` (its single source), for ``gnssacc config --show`` and
``gnssacc config --template``.

A comment block belongs to the key right below it; keys that follow without a comment of their
own share it (``gyro_bias_instability_deg_h`` and ``accel_bias_instability_mg``).
"""

from __future__ import annotations

import inspect
import io
import re
import tokenize

from . import config
from .stationary_params import StationaryParams

_SECTION = re.compile(r'^ {4}"(\w+)": \{\s*$')  # a section opens its own block
_KEY = re.compile(r'^\s*"(\w+)":')


def key_comments() -> dict[tuple[str, str], list[str]]:
    """``{(section, key): comment lines}`` for the keys that start a comment group; the
    ``[stationary]`` keys from the ``Attributes`` of :class:`gnssacc.prepare.stationary.StationaryParams`."""
    return {**_defaults_comments(), **attribute_docs(StationaryParams, "stationary")}


def attribute_docs(cls, section: str) -> dict[tuple[str, str], list[str]]:
    """The numpydoc ``Attributes`` of ``cls`` as ``{(section, first name): lines}`` (names given
    together, ``a, b : float``, share one entry under the first)."""
    text = inspect.getdoc(cls) or ""
    body = text.split("Attributes\n----------\n", 1)[-1] if "Attributes\n" in text else ""
    out, current = {}, None
    for line in body.splitlines():
        head = re.match(r"^(\w+)(?:, \w+)* : ", line)
        if head:
            current = (section, head.group(1))
            out[current] = []
        elif current and line.startswith("    "):
            out[current].append(line.strip())
        elif line.strip():
            break
    return out


def _defaults_comments() -> dict[tuple[str, str], list[str]]:
    try:
        source = inspect.getsource(config)
    except (OSError, TypeError):  # installed without sources: no documentation to show
        return {}
    block = source[source.index("DEFAULTS: dict") :]
    block = block[: block.index("\n}\n") + 3]
    comments: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(block).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
    out, section, pending = {}, None, []
    for n, line in enumerate(block.splitlines(), start=1):
        if n in comments and line.strip().startswith("#"):
            pending.append(comments[n])
        elif _SECTION.match(line):
            section, pending = _SECTION.match(line).group(1), []
        elif section and _KEY.match(line):
            if pending:
                out[(section, _KEY.match(line).group(1))] = pending
            pending = []
    return out


def commented_toml(
    values: dict, header: list[str], origin: dict | None = None, keys_off: bool = False
) -> str:
    """TOML of ``values`` (section -> key -> value) with each key's documentation above it, and,
    from ``origin`` (``(section, key)`` -> what set it), a note after each value not at its
    default; ``keys_off`` writes every key commented out (a template: only what is uncommented
    applies)."""
    docs = key_comments()
    lines = [f"# {h}" for h in header]
    for section, keys in values.items():
        lines += ["", f"[{section}]"]
        for key, value in keys.items():
            lines += [f"# {c}" if c else "#" for c in docs.get((section, key), [])]
            note = (
                f"   # set by {origin[(section, key)]}"
                if origin and (section, key) in origin
                else ""
            )
            lines.append(f"{'# ' if keys_off else ''}{key} = {config.toml_value(value)}{note}")
    return "\n".join(lines) + "\n"


TEMPLATE_HEADER = [
    "gnssacc configuration (gnssacc run --config THIS_FILE). Every key is shown at its value,",
    "commented out: uncomment and edit only what you mean to set. A key you set is used as it",
    "is; the self-tuning identifies the noise keys you leave commented from the recording.",
    "Units are in the key names (_deg_rth = deg/sqrt(h), _mps_rth = m/s/sqrt(h), _deg_h = deg/h,",
    "_mg = milli-g); vector keys take one number or three (x, y, z body or N, E, D).",
]


def template_toml(cfg: "config.RunConfig") -> str:
    """A commented starting file: every key of ``cfg`` documented and commented out."""
    return commented_toml(
        cfg.values, TEMPLATE_HEADER + [f"values from: {', '.join(cfg.sources)}"], keys_off=True
    )


def resolved_toml(cfg: "config.RunConfig") -> str:
    """The resolved configuration as TOML text (for ``gnssacc config --show`` and outputs): each
    key with its documentation and, when not at its default, what set it."""
    return commented_toml(cfg.values, [f"resolved from: {', '.join(cfg.sources)}"], cfg.origin)
