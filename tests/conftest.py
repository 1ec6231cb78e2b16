"""Shared test set-up."""

import os

import pytest

# No preparation cache unless a test asks for one (a stored outcome would hide the passes tests
# count); subprocesses inherit it.
os.environ["GNSSACC_CACHE_DIR"] = "none"

import gnssacc.estimators.kernels as kernels


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """Compile (or load) every numba kernel before the first test.

    On a first run (a clean clone, or after a kernel's source changed) the package compiles its
    kernels in the background, and its in-process fallback smooths a short warm-up drive in a
    thread. Tests that patch a method and count its calls would count that drive's calls too.
    """
    kernels.warm_up()
    kernels.smoother_ready()


def pytest_collection_modifyitems(config, items):
    """The tests marked ``slow`` first, each group in its order: on several workers (handed out
    one at a time, pyproject's addopts) the short ones then fill in at the end, instead of one
    slow test running alone while the other workers have finished."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
