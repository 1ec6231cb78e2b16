"""Results as a ROS bag of ``nav_msgs/Odometry``, one topic per method (and the truth), for
Foxglove, RViz or ``evo``'s bag reader (``evo_ape bag2 trajectories /gnssacc/truth/odom
/gnssacc/ekf/odom``).

Frames follow ROS REP-103/105: ``header.frame_id`` ``map`` is ENU about the run's tangent-plane
origin (stated in the bag's ``/gnssacc/origin`` ``sensor_msgs/NavSatFix``), ``child_frame_id``
``base_link`` is the body in FLU axes. The pose covariance (row-major 6x6 over x, y, z and the
rotations about them) holds the solution's 1-sigma on its diagonal: position east, north, up, and
roll, pitch, yaw (the attitude sigmas as Euler angles, as robot_localization reports them). The
twist is the velocity in ``base_link`` axes with its covariance rotated there from the solution's
NED sigmas; angular rates are not estimated (zero, covariance -1 on the diagonal: unknown). A
truth without attitude has the identity orientation with -1 on its rotation diagonal (unknown):
compare positions only (``evo_ape ... --pose_relation trans_part``).
Topic names are ``/gnssacc/<method>/odom`` with ``-`` written ``_`` (ROS names allow no ``-``).
"""

from __future__ import annotations

import heapq
from pathlib import Path

import numpy as np

from ..core.recording import RecordedRun
from ..core.rotations import ENU_NED, R_nb_to_ros, euler_to_dcm
from ..core.solution import NavSolution
from ..core.states import ATT, VEL
from ..sources.bag_streams import ODOMETRY_TYPE, MessageTypes, ns

#: ``--export`` kinds and the file each writes in the result folder.
BAG_EXPORTS = {"bag": "trajectories", "ros1bag": "trajectories.bag"}
ORIGIN_TOPIC = "/gnssacc/origin"


def topic_of(method: str) -> str:
    """The odometry topic of a method (``truth`` for the truth)."""
    return f"/gnssacc/{method.replace('-', '_')}/odom"


#: The linear velocity's block of a ROS twist covariance (linear, then angular).
LINEAR = slice(0, 3)


def _covariances(R_enu_flu: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose and twist covariances (6x6) of one epoch from the solution's 15 sigmas."""
    pose = np.zeros((6, 6))
    pose[[0, 1, 2], [0, 1, 2]] = sigma[[1, 0, 2]] ** 2  # NED -> ENU: east, north, up
    pose[[3, 4, 5], [3, 4, 5]] = sigma[ATT] ** 2  # roll, pitch, yaw
    twist = np.diag([0.0, 0.0, 0.0, -1.0, -1.0, -1.0])
    c_enu = ENU_NED @ np.diag(sigma[VEL] ** 2) @ ENU_NED.T
    twist[LINEAR, LINEAR] = R_enu_flu.T @ c_enu @ R_enu_flu
    return pose, twist


def _stream(m: MessageTypes, key: str, t, p_ned, rpy, v_ned, sigma):
    """(time ns, key, bytes) of one trajectory's messages."""
    for k in range(len(t)):
        R = R_nb_to_ros(euler_to_dcm(*rpy[k])) if rpy is not None else np.eye(3)
        v_flu = R.T @ (ENU_NED @ v_ned[k]) if v_ned is not None else np.zeros(3)
        pose_cov, twist_cov = (
            _covariances(R, sigma[k]) if sigma is not None else (np.zeros((6, 6)), np.zeros((6, 6)))
        )
        if rpy is None:  # a truth without attitude: identity orientation, marked unknown
            pose_cov[[3, 4, 5], [3, 4, 5]] = -1.0
        msg = m.odometry(float(t[k]), ENU_NED @ p_ned[k], R, v_flu, pose_cov, twist_cov)
        yield ns(t[k]), key, m.serialize(msg, ODOMETRY_TYPE)


def _origin_msg(m: MessageTypes, run: RecordedRun):
    o = run.origin
    fix = m.T["sensor_msgs/msg/NavSatFix"](
        header=m.header(run.t_start, "map"),
        status=m.T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
        latitude=float(np.degrees(o.lat0)),
        longitude=float(np.degrees(o.lon0)),
        altitude=float(o.h0),
        position_covariance=np.zeros(9),
        position_covariance_type=0,
    )
    return ns(run.t_start), "origin", m.serialize(fix, "sensor_msgs/msg/NavSatFix")


def write_odometry_bag(sols: dict[str, NavSolution], run: RecordedRun, path: Path) -> Path:
    """Write the solutions (and the truth, when there is one) as odometry topics.

    ``path`` ending in ``.bag``: a ROS 1 bag; otherwise a ROS 2 bag directory (MCAP storage).
    """
    path = Path(path)
    ros1 = path.suffix == ".bag"
    m = MessageTypes(ros1)
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    streams, topics = (
        [iter([_origin_msg(m, run)])],
        {"origin": (ORIGIN_TOPIC, "sensor_msgs/msg/NavSatFix")},
    )
    for mid, sol in sols.items():
        topics[mid] = (topic_of(mid), ODOMETRY_TYPE)
        streams.append(
            _stream(
                m,
                mid,
                sol.t,
                run.origin.to_ned(sol.lat, sol.lon, sol.h),
                sol.rpy,
                sol.v_n,
                sol.sigma,
            )
        )
    if run.truth is not None:
        tr = run.truth
        topics["truth"] = (topic_of("truth"), ODOMETRY_TYPE)
        streams.append(
            _stream(m, "truth", tr.t, run.origin.to_ned(tr.lat, tr.lon, tr.h), tr.rpy, tr.v_n, None)
        )
    with writer:
        conns = {
            key: writer.add_connection(topic, typ, typestore=m.ts)
            for key, (topic, typ) in topics.items()
        }
        for t_ns, key, data in heapq.merge(*streams, key=lambda x: x[0]):
            writer.write(conns[key], t_ns, data)
    return path
