"""gnssacc.core.memo.LastMade: the last value made, given again only for the same objects (by
identity) and key (by equality), without keeping the objects alive."""

import gc
import weakref

import numpy as np

from gnssacc.core.memo import LastMade


def test_given_again_only_for_the_same_objects_and_key():
    memo, a, b = LastMade(), np.arange(3.0), np.arange(3.0)
    assert memo.get((a,), 1) is None
    value = memo.keep((a,), 1, [1, 2])
    assert memo.get((a,), 1) is value
    assert memo.get((b,), 1) is None  # equal content, another object
    assert memo.get((a,), 2) is None  # another key
    assert memo.get((a, b), 1) is None  # other objects besides
    memo.keep((b,), 1, "other")  # one slot: the last one made
    assert memo.get((a,), 1) is None and memo.get((b,), 1) == "other"


def test_objects_are_not_kept_alive_and_unreferenceable_ones_are_not_kept():
    memo = LastMade()
    a = np.arange(3.0)
    memo.keep((a,), 0, "v")
    alive = weakref.ref(a)
    del a
    gc.collect()
    assert alive() is None  # the memo did not keep it
    memo.keep((3.0,), 0, "v")  # a float takes no weak reference
    assert memo.get((3.0,), 0) is None


def test_several_slots_keep_each_objects_value_and_free_the_dead_and_the_least_used():
    memo = LastMade(slots=2)
    a, b, c = np.arange(3.0), np.arange(3.0), np.arange(3.0)
    va, vb = memo.keep((a,), 0, "a"), memo.keep((b,), 0, "b")
    assert memo.get((a,), 0) == va and memo.get((b,), 0) == vb  # b used last
    memo.keep((a,), 1, "a1")  # the same objects, another key: replaces a's slot
    assert memo.get((a,), 0) is None and memo.get((a,), 1) == "a1"
    memo.keep((c,), 0, "c")  # full: b (the least recently used) goes
    assert memo.get((b,), 0) is None and memo.get((a,), 1) == "a1" and memo.get((c,), 0) == "c"
    del a
    gc.collect()
    memo.keep((b,), 0, "b")  # a's slot is free (its object is gone): c stays
    assert memo.get((c,), 0) == "c" and memo.get((b,), 0) == "b"
