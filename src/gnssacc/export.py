"""Trajectory export for other tools: TUM format (``evo``'s ``tum`` trajectories).

A TUM file has one line per pose: ``timestamp tx ty tz qx qy qz qw``. gnssacc writes positions
in the run's local NED tangent frame [m] (origin in the file header) and the body-FRD-to-NED
attitude as a unit quaternion, so ``evo_ape tum truth.tum trajectory_ekf.tum`` compares like with
like. ``truth.tum`` (positions only, identity attitude when the truth has none) is written beside
the estimates when the run has truth.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .rotations import dcm_to_quaternion, euler_to_dcm
from .run import RecordedRun
from .solution import NavSolution


def _write(path: Path, t, p_n, rpy, origin_note: str) -> None:
    quats = np.array([dcm_to_quaternion(euler_to_dcm(*a)) for a in rpy]) if len(t) else np.zeros((0, 4))
    header = ("gnssacc TUM trajectory: timestamp[s] x y z [m, local NED tangent frame] qx qy qz qw "
              f"[body FRD -> NED]; {origin_note}")
    np.savetxt(path, np.column_stack([t, p_n, quats]), fmt="%.6f", header=header)


def _origin_note(run: RecordedRun) -> str:
    o = run.origin
    return f"origin lat {np.degrees(o.lat0):.9f} deg, lon {np.degrees(o.lon0):.9f} deg, h {o.h0:.3f} m"


def write_tum(sol: NavSolution, run: RecordedRun, path: Path) -> None:
    """Write one solution in TUM format (see module docstring)."""
    _write(Path(path), sol.t, run.origin.to_ned(sol.lat, sol.lon, sol.h), sol.rpy, _origin_note(run))


def write_truth_tum(run: RecordedRun, path: Path) -> None:
    """Write the run's truth in TUM format (identity attitude where the truth has none)."""
    tr = run.truth
    rpy = tr.rpy if tr.rpy is not None else np.zeros((len(tr.t), 3))
    _write(Path(path), tr.t, run.origin.to_ned(tr.lat, tr.lon, tr.h), rpy,
           _origin_note(run) + ("" if tr.rpy is not None else "; truth has no attitude: identity written"))
