"""Decoding of bag messages into rows of numbers: IMU, GNSS fixes (NavSatFix and custom types
through field mappings), pose/odometry truth, and the IMU mounting from ``/tf_static``.

Rows keep the ROS frames and units of the messages (body FLU, local ENU, degrees); the
conversion to gnssacc's frames (FRD, NED, radians) is the loader's
(:mod:`gnssacc.sources.rosbag`), except for pose truth, whose orientation and velocity are
returned in NED/FRD (they need the message's quaternion).

Only the messages of the chosen connections are deserialised (``reader.messages(connections=...)``),
so image and other topics cost no decoding.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass

import numpy as np

from ..core.config_check import FIX_MAPPING_FIELDS
from ..core.errors import InputError
from ..core.rotations import ENU_NED, FLU_FRD, dcm_to_euler, quaternion_to_dcm, ros_to_R_nb
from .common import one_line

IMU_TYPE = "sensor_msgs/msg/Imu"
NAVSATFIX_TYPE = "sensor_msgs/msg/NavSatFix"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TWIST_TYPE = "geometry_msgs/msg/TwistStamped"
TWIST_COV_TYPE = "geometry_msgs/msg/TwistWithCovarianceStamped"
POSE_TYPES = (
    ODOMETRY_TYPE,
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
)
#: Types that may carry wheel odometry (a forward speed and a yaw rate).
ODOM_TYPES = (ODOMETRY_TYPE, TWIST_TYPE)
#: Types that may carry a GNSS receiver's velocity (ENU, as ROS GNSS drivers publish it).
VELOCITY_TYPES = (TWIST_TYPE, TWIST_COV_TYPE)
TF_TYPE = "tf2_msgs/msg/TFMessage"
TIME_SOURCES = ("header", "receive")
BASE_FRAMES = ("base_link", "base_footprint")

#: Field mappings of custom GNSS fix messages, by message type. Keys:
#: ``lat``, ``lon``, ``height``: field paths; ``latlon_scale_deg``: factor to degrees;
#: ``height_scale_m``: factor to metres (ellipsoidal height); ``sigma_n``, ``sigma_e``,
#: ``sigma_d``: field paths of 1-sigma accuracies (or None: ``gnss.default_sigma_m``);
#: ``sigma_scale_m``: factor to metres; ``stamp``: path of a ``builtin_interfaces/Time`` field or
#: None (then the bag receive time is used); ``status`` and ``no_fix_values``: a field whose
#: listed values mark a fix as invalid (skipped), or None.
FIX_MAPPINGS: dict[str, dict] = {
    # ROOAD: ubxtranslator/hpposllh = ubxtranslator/llh llh + ubxtranslator/llh err, no header.
    "ubxtranslator/msg/hpposllh": {
        "lat": "llh.lat",
        "lon": "llh.lon",
        "height": "llh.height",
        "latlon_scale_deg": 1.0,
        "height_scale_m": 1.0,
        "sigma_n": "err.lat",
        "sigma_e": "err.lon",
        "sigma_d": "err.height",
        "sigma_scale_m": 1.0,
        "stamp": None,
        "status": None,
        "no_fix_values": [],
    },
}
_MAPPING_KEYS = set(FIX_MAPPING_FIELDS)
_MAPPING_DEFAULTS = {
    "latlon_scale_deg": 1.0,
    "height_scale_m": 1.0,
    "sigma_n": None,
    "sigma_e": None,
    "sigma_d": None,
    "sigma_scale_m": 1.0,
    "stamp": None,
    "status": None,
    "no_fix_values": [],
}

#: Columns of the rows: IMU ``t, f (3), omega (3), q (x, y, z, w), var(roll, pitch, yaw)``;
#: fix ``t, lat, lon, h, sigma N, E, D``; pose ``t, p N, E, D, v N, E, D, roll, pitch, yaw``;
#: Odometry: the pose's and then the twist's ``v x, y, z (FLU), omega z (FLU), var v x, var omega z``
#: and its linear covariance as given ``xx, yy, zz, xy, xz, yz`` (NaN without one);
#: TwistStamped, TwistWithCovarianceStamped: ``t`` and the twist's columns.
IMU_COLS, FIX_COLS, POSE_COLS = 14, 7, 10
TWIST_COLS = 12
ODOM_COLS = POSE_COLS + TWIST_COLS


def normalize_type(name: str) -> str:
    """``pkg/Type`` -> ``pkg/msg/Type`` (the form rosbags uses for ROS 1 and ROS 2)."""
    parts = str(name).strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


def merge_fix_mappings(user: dict | None) -> dict[str, dict]:
    """The shipped :data:`FIX_MAPPINGS` merged with the user's ``[bag] fix_mappings``.

    Parameters
    ----------
    user : dict or None
        Message type (``pkg/Type`` or ``pkg/msg/Type``) -> mapping; keys as in :data:`FIX_MAPPINGS`.
        A mapping of a shipped type replaces only the keys it gives.

    Returns
    -------
    dict
        Normalised message type -> complete mapping.

    Raises
    ------
    InputError
        A mapping that is not a dict, has unknown keys or lacks ``lat``, ``lon`` or ``height``.
    """
    out = {k: dict(v) for k, v in FIX_MAPPINGS.items()}
    for typ, m in (user or {}).items():
        if not isinstance(m, dict):
            raise InputError("fix mapping", f"the mapping for {typ} must be a dict of field paths")
        unknown = set(m) - _MAPPING_KEYS
        if unknown:
            raise InputError(
                "fix mapping",
                f"unknown key(s) {', '.join(sorted(unknown))} in the mapping for {typ} "
                f"(known: {', '.join(sorted(_MAPPING_KEYS))})",
            )
        base = out.get(normalize_type(typ), {})
        merged = {**_MAPPING_DEFAULTS, **base, **m}
        missing = [k for k in ("lat", "lon", "height") if not merged.get(k)]
        if missing:
            raise InputError(
                "fix mapping", f"the mapping for {typ} needs field path(s) {', '.join(missing)}"
            )
        out[normalize_type(typ)] = merged
    return out


class Collector:
    """Rows of one topic (time [s] first), with the counts of skipped fixes.

    Kept in a flat ``array('d')`` (8 bytes per value, no per-row Python objects), so memory is
    bounded by the data kept.
    """

    def __init__(self, topic: str, ncols: int):
        self.topic = topic
        self._buf = array("d")
        self.ncols = ncols
        self.skipped_no_fix = 0  # fixes marked invalid (NO_FIX status)
        self.zero_cov = 0  # fixes with an all-zero covariance (default sigma used)
        self.total = 0  # messages read
        self.frame_id = ""  # header.frame_id of the first message
        self.child_frame_id = ""  # child_frame_id of the first (Odometry) message

    def add(self, row) -> None:
        self._buf.extend(row)

    def __len__(self) -> int:
        return len(self._buf) // self.ncols

    def table(self) -> np.ndarray:
        """The rows as a new float array of shape (N, ncols)."""
        return np.frombuffer(self._buf, float).reshape(-1, self.ncols).copy()


def stamp_s(stamp) -> float:
    """A ``builtin_interfaces/Time`` in seconds: the float nearest the exact integer nanoseconds."""
    return (int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)) / 1e9


def _get(msg, path: str):
    for part in path.split("."):
        msg = getattr(msg, part)
    return msg


def imu_row(msg, t: float) -> tuple:
    """``sensor_msgs/Imu`` -> (t [s], f FLU [m/s^2], omega FLU [rad/s], q ENU<-FLU, var rpy [rad^2]).

    The orientation and its variances are NaN when absent (``orientation_covariance[0] = -1``
    or an all-zero quaternion, REP-145).
    """
    q, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
    cov = msg.orientation_covariance
    has_q = float(cov[0]) != -1.0 and (q.x or q.y or q.z or q.w)
    return (
        t,
        a.x,
        a.y,
        a.z,
        w.x,
        w.y,
        w.z,
        q.x if has_q else np.nan,
        q.y if has_q else np.nan,
        q.z if has_q else np.nan,
        q.w if has_q else np.nan,
        cov[0] if has_q else np.nan,
        cov[4] if has_q else np.nan,
        cov[8] if has_q else np.nan,
    )


def navsat_row(msg, t: float, col: Collector, default_sigma: np.ndarray) -> tuple | None:
    """``sensor_msgs/NavSatFix`` -> (t [s], lat [deg], lon [deg], h [m], sigma N, E, D [m]), or None.

    NO_FIX messages are counted in ``col`` and skipped. The ENU covariance diagonal gives the
    sigmas; an unknown or all-zero covariance gives ``default_sigma`` (N, E, D [m]).
    """
    if int(msg.status.status) < 0:  # STATUS_NO_FIX = -1
        col.skipped_no_fix += 1
        return None
    cov = np.asarray(msg.position_covariance, float)
    ctype = int(msg.position_covariance_type)
    if ctype == 0:
        sig = default_sigma
    else:
        diag = np.array([cov[4], cov[0], cov[8]])  # ENU diagonal -> N, E, D variances
        if not np.any(cov):
            col.zero_cov += 1
            sig = default_sigma
        else:
            sig = np.sqrt(np.where(diag > 0, diag, np.nan))
    return (t, msg.latitude, msg.longitude, msg.altitude, sig[0], sig[1], sig[2])


def _custom_fix_row(msg, t, col: Collector, m: dict, default_sigma: np.ndarray):
    if m.get("status") and _get(msg, m["status"]) in m.get("no_fix_values", []):
        col.skipped_no_fix += 1
        return None
    if m.get("stamp"):
        t = stamp_s(_get(msg, m["stamp"]))
    sc = float(m["latlon_scale_deg"])
    sig = []
    for k, d in zip(("sigma_n", "sigma_e", "sigma_d"), default_sigma):
        sig.append(float(_get(msg, m[k])) * float(m["sigma_scale_m"]) if m.get(k) else d)
    if all(s == 0 for s in sig):
        col.zero_cov += 1
        sig = list(default_sigma)
    sig = [s if s > 0 else np.nan for s in sig]
    return (
        t,
        float(_get(msg, m["lat"])) * sc,
        float(_get(msg, m["lon"])) * sc,
        float(_get(msg, m["height"])) * float(m["height_scale_m"]),
        *sig,
    )


def mapped_fix_row(
    msg,
    t: float,
    col: Collector,
    m: dict,
    default_sigma: np.ndarray,
    where: str,
    topic: str,
    typ: str,
) -> tuple | None:
    """A custom fix type through its field mapping ``m`` (see :data:`FIX_MAPPINGS`).

    Returns the row of :func:`navsat_row` (the mapping's scales applied: degrees, metres), or
    None for a fix its status field marks invalid. A mapping that does not fit the message
    raises :class:`InputError` listing the message's fields.
    """
    try:
        return _custom_fix_row(msg, t, col, m, default_sigma)
    except (AttributeError, TypeError, ValueError) as err:
        raise InputError(
            where,
            f"topic {topic}: the field mapping of {typ} does not fit its messages: "
            f"{one_line(err)} (fields of the message: "
            f"{', '.join(k for k in getattr(msg, '__dataclass_fields__', {}) if not k.startswith('_'))})",
        ) from None


def pose_row(msg, t: float, msgtype: str) -> tuple:
    """Odometry / PoseStamped / PoseWithCovarianceStamped -> (t [s], p NED [m], v NED [m/s], rpy [rad]).

    Position: ENU ``(e, n, u) -> (n, e, -u)`` about the pose frame's origin. Attitude: roll,
    pitch, yaw of ``R_nb`` (FRD body to NED). Velocity: the Odometry twist (FLU body axes)
    rotated to NED; NaN for the pose types and when the quaternion is all zero.
    """
    if msgtype == "geometry_msgs/msg/PoseStamped":
        pose, twist = msg.pose, None
    else:
        pose = msg.pose.pose
        twist = msg.twist.twist if msgtype == "nav_msgs/msg/Odometry" else None
    p, q = pose.position, pose.orientation
    if q.x or q.y or q.z or q.w:
        R_enu_flu = quaternion_to_dcm(q.x, q.y, q.z, q.w)
        rpy = dcm_to_euler(ros_to_R_nb(R_enu_flu))
        v = (
            ENU_NED @ R_enu_flu @ np.array([twist.linear.x, twist.linear.y, twist.linear.z])
            if twist is not None
            else (np.nan,) * 3
        )
    else:
        rpy, v = (np.nan,) * 3, (np.nan,) * 3
    return (t, p.y, p.x, -p.z, *v, *rpy)


def twist_columns(twist, cov=None) -> tuple:
    """A twist (in its message's axes) -> (v x, y, z [m/s], omega z [rad/s], var v x, var omega z,
    and the linear covariance ``xx, yy, zz, xy, xz, yz`` [m^2/s^2] as given); the two variances
    NaN when unknown (no covariance, or a non-positive one), the linear block NaN without a
    covariance."""
    var_v = float(cov[0]) if cov is not None and float(cov[0]) > 0 else np.nan
    var_w = float(cov[35]) if cov is not None and float(cov[35]) > 0 else np.nan
    lin = (
        (np.nan,) * 6
        if cov is None
        else tuple(float(cov[i]) for i in (0, 7, 14, 1, 2, 8))  # row-major 6x6
    )
    return (twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.z, var_v, var_w, *lin)


def odometry_row(msg, t: float) -> tuple:
    """``nav_msgs/Odometry`` -> the pose row (:func:`pose_row`) and the twist's columns
    (:func:`twist_columns`; the twist is in the ``child_frame_id`` axes, REP-103 FLU)."""
    return pose_row(msg, t, ODOMETRY_TYPE) + twist_columns(msg.twist.twist, msg.twist.covariance)


def twist_row(msg, t: float) -> tuple:
    """``geometry_msgs/TwistStamped`` -> (t, the twist's columns), variances unknown;
    ``TwistWithCovarianceStamped`` -> (t, the twist's columns with its covariance)."""
    if hasattr(msg.twist, "covariance"):
        return (t,) + twist_columns(msg.twist.twist, msg.twist.covariance)
    return (t,) + twist_columns(msg.twist)


class RowDecoder:
    """Turns one message of a chosen topic into a row (or None for a skipped fix).

    Parameters
    ----------
    mappings : dict
        Custom fix types -> field mapping (:func:`merge_fix_mappings`).
    time_source : {"header", "receive"}
        Header stamps (receive time for header-less types) or the bag receive times.
    default_sigma : ndarray, shape (3,)
        N, E, D fix sigma [m] when a message gives none.
    where : str
        The bag, for error messages.
    """

    def __init__(self, mappings: dict, time_source: str, default_sigma: np.ndarray, where: str):
        receive = time_source == "receive"
        # the receive-time choice also overrides a mapping's stamp field
        self.mappings = {typ: {**m, "stamp": None} if receive else m for typ, m in mappings.items()}
        self.header_time = not receive
        self.default_sigma = default_sigma
        self.where = where

    def row(self, msg, t_recv_ns: int, typ: str, col: Collector) -> tuple | None:
        """The row of ``msg`` (type ``typ``) received at ``t_recv_ns`` [ns]; counts go to ``col``."""
        t = t_recv_ns / 1e9
        if self.header_time and hasattr(msg, "header"):
            t = stamp_s(msg.header.stamp)
        if typ == IMU_TYPE:
            return imu_row(msg, t)
        if typ == NAVSATFIX_TYPE:
            return navsat_row(msg, t, col, self.default_sigma)
        if typ == ODOMETRY_TYPE:
            return odometry_row(msg, t)
        if typ in VELOCITY_TYPES:
            return twist_row(msg, t)
        if typ in POSE_TYPES:
            return pose_row(msg, t, typ)
        return mapped_fix_row(
            msg, t, col, self.mappings[typ], self.default_sigma, self.where, col.topic, typ
        )


def row_width(typ: str) -> int:
    """Columns of a row of message type ``typ``."""
    widths = {IMU_TYPE: IMU_COLS, ODOMETRY_TYPE: ODOM_COLS, TWIST_TYPE: 1 + TWIST_COLS}
    widths[TWIST_COV_TYPE] = 1 + TWIST_COLS
    return widths.get(typ, POSE_COLS if typ in POSE_TYPES else FIX_COLS)


@dataclass
class Decoded:
    """What :func:`decode_topics` read."""

    cols: dict[str, Collector]  # topic -> rows
    imu_frame_id: str  # header.frame_id of the first IMU message ("" if none)
    damaged: str | None  # why reading stopped early, or None


def decode_topics(reader, topics: dict[str, str], decoder: RowDecoder) -> Decoded:
    """Read and decode every message of the given topics, in bag order.

    Parameters
    ----------
    reader
        An open :class:`rosbags.highlevel.AnyReader` (or :class:`~gnssacc.sources.bag_salvage.Ros1Salvage`).
    topics : dict
        Topic -> message type of the topics to read.
    decoder : RowDecoder

    Returns
    -------
    Decoded
        A read error part-way (a damaged bag) ends the reading and is returned in ``damaged``;
        a message that cannot be deserialised raises :class:`InputError`.
    """
    cols = {topic: Collector(topic, row_width(typ)) for topic, typ in topics.items()}
    conns = [c for c in reader.connections if c.topic in topics]
    imu_frame_id = ""
    it = reader.messages(connections=conns)
    while True:
        try:
            conn, t_recv_ns, raw = next(it)
        except StopIteration:
            return Decoded(cols, imu_frame_id, None)
        except Exception as err:
            return Decoded(cols, imu_frame_id, one_line(err))
        topic, typ = conn.topic, conn.msgtype
        col = cols[topic]
        col.total += 1
        try:
            msg = reader.deserialize(raw, typ)
        except Exception as err:
            raise InputError(
                decoder.where, f"topic {topic}: cannot decode a {typ} message: {one_line(err)}"
            ) from None
        if typ == IMU_TYPE and not imu_frame_id:
            imu_frame_id = msg.header.frame_id
        if col.total == 1 and hasattr(msg, "header"):
            col.frame_id = str(msg.header.frame_id)
            col.child_frame_id = str(getattr(msg, "child_frame_id", ""))
        row = decoder.row(msg, t_recv_ns, typ, col)
        if row is not None:
            col.add(row)


def tf_mounting(reader, imu_frame_id: str) -> tuple[np.ndarray, str] | None:
    """The IMU mounting from a ``/tf_static`` transform ``base_link|base_footprint -> imu frame``.

    Returns
    -------
    (R_bi, what) or None
        ``R_bi`` (IMU FRD axes to body FRD axes, ``x_b = R_bi @ x_imu``) and a description of the
        transform; None without ``/tf_static``, IMU frame id or a matching transform.
    """
    conns = [
        c
        for c in reader.connections
        if c.msgtype == TF_TYPE and c.topic in ("/tf_static", "tf_static")
    ]
    if not conns or not imu_frame_id:
        return None
    child = imu_frame_id.lstrip("/")
    for conn, _, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        for tr in msg.transforms:
            parent = tr.header.frame_id.lstrip("/")
            if tr.child_frame_id.lstrip("/") == child and parent in BASE_FRAMES:
                q = tr.transform.rotation
                R_flu = quaternion_to_dcm(q.x, q.y, q.z, q.w)  # p_parent = R @ p_child
                return FLU_FRD @ R_flu @ FLU_FRD, f"/tf_static {parent} -> {child}"
    return None
