"""The last value a function made, given again for the same arguments.

The tuner's ~90 EKF passes over one run ask several helpers for the same thing each pass (the
turn rates of the gyros, the inflation segments of the suspect IMU spans). Those helpers keep the
last value they made, with weak references to the objects it was made from (recognised by
identity, never kept alive by the memo) and a fingerprint of their content and of the other
arguments; a value is given again only while all of these are the same. A value given again is
shared: not to be written to.
"""

from __future__ import annotations

import weakref
from typing import Any


class LastMade:
    """One slot: the last value made from ``objects`` (by identity) and ``key`` (by equality)."""

    def __init__(self) -> None:
        self._slot: tuple | None = None

    def get(self, objects: tuple, key: Any) -> Any:
        """The value kept for these ``objects`` and ``key``, else ``None``."""
        if self._slot is None:
            return None
        refs, was, value = self._slot
        same = len(refs) == len(objects) and all(r() is o for r, o in zip(refs, objects))
        return value if same and was == key else None

    def keep(self, objects: tuple, key: Any, value: Any) -> Any:
        """Keep ``value`` as made from ``objects`` and ``key`` (nothing is kept when an object takes
        no weak reference); returns ``value``."""
        try:
            self._slot = (tuple(weakref.ref(o) for o in objects), key, value)
        except TypeError:
            self._slot = None
        return value
