"""The last values a function made, given again for the same arguments.

The tuner's ~90 EKF passes over one run ask several helpers for the same thing each pass (the
turn rates of the gyros, the inflation segments of the suspect IMU spans). Those helpers keep the
last values they made (one per run a windowed tuning passes over,
:mod:`gnssacc.prepare.tune_windows`), with weak references to the objects each was made from
(recognised by identity, never kept alive by the memo) and a fingerprint of their content and of
the other arguments; a value is given again only while all of these are the same. A value given
again is shared: not to be written to.
"""

from __future__ import annotations

import weakref
from typing import Any


class LastMade:
    """The last ``slots`` values made, each from its ``objects`` (by identity) and ``key`` (by
    equality): a value is given again while its objects live and its key is the same. The
    noise tuner's windows (:mod:`gnssacc.prepare.tune_windows`) pass over a few short runs in
    turn, each of which asks for its own value every pass; one slot would make them afresh each
    time. A slot whose objects are gone is freed first."""

    def __init__(self, slots: int = 1) -> None:
        self.slots = max(1, int(slots))
        self._slots: list[tuple] = []  # (weak refs, key, value), the last used last

    @staticmethod
    def _same(refs: tuple, objects: tuple) -> bool:
        return len(refs) == len(objects) and all(r() is o for r, o in zip(refs, objects))

    def get(self, objects: tuple, key: Any) -> Any:
        """The value kept for these ``objects`` and ``key``, else ``None``."""
        for i, (refs, was, value) in enumerate(self._slots):
            if self._same(refs, objects) and was == key:
                self._slots.append(self._slots.pop(i))
                return value
        return None

    def keep(self, objects: tuple, key: Any, value: Any) -> Any:
        """Keep ``value`` as made from ``objects`` and ``key`` (nothing is kept when an object takes
        no weak reference), in place of the one these objects had, a slot whose objects are gone,
        or the least recently used; returns ``value``."""
        try:
            refs = tuple(weakref.ref(o) for o in objects)
        except TypeError:
            return value
        self._slots = [
            s
            for s in self._slots
            if all(r() is not None for r in s[0]) and not self._same(s[0], objects)
        ]
        drop = max(0, len(self._slots) + 1 - self.slots)  # the least recently used
        self._slots = self._slots[drop:] + [(refs, key, value)]
        return value
