"""Write a :class:`~gnssacc.run.RecordedRun` as a ROS bag, so every bag path can be tested end to
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
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from ..earth import LocalTangentFrame
from ..errors import InputError
from ..rotations import ENU_NED, FLU_FRD, R_nb_to_ros, dcm_to_quaternion, euler_to_dcm
from ..run import RecordedRun

KINDS = ("ros1-rooad", "ros2-sqlite3", "ros2-mcap", "mcap")
LLH_MSG = "float64 lat\nfloat64 lon\nfloat64 height\n"
HPPOSLLH_MSG = "ubxtranslator/llh llh\nubxtranslator/llh err\n"


ned_frd_to_enu_flu = R_nb_to_ros  # name kept for callers of this module


def _ns(t: float) -> int:
    return int(round(float(t) * 1e9))


class _Types:
    """Typestore plus message constructors for one ROS version."""

    def __init__(self, ros1: bool):
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        types = get_types_from_msg(LLH_MSG, "ubxtranslator/msg/llh")
        types.update(get_types_from_msg(HPPOSLLH_MSG, "ubxtranslator/msg/hpposllh"))
        self.ts.register(types)
        self.T = self.ts.types

    def header(self, t, frame_id):
        ns = _ns(t)
        stamp = self.T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def serialize(self, msg, typ) -> bytes:
        return self.ts.serialize_ros1(msg, typ) if self.ros1 else self.ts.serialize_cdr(msg, typ)

    def vec3(self, v):
        return self.T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(self, q):
        return self.T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])


def write_bag(run: RecordedRun, path, kind: str = "ros2-sqlite3", *, imu_topic: str | None = None,
              gnss_topic: str | None = "default", truth_topic: str | None = None, truth_type: str = "fix",
              imu_frame: str = "flu", imu_frame_id: str = "imu_link", with_orientation: bool = False,
              imu_mount_rpy_deg=None, extra_image_topic_bytes: int = 0, image_rate_hz: float = 10.0,
              image_topic: str = "/camera/image_raw", time_offset_s: float = 0.0, receive_delay_s: float = 0.0,
              shuffle_receive: bool = False, fix_status=0) -> Path:
    """Write ``run`` as a bag.

    Parameters
    ----------
    run : RecordedRun
        IMU in body FRD, fixes, optional truth (with ``rpy``/``v_n`` for orientation/odometry).
    path : str or Path
        ``.bag`` file, ROS 2 directory, or ``.mcap`` file; must not exist.
    kind : {"ros1-rooad", "ros2-sqlite3", "ros2-mcap", "mcap"}
    imu_topic : str, optional
        Default ``/vectornav/IMU`` (ROOAD) or ``/imu/data``.
    gnss_topic : str or None
        Default ``/UBX/hpposllh`` (ROOAD, custom type) or ``/gnss/fix`` (NavSatFix); None: no GNSS topic.
    truth_topic : str, optional
        Write the truth on this topic: ``truth_type="fix"`` (hpposllh for ROOAD, NavSatFix
        otherwise) or ``"odometry"`` (``nav_msgs/Odometry`` in ENU about the first fix).
    imu_frame : {"flu", "frd"}
        Axes written on the IMU topic ("frd" is non-standard, for tests only).
    with_orientation : bool
        Fill the Imu orientation from ``run.truth.rpy`` (nearest truth epoch), else mark it
        absent (``orientation_covariance[0] = -1``).
    imu_mount_rpy_deg : (roll, pitch, yaw), optional
        IMU mounting; IMU data written in the IMU axes and a ``/tf_static`` transform added.
    extra_image_topic_bytes : int
        If > 0, add ``sensor_msgs/Image`` messages of this size on ``image_topic`` at ``image_rate_hz``.
    time_offset_s : float
        Added to every stamp (e.g. 1.7e9 for epoch-like times).
    receive_delay_s : float
        Receive time = stamp + this delay.
    shuffle_receive : bool
        Swap the stamps of a few neighbouring IMU messages (out-of-order test data).
    fix_status : int or array of int
        NavSatStatus.status of the GNSS fixes (-1 NO_FIX, 0 FIX, ...); NavSatFix kinds only.
    """
    if kind not in KINDS:
        raise InputError(str(path), f"unknown bag kind {kind!r} (known: {', '.join(KINDS)})")
    path = Path(path)
    if path.exists():
        raise InputError(str(path), "exists already; write_bag does not overwrite")
    ros1 = kind == "ros1-rooad"
    ty = _Types(ros1)
    T = ty.T
    imu_topic = imu_topic or ("/vectornav/IMU" if ros1 else "/imu/data")
    if gnss_topic == "default":
        gnss_topic = "/UBX/hpposllh" if ros1 else "/gnss/fix"
    fix_type = "ubxtranslator/msg/hpposllh" if ros1 else "sensor_msgs/msg/NavSatFix"
    g0 = run.gnss
    origin = LocalTangentFrame(g0.lat[0], g0.lon[0], g0.h[0]) if len(g0) else run.origin

    if ros1:
        from rosbags.rosbag1 import Writer
        writer = Writer(path)
        target = path
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer
        target = path.with_suffix("") if kind == "mcap" else path
        if kind == "mcap" and target.exists():
            raise InputError(str(target), "exists already (scratch directory for the .mcap)")
        plugin = StoragePlugin.SQLITE3 if kind == "ros2-sqlite3" else StoragePlugin.MCAP
        writer = Writer(target, version=9, storage_plugin=plugin)

    # message streams: (receive_ns, connection-key, bytes)
    def imu_msgs():
        imu = run.imu
        R_ib = np.eye(3)
        if imu_mount_rpy_deg is not None:
            R_ib = euler_to_dcm(*np.radians(np.asarray(imu_mount_rpy_deg, float))).T
        C = (FLU_FRD if imu_frame == "flu" else np.eye(3)) @ R_ib
        with np.errstate(invalid="ignore"):       # NaN rows (bad-input tests) stay NaN
            f = imu.f_b @ C.T
            w = imu.omega_ib_b @ C.T
        t = imu.t + time_offset_s
        stamps = t.copy()
        if shuffle_receive:
            for k in range(10, len(t) - 1, max(len(t) // 7, 2)):
                stamps[k], stamps[k + 1] = stamps[k + 1], stamps[k]
        tr = run.truth
        Imu = T["sensor_msgs/msg/Imu"]
        zero9 = np.zeros(9)
        noq = np.r_[-1.0, np.zeros(8)]
        for k in range(len(t)):
            if with_orientation and tr is not None and tr.rpy is not None:
                j = min(int(np.searchsorted(tr.t, imu.t[k])), len(tr.t) - 1)
                R_n_imu = euler_to_dcm(*tr.rpy[j]) @ R_ib.T
                q = ty.quat(dcm_to_quaternion(ned_frd_to_enu_flu(R_n_imu)))
                qcov = np.diag(np.radians([1.0, 1.0, 5.0]) ** 2).ravel()
            else:
                q, qcov = ty.quat((0.0, 0.0, 0.0, 1.0)), noq
            msg = Imu(header=ty.header(stamps[k], imu_frame_id), orientation=q, orientation_covariance=qcov,
                      angular_velocity=ty.vec3(w[k]), angular_velocity_covariance=zero9,
                      linear_acceleration=ty.vec3(f[k]), linear_acceleration_covariance=zero9)
            yield _ns(t[k] + receive_delay_s), "imu", ty.serialize(msg, "sensor_msgs/msg/Imu")

    def fix_msgs(key, tt, lat, lon, h, sig, typ, status_arg=0):
        status = np.broadcast_to(np.asarray(status_arg, int), (len(tt),))
        for k in range(len(tt)):
            if typ == "sensor_msgs/msg/NavSatFix":
                cov = np.zeros(9)
                cov[0], cov[4], cov[8] = sig[k, 1] ** 2, sig[k, 0] ** 2, sig[k, 2] ** 2
                msg = T[typ](header=ty.header(tt[k] + time_offset_s, "gnss"),
                             status=T["sensor_msgs/msg/NavSatStatus"](status=int(status[k]), service=1),
                             latitude=float(np.degrees(lat[k])), longitude=float(np.degrees(lon[k])),
                             altitude=float(h[k]), position_covariance=cov, position_covariance_type=2)
            else:
                llh = T["ubxtranslator/msg/llh"]
                msg = T[typ](llh=llh(lat=float(np.degrees(lat[k])), lon=float(np.degrees(lon[k])), height=float(h[k])),
                             err=llh(lat=float(sig[k, 0]), lon=float(sig[k, 1]), height=float(sig[k, 2])))
            yield _ns(tt[k] + time_offset_s + receive_delay_s), key, ty.serialize(msg, typ)

    def odom_msgs(key):
        tr = run.truth
        Odom = T["nav_msgs/msg/Odometry"]
        p_n = origin.to_ned(tr.lat, tr.lon, tr.h)
        for k in range(len(tr.t)):
            R = ned_frd_to_enu_flu(euler_to_dcm(*tr.rpy[k])) if tr.rpy is not None else np.eye(3)
            v_flu = R.T @ (ENU_NED @ tr.v_n[k]) if tr.v_n is not None else np.zeros(3)
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](
                    x=float(p_n[k, 1]), y=float(p_n[k, 0]), z=float(-p_n[k, 2])), orientation=ty.quat(dcm_to_quaternion(R))),
                covariance=np.zeros(36))
            twist = T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=ty.vec3(v_flu), angular=ty.vec3(np.zeros(3))),
                covariance=np.zeros(36))
            msg = Odom(header=ty.header(tr.t[k] + time_offset_s, "map"), child_frame_id="base_link",
                       pose=pose, twist=twist)
            yield _ns(tr.t[k] + time_offset_s + receive_delay_s), key, ty.serialize(msg, "nav_msgs/msg/Odometry")

    def image_msgs():
        n = int(extra_image_topic_bytes)
        t = np.arange(run.t_start, run.t_end, 1.0 / image_rate_hz) + time_offset_s
        data = np.zeros(n, np.uint8)
        Img = T["sensor_msgs/msg/Image"]
        # Serialize once, then patch nothing: the stamp differs only in the header, so re-serialize
        # a small header-only template and reuse the big payload bytes would be fragile; the cost
        # here is one copy per message, which is fine for a benchmark generator.
        for k in range(len(t)):
            msg = Img(header=ty.header(t[k], "camera"), height=1, width=n, encoding="mono8", is_bigendian=0,
                      step=n, data=data)
            yield _ns(t[k] + receive_delay_s), "image", ty.serialize(msg, "sensor_msgs/msg/Image")

    import heapq
    try:
        writer.open()
        conns = {}

        def add(key, topic, typ):
            conns[key] = writer.add_connection(topic, typ, typestore=ty.ts)
        add("imu", imu_topic, "sensor_msgs/msg/Imu")
        streams = [imu_msgs()]
        if gnss_topic:
            add("gnss", gnss_topic, fix_type)
            streams.append(fix_msgs("gnss", g0.t, g0.lat, g0.lon, g0.h, g0.sigma_ned, fix_type, fix_status))
        if truth_topic:
            tr = run.truth
            if tr is None:
                raise InputError(str(path), "truth_topic given but the run has no truth")
            if truth_type == "odometry":
                add("truth", truth_topic, "nav_msgs/msg/Odometry")
                streams.append(odom_msgs("truth"))
            else:
                add("truth", truth_topic, fix_type)
                sig = np.tile([0.02, 0.02, 0.03], (len(tr.t), 1))
                streams.append(fix_msgs("truth", tr.t, tr.lat, tr.lon, tr.h, sig, fix_type))
        if imu_mount_rpy_deg is not None:
            add("tf", "/tf_static", "tf2_msgs/msg/TFMessage")
            R_flu = FLU_FRD @ euler_to_dcm(*np.radians(np.asarray(imu_mount_rpy_deg, float))) @ FLU_FRD
            q = dcm_to_quaternion(R_flu)
            tf = T["geometry_msgs/msg/TransformStamped"](
                header=ty.header(run.t_start + time_offset_s, "base_link"), child_frame_id=imu_frame_id,
                transform=T["geometry_msgs/msg/Transform"](translation=ty.vec3(np.zeros(3)), rotation=ty.quat(q)))
            msg = T["tf2_msgs/msg/TFMessage"](transforms=[tf])
            streams.append(iter([(_ns(run.t_start + time_offset_s), "tf",
                                  ty.serialize(msg, "tf2_msgs/msg/TFMessage"))]))
        if extra_image_topic_bytes > 0:
            add("image", image_topic, "sensor_msgs/msg/Image")
            streams.append(image_msgs())
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
