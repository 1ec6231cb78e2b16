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

from .rotations import euler_to_dcm
from .run import RecordedRun
from .solution import NavSolution


def dcm_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(qx, qy, qz, qw)`` of a rotation matrix (Shepperd's method), ``qw >= 0``."""
    R = np.asarray(R, float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


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
