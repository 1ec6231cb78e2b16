"""``python -m gnssacc``: the ``gnssacc`` command."""

from .cli import entry

entry()
