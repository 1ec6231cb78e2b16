"""Progress bars: shown on a terminal, silent when stderr is not a TTY (CI, pipes, notebooks)."""
from __future__ import annotations

import sys

from tqdm import tqdm


def progress(iterable, desc: str = "", enable: bool = True, total: int | None = None):
    """Wrap ``iterable`` in a tqdm bar when ``enable`` and stderr is a terminal."""
    show = enable and sys.stderr.isatty()
    return tqdm(iterable, desc=desc, total=total, disable=not show, leave=False, dynamic_ncols=True)
