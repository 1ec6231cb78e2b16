"""Trajectory export for other tools: TUM format (``evo``'s ``tum`` trajectories).

A TUM file has one line per pose: ``timestamp tx ty tz qx qy qz qw``. gnssacc writes positions in
the run's local **ENU** tangent frame [m] (x east, y north, z up; origin in the file header), as
``evo`` and ROS users expect and as ``trajectory.png`` draws the track, and the attitude as the unit
quaternion of the rotation from the body **FLU** axes (x forward, y left, z up) to ENU:
``R_enu_flu = C_enu_ned R_nb C_frd_flu``, the same convention as the odometry bag export
(:mod:`gnssacc.outputs.odombag`). ``evo_ape tum truth.tum trajectory_ekf.tum`` then compares like with
like: ``truth.tum`` holds the truth at the estimates' epochs too (:func:`write_truth_tum`), so with
``--align`` off evo's APE statistics are those of the table and ``metrics.json``
(:func:`gnssacc.analysis.errorstats.error_statistics`), to the file's micrometre.

The truth is always ``truth.tum``. A truth with positions only (e.g. an RTK receiver's fixes, the
KITTI sequence) gets placeholder identity quaternions, says ``POSITIONS ONLY`` in its header line, and
is warned about: ``evo_ape ... --pose_relation trans_part`` compares positions correctly, ``evo_rpe``
(relative motion in the reference's body axes) does not.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import warn_data
from ..core.recording import RecordedRun
from ..core.rotations import dcm_to_quaternion, euler_to_dcm
from ..core.solution import NavSolution

#: NED vector -> ENU vector.
C_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: FLU vector -> FRD vector (its own inverse).
C_FRD_FLU = np.diag([1.0, -1.0, -1.0])


def enu_pose(p_n: np.ndarray, rpy: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """ENU positions (K, 3) [m] from NED ones, and the FLU-to-ENU quaternions (K, 4) ``qx qy qz qw``
    from roll, pitch, yaw [rad] of the FRD body in NED (identity quaternions when ``rpy`` is ``None``)."""
    p_enu = np.asarray(p_n, float) @ C_ENU_NED.T
    if rpy is None:
        return p_enu, np.tile([0.0, 0.0, 0.0, 1.0], (len(p_enu), 1))
    quats = [dcm_to_quaternion(C_ENU_NED @ euler_to_dcm(*a) @ C_FRD_FLU) for a in rpy]
    return p_enu, np.array(quats).reshape(-1, 4)


def _write(path: Path, t, p_n, rpy, note: str) -> None:
    p_enu, quats = enu_pose(p_n, rpy)
    header = (
        "gnssacc TUM trajectory: timestamp[s] x y z [m, local ENU tangent frame: x east, y north, z up] "
        f"qx qy qz qw [body FLU -> ENU]; {note}"
    )
    np.savetxt(path, np.column_stack([t, p_enu, quats]), fmt="%.6f", header=header)


def _origin_note(run: RecordedRun) -> str:
    o = run.origin
    return (
        f"origin lat {np.degrees(o.lat0):.9f} deg, lon {np.degrees(o.lon0):.9f} deg, h {o.h0:.3f} m"
    )


def write_tum(sol: NavSolution, run: RecordedRun, path: Path) -> None:
    """Write one solution in TUM format (see module docstring)."""
    _write(
        Path(path), sol.t, run.origin.to_ned(sol.lat, sol.lon, sol.h), sol.rpy, _origin_note(run)
    )


def truth_epochs(run: RecordedRun, sols: dict[str, NavSolution], window=None) -> np.ndarray:
    """The epochs of ``truth.tum`` [s]: the truth's own and every solution's, inside the truth's span
    and the scored ``window`` (once each, to the microsecond the file keeps)."""
    tr = run.truth
    t = np.concatenate([tr.t] + [s.t for s in sols.values()])
    lo, hi = float(tr.t[0]), float(tr.t[-1])
    if window is not None:
        lo, hi = max(lo, window[0]), min(hi, window[1])
    t = t[(t >= lo) & (t <= hi)]
    return np.unique(np.round(t, 6))


def write_truth_tum(
    run: RecordedRun, folder: Path, sols: dict[str, NavSolution] | None = None, window=None
) -> Path:
    """Write the run's truth as ``truth.tum`` in ``folder``; return the file.

    The truth is written at :func:`truth_epochs`: its own epochs and, interpolated linearly as gnssacc
    scores (positions; roll, pitch, yaw unwrapped), at every solution's epochs, inside the scored
    ``window`` [s] when given. ``evo_ape`` matches each estimate to the nearest reference time (within
    0.01 s) without interpolating, so it then scores exactly the epochs and errors of the table's
    PRMSE. A truth with positions only is marked in the header line and warned about (module docstring).
    """
    from ..analysis.metrics import truth_at

    tr = run.truth
    path = Path(folder) / "truth.tum"
    t = truth_epochs(run, sols or {}, window)
    note = _origin_note(run) + (
        "; the truth at its own epochs and, interpolated linearly, at the estimates' "
        "epochs (as gnssacc scores them)"
    )
    if window is not None:
        note += f", over the scored window t = {window[0]:.6f} .. {window[1]:.6f} s"
    rpy = None
    if tr.rpy is None:
        note += "; POSITIONS ONLY: the truth has no attitude, the quaternions are placeholders"
        warn_data(
            "truth.tum",
            "holds positions only (the truth has no attitude; its quaternions are placeholders, "
            "and its header says so): compare positions only (evo_ape ... --pose_relation "
            "trans_part); evo_rpe's figures would be meaningless",
        )
    else:
        unwrapped = np.unwrap(tr.rpy, axis=0)
        rpy = np.column_stack([np.interp(t, tr.t, unwrapped[:, i]) for i in range(3)])
    _write(path, t, truth_at(run, t)[0], rpy, note)
    return path
