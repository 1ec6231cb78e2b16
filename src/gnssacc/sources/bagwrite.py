"""Write a :class:`~gnssacc.core.recording.RecordedRun` as a ROS bag, so every bag path can be tested end to
end with known truth (and benchmarked).

Kinds
    ``ros1-rooad``: ROS 1 ``.bag`` in the ROOAD layout: ``/vectornav/IMU`` ``sensor_msgs/Imu`` (FLU)
    and the custom ``ubxtranslator/hpposllh`` on ``/UBX/hpposllh`` (no header: the receive time is
    the fix time), registered from its ``.msg`` text; truth as another hpposllh topic.
    ``ros2-sqlite3``, ``ros2-mcap``: ROS 2 bag directories with ``sensor_msgs/NavSatFix``.
    ``mcap``: a bare ``.mcap`` file (the MCAP storage file of a ROS 2 bag, moved out).

The run's IMU samples (body FRD) are written FLU (``(x, -y, -z)``); with ``imu_mount_rpy_deg``
they are first rotated into the IMU axes (``x_imu = R_bi^T x_b``) and a ``/tf_static``
``base_link -> imu_link`` transform is written. Fix sigmas are written as diagonal ENU
covariances (NavSatFix ``COVARIANCE_TYPE_DIAGONAL_KNOWN``) or as hpposllh ``err`` fields.
The messages of each topic come from :mod:`gnssacc.sources.bag_streams`.
"""

from __future__ import annotations

import heapq
import shutil
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..core.earth import LocalTangentFrame
from ..core.errors import InputError
from ..core.recording import RecordedRun
from ..core.rotations import R_nb_to_ros
from .bag_streams import (
    HPPOSLLH_TYPE,
    IMAGE_TYPE,
    IMU_TYPE,
    NAVSATFIX_TYPE,
    ODOMETRY_TYPE,
    TF_TYPE,
    TWIST_COV_TYPE,
    TWIST_TYPE,
    MessageTypes,
    fix_messages,
    gnss_velocity_messages,
    image_messages,
    imu_messages,
    odometry_messages,
    tf_static_messages,
    wheel_odometry_messages,
)

KINDS = ("ros1-rooad", "ros2-sqlite3", "ros2-mcap", "mcap")
#: Sigmas N, E, D [m] written with a fix-type truth (an RTK receiver's).
TRUTH_FIX_SIGMA_M = (0.02, 0.02, 0.03)

ned_frd_to_enu_flu = R_nb_to_ros  # name kept for callers of this module


@dataclass(frozen=True)
class BagOptions:
    """What :func:`write_bag` writes besides the IMU and the fixes (every field a keyword of it).

    Attributes
    ----------
    imu_topic : str, optional
        Default ``/vectornav/IMU`` (ROOAD) or ``/imu/data``.
    gnss_topic : str or None
        Default ``/UBX/hpposllh`` (ROOAD, custom type) or ``/gnss/fix`` (NavSatFix); None: no GNSS topic.
    truth_topic : str, optional
        Write the truth on this topic: ``truth_type="fix"`` (hpposllh for ROOAD, NavSatFix
        otherwise) or ``"odometry"`` (``nav_msgs/Odometry`` in ENU about the first fix).
    imu_frame : {"flu", "frd"}
        Axes written on the IMU topic ("frd" is non-standard, for tests only).
    imu_frame_id : str
        ``header.frame_id`` of the IMU messages (and the child of the ``/tf_static`` transform).
    with_orientation : bool
        Fill the Imu orientation from ``run.truth.rpy`` (the truth epoch at or after each sample), else mark it
        absent (``orientation_covariance[0] = -1``).
    orientation_yaw_error_deg : float
        Heading error of that orientation [deg], as a magnetometer near a vehicle's steel gives
        it: the orientation is turned by this about the vertical (roll and pitch stay right).
    orientation_sigma_deg : (roll, pitch, yaw), optional
        The 1-sigmas its covariance states [deg] (default
        :data:`gnssacc.sources.bag_streams.ORIENTATION_SIGMA_DEG`), whatever its real error.
    imu_mount_rpy_deg : (roll, pitch, yaw), optional
        IMU mounting [deg]; IMU data written in the IMU axes and a ``/tf_static`` transform added.
    write_tf : bool
        Whether the mounting is also written as ``/tf_static`` (many bags lack it: then only the
        data say how the IMU sits).
    extra_image_topic_bytes : int
        If > 0, add ``sensor_msgs/Image`` messages of this size on ``image_topic`` at ``image_rate_hz`` [Hz].
    time_offset_s : float
        Added to every stamp [s] (e.g. 1.7e9 for epoch-like times).
    receive_delay_s : float
        Receive time = stamp + this delay [s].
    shuffle_receive : bool
        Swap the stamps of a few neighbouring IMU messages (out-of-order test data).
    fix_status : int or array of int
        NavSatStatus.status of the GNSS fixes (-1 NO_FIX, 0 FIX, ...); NavSatFix kinds only.
    truth_frame_id : str
        ``header.frame_id`` of an ``"odometry"`` truth (default ``map``; a test may say ``odom``).
    truth_offset_enu_m : (e, n, u)
        Shift of an ``"odometry"`` truth's positions [m] (a frame whose origin is not the first fix).
    odom_topic : str, optional
        Write ``run.odometry`` on this topic as a drive controller does: ``nav_msgs/Odometry`` in
        the local ``odom`` frame (:func:`gnssacc.sources.bag_streams.wheel_odometry_messages`).
    gnss_vel_topic : str or None
        Where ``run.gnss_vel`` is written when the run has it (default ``/gnss/vel``), in the
        fixes' frame ``gnss``, as a GNSS driver publishes it
        (:func:`gnssacc.sources.bag_streams.gnss_velocity_messages`); None: not written.
    gnss_vel_covariance : bool
        ``TwistWithCovarianceStamped`` with the velocity's covariance (default), else
        ``TwistStamped`` (no covariance).
    """

    imu_topic: str | None = None
    gnss_topic: str | None = "default"
    truth_topic: str | None = None
    truth_type: str = "fix"
    imu_frame: str = "flu"
    imu_frame_id: str = "imu_link"
    with_orientation: bool = False
    orientation_yaw_error_deg: float = 0.0
    orientation_sigma_deg: tuple | None = None
    write_tf: bool = True
    imu_mount_rpy_deg: tuple | None = None
    extra_image_topic_bytes: int = 0
    image_rate_hz: float = 10.0
    image_topic: str = "/camera/image_raw"
    time_offset_s: float = 0.0
    receive_delay_s: float = 0.0
    shuffle_receive: bool = False
    fix_status: object = 0
    truth_frame_id: str = "map"
    truth_offset_enu_m: tuple = (0.0, 0.0, 0.0)
    odom_topic: str | None = None
    gnss_vel_topic: str | None = "default"
    gnss_vel_covariance: bool = True


def write_bag(
    run: RecordedRun, path, kind: str = "ros2-sqlite3", options: BagOptions | None = None, **changes
) -> Path:
    """Write ``run`` as a bag.

    Parameters
    ----------
    run : RecordedRun
        IMU in body FRD, fixes, optional truth (with ``rpy``/``v_n`` for orientation/odometry).
    path : str or Path
        ``.bag`` file, ROS 2 directory, or ``.mcap`` file; must not exist.
    kind : {"ros1-rooad", "ros2-sqlite3", "ros2-mcap", "mcap"}
    options : BagOptions, optional
        Topics, frames, times and extras; default ``BagOptions()``.
    **changes
        Fields of :class:`BagOptions` to change (``write_bag(run, p, imu_mount_rpy_deg=(0, 0, 90))``).

    Returns
    -------
    Path
        ``path``.
    """
    if kind not in KINDS:
        raise InputError(str(path), f"unknown bag kind {kind!r} (known: {', '.join(KINDS)})")
    unknown = set(changes) - {f.name for f in fields(BagOptions)}
    if unknown:
        raise TypeError(
            f"write_bag() got unexpected keyword argument(s) {', '.join(sorted(unknown))}"
        )
    opts = replace(options or BagOptions(), **changes)
    path = Path(path)
    if path.exists():
        raise InputError(str(path), "exists already; write_bag does not overwrite")
    if opts.truth_topic and run.truth is None:
        raise InputError(str(path), "truth_topic given but the run has no truth")
    if opts.odom_topic and run.odometry is None:
        raise InputError(str(path), "odom_topic given but the run has no wheel odometry")
    ty = MessageTypes(kind == "ros1-rooad")
    writer, target = _open_writer(path, kind)
    try:
        writer.open()
        conns, streams = {}, []
        for key, topic, typ, stream in _topics(ty, run, opts):
            conns[key] = writer.add_connection(topic, typ, typestore=ty.ts)
            streams.append(stream)
        for t_ns, key, data in heapq.merge(*streams, key=lambda x: x[0]):
            writer.write(conns[key], t_ns, data)
        writer.close()
    except BaseException:
        try:
            writer.close()
        except Exception:
            pass
        raise
    if kind == "mcap":
        files = list(target.glob("*.mcap"))
        shutil.move(str(files[0]), str(path))
        shutil.rmtree(target)
    return path


def _open_writer(path: Path, kind: str):
    """(rosbags writer, the path it writes): for ``mcap`` a scratch ROS 2 directory beside ``path``."""
    if kind == "ros1-rooad":
        from rosbags.rosbag1 import Writer

        return Writer(path), path
    from rosbags.rosbag2 import StoragePlugin, Writer

    target = path.with_suffix("") if kind == "mcap" else path
    if kind == "mcap" and target.exists():
        raise InputError(str(target), "exists already (scratch directory for the .mcap)")
    plugin = StoragePlugin.SQLITE3 if kind == "ros2-sqlite3" else StoragePlugin.MCAP
    return Writer(target, version=9, storage_plugin=plugin), target


def _topics(ty: MessageTypes, run: RecordedRun, opts: BagOptions):
    """(key, topic, type, message stream) of each topic to write, in connection order."""
    imu_topic = opts.imu_topic or ("/vectornav/IMU" if ty.ros1 else "/imu/data")
    gnss_topic = (
        ("/UBX/hpposllh" if ty.ros1 else "/gnss/fix")
        if opts.gnss_topic == "default"
        else opts.gnss_topic
    )
    fix_type = HPPOSLLH_TYPE if ty.ros1 else NAVSATFIX_TYPE
    g, tr = run.gnss, run.truth
    yield "imu", imu_topic, IMU_TYPE, imu_messages(ty, run, opts)
    if gnss_topic:
        yield (
            "gnss",
            gnss_topic,
            fix_type,
            fix_messages(
                ty, "gnss", fix_type, g.t, g.lat, g.lon, g.h, g.sigma_ned, opts, opts.fix_status
            ),
        )
    if opts.truth_topic and opts.truth_type == "odometry":
        origin = LocalTangentFrame(g.lat[0], g.lon[0], g.h[0]) if len(g) else run.origin
        if np.any(
            opts.truth_offset_enu_m
        ):  # the frame's origin elsewhere: positions shifted by -offset
            e, n, u = opts.truth_offset_enu_m
            origin = LocalTangentFrame(*origin.to_llh(np.array([-n, -e, u], float)))
        yield (
            "truth",
            opts.truth_topic,
            ODOMETRY_TYPE,
            odometry_messages(ty, run, origin, opts, frame_id=opts.truth_frame_id),
        )
    elif opts.truth_topic:
        sig = np.tile(TRUTH_FIX_SIGMA_M, (len(tr.t), 1))
        yield (
            "truth",
            opts.truth_topic,
            fix_type,
            fix_messages(ty, "truth", fix_type, tr.t, tr.lat, tr.lon, tr.h, sig, opts),
        )
    if opts.odom_topic:
        yield "odom", opts.odom_topic, ODOMETRY_TYPE, wheel_odometry_messages(ty, run, opts)
    if run.gnss_vel is not None and gnss_topic and opts.gnss_vel_topic:
        topic = "/gnss/vel" if opts.gnss_vel_topic == "default" else opts.gnss_vel_topic
        typ = TWIST_COV_TYPE if opts.gnss_vel_covariance else TWIST_TYPE
        frame = "gnss"  # the fixes' frame (bag_streams writes NavSatFix in "gnss")
        yield "gnss_vel", topic, typ, gnss_velocity_messages(ty, run, opts, typ, frame)
    if opts.imu_mount_rpy_deg is not None and opts.write_tf:
        yield "tf", "/tf_static", TF_TYPE, tf_static_messages(ty, run, opts)
    if opts.extra_image_topic_bytes > 0:
        yield "image", opts.image_topic, IMAGE_TYPE, image_messages(ty, run, opts)
