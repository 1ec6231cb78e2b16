"""Message streams of a bag being written (:func:`gnssacc.sources.bagwrite.write_bag`): one
generator per topic, each yielding ``(receive time [ns], connection key, serialised message)`` in
time order, so the writer can merge them.

Frames: the run's IMU samples (body FRD) are written FLU ``(x, -y, -z)`` (or FRD, for tests),
after a rotation into the IMU axes when a mounting is given; positions and orientations in ROS's
ENU / FLU (REP-103); fix sigmas as diagonal ENU covariances or hpposllh ``err`` fields [m].
"""

from __future__ import annotations

import numpy as np

from ..core.earth import LocalTangentFrame
from ..core.recording import RecordedRun
from ..core.rotations import ENU_NED, FLU_FRD, R_nb_to_ros, dcm_to_quaternion, euler_to_dcm

LLH_MSG = "float64 lat\nfloat64 lon\nfloat64 height\n"
HPPOSLLH_MSG = "ubxtranslator/llh llh\nubxtranslator/llh err\n"
IMU_TYPE = "sensor_msgs/msg/Imu"
NAVSATFIX_TYPE = "sensor_msgs/msg/NavSatFix"
HPPOSLLH_TYPE = "ubxtranslator/msg/hpposllh"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
IMAGE_TYPE = "sensor_msgs/msg/Image"
TWIST_TYPE = "geometry_msgs/msg/TwistStamped"
TWIST_COV_TYPE = "geometry_msgs/msg/TwistWithCovarianceStamped"
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: Orientation sigmas written with ``with_orientation`` (roll, pitch, yaw) [deg].
ORIENTATION_SIGMA_DEG = (1.0, 1.0, 5.0)


def ns(t: float) -> int:
    """Seconds -> integer nanoseconds (rounded)."""
    return int(round(float(t) * 1e9))


class MessageTypes:
    """Typestore of one ROS version (with the ROOAD ``ubxtranslator`` types) and message constructors.

    Parameters
    ----------
    ros1 : bool
        ROS 1 Noetic (serialised ROS 1 style) or ROS 2 Humble (CDR).
    """

    def __init__(self, ros1: bool):
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        types = get_types_from_msg(LLH_MSG, "ubxtranslator/msg/llh")
        types.update(get_types_from_msg(HPPOSLLH_MSG, HPPOSLLH_TYPE))
        self.ts.register(types)
        self.T = self.ts.types

    def header(self, t: float, frame_id: str):
        """A ``std_msgs/Header`` stamped ``t`` [s]."""
        n = ns(t)
        stamp = self.T["builtin_interfaces/msg/Time"](sec=n // 10**9, nanosec=n % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def serialize(self, msg, typ: str) -> bytes:
        return self.ts.serialize_ros1(msg, typ) if self.ros1 else self.ts.serialize_cdr(msg, typ)

    def vec3(self, v):
        return self.T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def quat(self, q):
        """A ``geometry_msgs/Quaternion`` from ``(x, y, z, w)``."""
        return self.T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])

    def odometry(
        self,
        t: float,
        p_enu,
        R_enu_flu,
        v_flu,
        pose_cov,
        twist_cov,
        frame_id: str = "map",
        w_flu=(0.0, 0.0, 0.0),
    ):
        """A ``nav_msgs/Odometry`` stamped ``t`` [s] in ``frame_id`` (ENU, or a local ``odom``
        frame) of ``base_link`` (FLU): position [m], orientation frame <- FLU, body-axes velocity
        [m/s] and angular rate [rad/s], and the 6x6 pose and twist covariances."""
        T = self.T
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](
                x=float(p_enu[0]), y=float(p_enu[1]), z=float(p_enu[2])
            ),
            orientation=self.quat(dcm_to_quaternion(R_enu_flu)),
        )
        twist = T["geometry_msgs/msg/Twist"](linear=self.vec3(v_flu), angular=self.vec3(w_flu))
        return T[ODOMETRY_TYPE](
            header=self.header(t, frame_id),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=pose, covariance=np.ravel(pose_cov)
            ),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.ravel(twist_cov)
            ),
        )


def imu_axes(imu_mount_rpy_deg) -> np.ndarray:
    """``R_ib`` (body FRD to IMU FRD axes, ``x_imu = R_ib @ x_b``) of a mounting [deg]; identity for None."""
    if imu_mount_rpy_deg is None:
        return np.eye(3)
    return euler_to_dcm(*np.radians(np.asarray(imu_mount_rpy_deg, float))).T


def imu_messages(ty: MessageTypes, run: RecordedRun, opts, key: str = "imu"):
    """``sensor_msgs/Imu`` of every IMU sample, in the IMU axes (``opts.imu_frame``: FLU or FRD).

    ``opts`` (:class:`~gnssacc.sources.bagwrite.BagOptions`) gives the mounting, frame id, time
    offset and receive delay [s], whether to fill the orientation from the truth (the truth epoch
    at or after each sample; else marked absent) and whether to swap a few neighbouring stamps.
    """
    imu = run.imu
    R_ib = imu_axes(opts.imu_mount_rpy_deg)
    C = (FLU_FRD if opts.imu_frame == "flu" else np.eye(3)) @ R_ib
    with np.errstate(invalid="ignore"):  # NaN rows (bad-input tests) stay NaN
        f = imu.f_b @ C.T
        w = imu.omega_ib_b @ C.T
    t = imu.t + opts.time_offset_s
    stamps = t.copy()
    if opts.shuffle_receive:
        for k in range(10, len(t) - 1, max(len(t) // 7, 2)):
            stamps[k], stamps[k + 1] = stamps[k + 1], stamps[k]
    tr = run.truth
    Imu = ty.T[IMU_TYPE]
    zero9 = np.zeros(9)
    noq = np.r_[-1.0, np.zeros(8)]
    R_mag = euler_to_dcm(
        0.0, 0.0, np.radians(opts.orientation_yaw_error_deg)
    )  # heading error, about down
    stated = np.diag(np.radians(opts.orientation_sigma_deg or ORIENTATION_SIGMA_DEG) ** 2).ravel()
    for k in range(len(t)):
        if opts.with_orientation and tr is not None and tr.rpy is not None:
            j = min(int(np.searchsorted(tr.t, imu.t[k])), len(tr.t) - 1)
            R_n_imu = R_mag @ euler_to_dcm(*tr.rpy[j]) @ R_ib.T
            q = ty.quat(dcm_to_quaternion(R_nb_to_ros(R_n_imu)))
            qcov = stated
        else:
            q, qcov = ty.quat((0.0, 0.0, 0.0, 1.0)), noq
        msg = Imu(
            header=ty.header(stamps[k], opts.imu_frame_id),
            orientation=q,
            orientation_covariance=qcov,
            angular_velocity=ty.vec3(w[k]),
            angular_velocity_covariance=zero9,
            linear_acceleration=ty.vec3(f[k]),
            linear_acceleration_covariance=zero9,
        )
        yield ns(t[k] + opts.receive_delay_s), key, ty.serialize(msg, IMU_TYPE)


def _fix_message(
    ty: MessageTypes, typ: str, t: float, lat: float, lon: float, h: float, sig, status: int
):
    T = ty.T
    if typ == NAVSATFIX_TYPE:
        cov = np.zeros(9)
        cov[0], cov[4], cov[8] = sig[1] ** 2, sig[0] ** 2, sig[2] ** 2  # NED sigmas -> ENU diagonal
        return T[typ](
            header=ty.header(t, "gnss"),
            status=T["sensor_msgs/msg/NavSatStatus"](status=int(status), service=1),
            latitude=float(np.degrees(lat)),
            longitude=float(np.degrees(lon)),
            altitude=float(h),
            position_covariance=cov,
            position_covariance_type=2,
        )
    llh = T["ubxtranslator/msg/llh"]
    return T[typ](
        llh=llh(lat=float(np.degrees(lat)), lon=float(np.degrees(lon)), height=float(h)),
        err=llh(lat=float(sig[0]), lon=float(sig[1]), height=float(sig[2])),
    )


def fix_messages(ty: MessageTypes, key: str, typ: str, tt, lat, lon, h, sig, opts, status=0):
    """GNSS fixes as ``NavSatFix`` or ``ubxtranslator/hpposllh`` (``typ``).

    Parameters
    ----------
    tt, lat, lon, h, sig : ndarray
        Times [s], latitude and longitude [rad], ellipsoidal height [m], sigmas N, E, D [m] (K, 3).
    opts : BagOptions
        Time offset and receive delay [s].
    status : int or array of int
        ``NavSatStatus.status`` per fix (NavSatFix only).
    """
    status = np.broadcast_to(np.asarray(status, int), (len(tt),))
    for k in range(len(tt)):
        msg = _fix_message(
            ty, typ, tt[k] + opts.time_offset_s, lat[k], lon[k], h[k], sig[k], status[k]
        )
        yield ns(tt[k] + opts.time_offset_s + opts.receive_delay_s), key, ty.serialize(msg, typ)


def odometry_messages(
    ty: MessageTypes,
    run: RecordedRun,
    origin: LocalTangentFrame,
    opts,
    key: str = "truth",
    frame_id: str = "map",
):
    """The truth as ``nav_msgs/Odometry`` in ``frame_id``: position ENU [m] about ``origin``, orientation
    ENU <- FLU (identity without ``truth.rpy``), twist in body FLU [m/s] (zero without ``truth.v_n``)."""
    tr = run.truth
    p_n = origin.to_ned(tr.lat, tr.lon, tr.h)
    zero = np.zeros(36)
    for k in range(len(tr.t)):
        R = R_nb_to_ros(euler_to_dcm(*tr.rpy[k])) if tr.rpy is not None else np.eye(3)
        v_flu = R.T @ (ENU_NED @ tr.v_n[k]) if tr.v_n is not None else np.zeros(3)
        msg = ty.odometry(
            tr.t[k] + opts.time_offset_s, ENU_NED @ p_n[k], R, v_flu, zero, zero, frame_id
        )
        yield (
            ns(tr.t[k] + opts.time_offset_s + opts.receive_delay_s),
            key,
            ty.serialize(msg, ODOMETRY_TYPE),
        )


def wheel_odometry_messages(ty: MessageTypes, run: RecordedRun, opts, key: str = "odom"):
    """``run.odometry`` as a drive controller publishes it: ``nav_msgs/Odometry`` in the local
    ``odom`` frame (x forward at the start, z up), the pose dead-reckoned from the odometry itself
    (forward speed and yaw rate, flat), the twist in ``base_link`` FLU (``linear.x`` the forward
    speed, ``angular.z = -yaw_rate``) with the stated variances (zero when unknown)."""
    odo = run.odometry
    dt = np.diff(odo.t, prepend=odo.t[0])
    w_up = -(odo.yaw_rate if odo.yaw_rate is not None else np.zeros(len(odo.t)))
    heading = np.cumsum(w_up * dt)  # about z up, from x forward at the start
    x = np.cumsum(odo.v_forward * np.cos(heading) * dt)
    y = np.cumsum(odo.v_forward * np.sin(heading) * dt)
    zero = np.zeros(36)
    for k in range(len(odo.t)):
        c, sn = np.cos(heading[k]), np.sin(heading[k])
        R = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        tw = zero.copy()
        if odo.sigma_v is not None:
            tw[0] = odo.sigma_v[k] ** 2
        if odo.sigma_yaw_rate is not None:
            tw[35] = odo.sigma_yaw_rate[k] ** 2
        msg = ty.odometry(
            odo.t[k] + opts.time_offset_s,
            (x[k], y[k], 0.0),
            R,
            (odo.v_forward[k], 0.0, 0.0),
            zero,
            tw,
            frame_id="odom",
            w_flu=(0.0, 0.0, w_up[k]),
        )
        yield (
            ns(odo.t[k] + opts.time_offset_s + opts.receive_delay_s),
            key,
            ty.serialize(msg, ODOMETRY_TYPE),
        )


def gnss_velocity_messages(
    ty: MessageTypes, run: RecordedRun, opts, typ: str, frame_id: str, key: str = "gnss_vel"
):
    """``run.gnss_vel`` as a ROS GNSS driver publishes it: ``TwistWithCovarianceStamped`` (or
    ``TwistStamped``, ``typ``) in ENU [m/s], stamped with the fixes' epochs, the linear block of
    the covariance ENU [m^2/s^2] (an unmeasured axis: velocity 0, variance -1; the angular block
    -1: not measured)."""
    vel = run.gnss_vel
    T = ty.T
    for k in range(len(vel.t)):
        v_enu = ENU_NED @ np.nan_to_num(vel.v_ned[k])
        twist = T["geometry_msgs/msg/Twist"](linear=ty.vec3(v_enu), angular=ty.vec3((0, 0, 0)))
        t = vel.t[k] + opts.time_offset_s
        if typ == TWIST_TYPE:
            msg = T[typ](header=ty.header(t, frame_id), twist=twist)
        else:
            c = ENU_NED @ vel.cov_ned(k) @ ENU_NED.T
            unmeasured = ~np.isfinite(np.diag(c))
            c = np.nan_to_num(c)
            c[unmeasured, unmeasured] = -1.0
            cov = np.zeros((6, 6))
            cov[:3, :3] = c
            cov[3, 3] = cov[4, 4] = cov[5, 5] = -1.0
            msg = T[typ](
                header=ty.header(t, frame_id),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=twist, covariance=cov.ravel()
                ),
            )
        yield ns(t + opts.receive_delay_s), key, ty.serialize(msg, typ)


def image_messages(ty: MessageTypes, run: RecordedRun, opts, key: str = "image"):
    """Dummy ``sensor_msgs/Image`` of ``opts.extra_image_topic_bytes`` bytes at ``opts.image_rate_hz``
    [Hz] over the run: the "camera" share of a real recording, for reading benchmarks."""
    n = int(opts.extra_image_topic_bytes)
    t = np.arange(run.t_start, run.t_end, 1.0 / opts.image_rate_hz) + opts.time_offset_s
    data = np.zeros(n, np.uint8)
    Img = ty.T[IMAGE_TYPE]
    for k in range(
        len(t)
    ):  # one serialisation (one payload copy) per message: fine for a generator
        msg = Img(
            header=ty.header(t[k], "camera"),
            height=1,
            width=n,
            encoding="mono8",
            is_bigendian=0,
            step=n,
            data=data,
        )
        yield ns(t[k] + opts.receive_delay_s), key, ty.serialize(msg, IMAGE_TYPE)


def tf_static_messages(ty: MessageTypes, run: RecordedRun, opts, key: str = "tf"):
    """One ``/tf_static`` message: ``base_link -> opts.imu_frame_id`` of the mounting (FLU axes)."""
    R_flu = FLU_FRD @ euler_to_dcm(*np.radians(np.asarray(opts.imu_mount_rpy_deg, float))) @ FLU_FRD
    t = run.t_start + opts.time_offset_s
    tf = ty.T["geometry_msgs/msg/TransformStamped"](
        header=ty.header(t, "base_link"),
        child_frame_id=opts.imu_frame_id,
        transform=ty.T["geometry_msgs/msg/Transform"](
            translation=ty.vec3(np.zeros(3)), rotation=ty.quat(dcm_to_quaternion(R_flu))
        ),
    )
    yield ns(t), key, ty.serialize(ty.T[TF_TYPE](transforms=[tf]), TF_TYPE)
