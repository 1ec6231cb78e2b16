"""Build step: compile gnssacc's numba kernels into the wheel, so that the first run after
``pip install`` loads them instead of compiling them (the metadata is in ``pyproject.toml``).

After setuptools' ``build_py`` has copied the package into the build folder, the kernels are
compiled there, in two processes (the EKF's propagation, the biggest, and the rest), by the build
environment's numba (``[build-system] requires``) with numba's own on-disk cache: its index and
object files land in ``gnssacc/estimators/__pycache__`` (and ``estimators/aids/``'s, the aids'
compiled models) and go into the wheel with the sources
(``pip uninstall`` removes them too). numba validates them when it loads them, as it validates
any cache: the numba version, the Python version, this CPU's model and features, and the
source's content (numba 0.68's content stamps make the cache valid wherever the package is
installed); when any differs (a wheel built on another machine, another numba installed at run
time) numba ignores them and the first run compiles, with its notice. Nothing here can fail the
build: without numba 0.68, with ``GNSSACC_BUILD_KERNELS=0`` (e.g. when building a wheel to
distribute), or for an editable install it only skips the step.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

#: First numba whose cache stamps are the sources' content (before: modification times, which an
#: install does not keep).
NUMBA_CONTENT_STAMPS = (0, 68)


def _numba_version() -> tuple[int, ...] | None:
    try:
        from importlib.metadata import version

        return tuple(int(p) for p in version("numba").split(".")[:2])
    except Exception:  # not installed, or a version string of another form
        return None


class BuildPyWithKernels(build_py):
    """``build_py``, then the numba kernels compiled into the build folder's package."""

    def run(self) -> None:
        super().run()
        kernels = Path(self.build_lib) / "gnssacc" / "estimators"
        for cache in (kernels / "__pycache__", kernels / "aids" / "__pycache__"):
            for old in [
                *cache.glob("*.nbi"),
                *cache.glob("*.nbc"),
                *cache.glob("*.sha1"),
            ]:  # a previous build's
                old.unlink()
        if (
            getattr(self, "editable_mode", False)
            or os.environ.get("GNSSACC_BUILD_KERNELS", "1") == "0"
        ):
            return
        found = _numba_version()
        if found is None or found < NUMBA_CONTENT_STAMPS:
            self.announce(
                "gnssacc: numba >= 0.68 not in the build environment: the first run compiles the "
                "kernels",
                level=3,
            )
            return
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # the in-tree cache
        # The build folder first; pip's isolated build environment may itself be on PYTHONPATH.
        env["PYTHONPATH"] = os.pathsep.join(
            filter(None, [os.path.abspath(self.build_lib), env.get("PYTHONPATH")])
        )
        code = "from gnssacc.estimators.kernels import compile_groups; compile_groups({})"
        procs = [
            subprocess.Popen(
                [sys.executable, "-c", code.format(groups)], env=env, cwd=self.build_lib
            )
            for groups in (["propagation"], ["update", "loop", "window", "chain", "band"])
        ]
        if any(p.wait() != 0 for p in procs):
            self.announce(
                "gnssacc: compiling the numba kernels failed: the first run compiles them", level=3
            )


setup(cmdclass={"build_py": BuildPyWithKernels})
