"""Trajectory export for other tools: TUM format (``evo``'s ``tum`` trajectories).

A TUM file has one line per pose: ``timestamp tx ty tz qx qy qz qw``. gnssacc writes positions
in the run's local NED tangent frame [m] (origin in the file header) and the body-FRD-to-NED
attitude as a unit quaternion, so ``evo_ape tum truth.tum trajectory_ekf.tum`` compares like with
like. ``truth.tum`` is written beside the estimates when the run has truth with attitude, and
``truth_positions.tum`` (with a warning) when its truth has positions only.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import warn_data
from ..core.recording import RecordedRun
from ..core.rotations import dcm_to_quaternion, euler_to_dcm
from ..core.solution import NavSolution


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


def write_truth_tum(run: RecordedRun, folder: Path) -> Path:
    """Write the run's truth in TUM format into ``folder``; return the file.

    With attitude: ``truth.tum``. Without (positions only, e.g. fixes of an RTK receiver):
    ``truth_positions.tum``, whose quaternions are the identity and say nothing, with a warning:
    ``evo_ape`` with ``--pose_relation trans_part`` compares positions correctly, while
    ``evo_rpe`` (which expresses relative motion in the reference's body axes) does not.
    """
    tr = run.truth
    if tr.rpy is not None:
        path = Path(folder) / "truth.tum"
        _write(path, tr.t, run.origin.to_ned(tr.lat, tr.lon, tr.h), tr.rpy, _origin_note(run))
        return path
    path = Path(folder) / "truth_positions.tum"
    _write(path, tr.t, run.origin.to_ned(tr.lat, tr.lon, tr.h), np.zeros((len(tr.t), 3)),
           _origin_note(run) + "; POSITIONS ONLY: the truth has no attitude, the quaternions are placeholders")
    warn_data(f"{run.where} (truth)", "has no attitude: truth_positions.tum carries placeholder quaternions; compare "
                                      "positions only (evo_ape ... --pose_relation trans_part); evo_rpe's figures "
                                      "would be meaningless")
    return path
