"""Which topics of a bag are the IMU, the GNSS, the truth and the wheel odometry: a survey of the
topics and the rules that pick them (:func:`select_topics`).

The truth is only proposed here (``Selection.truth_candidates``): a candidate becomes the truth
when its data show it geo-referenced and agreeing with the fixes
(:mod:`gnssacc.sources.truth_check`), which the loader decides after decoding.

A choice that is not unambiguous raises :class:`~gnssacc.core.errors.InputError` listing the
candidates and the command-line flag that picks one; every choice made comes with its reason
(``Selection.reasons``, shown by ``gnssacc inspect`` and kept in ``run.meta["selection"]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..core.errors import InputError
from .bag_decode import (
    IMU_TYPE,
    NAVSATFIX_TYPE,
    ODOM_TYPES,
    POSE_TYPES,
    TF_TYPE,
    VELOCITY_TYPES,
    merge_fix_mappings,
)

#: Types never taken for a GNSS fix, left out of the hint when no fix topic is found.
_NOT_FIX_PREFIXES = ("std_msgs/", "rosgraph_msgs/")
_NOT_FIX_TYPES = (
    IMU_TYPE,
    TF_TYPE,
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    *POSE_TYPES,
    *ODOM_TYPES,
    *VELOCITY_TYPES,
)


@dataclass
class TopicStat:
    """One topic of a bag: name, message type, message count and mean rate."""

    topic: str
    msgtype: str
    count: int
    rate_hz: float  # count / bag span (approximate: rosbag2 stores no per-topic span)

    def describe(self) -> str:
        return f"{self.topic} ({self.msgtype}, {self.count} msgs, ~{self.rate_hz:.1f} Hz)"


@dataclass
class Selection:
    """The topics chosen, with the reason for each choice.

    Attributes
    ----------
    imu, gnss : TopicStat
        ``gnss`` is None when the GNSS is made from the truth.
    truth, truth_kind : TopicStat or None, str or None
        The truth chosen without the agreement check: given by ``--truth-topic`` (checked, but only
        warned about) or the fix topic ``--gnss-from-truth`` makes the fixes from; kind ``"fix"``
        or ``"pose"``.
    reasons : list of str
    truth_candidates : list of (TopicStat, str)
        Without a chosen truth: the topics (and kinds) that become the truth only when geo-referenced
        and agreeing with the fixes.
    odom : TopicStat or None
        The wheel-odometry topic given by ``--odom-topic``.
    odom_candidates : list of TopicStat
        Without one given: the Odometry / TwistStamped topics (but a given truth), of which the one
        left after the truth is decided is the wheel odometry.
    vel_candidates : list of TopicStat
        The TwistStamped / TwistWithCovarianceStamped topics (but the given odometry) that may be
        the GNSS receiver's velocity (decided from the data:
        :func:`gnssacc.sources.bag_velocity.choose_velocity`).
    """

    imu: TopicStat
    gnss: TopicStat | None  # None when the GNSS is made from the truth
    truth: TopicStat | None
    truth_kind: str | None  # "fix" or "pose"
    reasons: list[str]
    truth_candidates: list = field(default_factory=list)
    odom: TopicStat | None = None
    odom_candidates: list = field(default_factory=list)
    vel_candidates: list = field(default_factory=list)


def survey(reader) -> list[TopicStat]:
    """The topics of an open reader, sorted by name; rates [Hz] over the whole bag's span."""
    span = max((reader.end_time - reader.start_time) * 1e-9, 1e-9) if reader.message_count else 0.0
    out = []
    for topic, info in reader.topics.items():
        typ = info.msgtype or "?"
        out.append(
            TopicStat(topic, typ, int(info.msgcount), info.msgcount / span if span > 0 else 0.0)
        )
    return sorted(out, key=lambda s: s.topic)


def _ambiguous(where, what: str, cands: list[TopicStat], flag: str):
    listing = "; ".join(c.describe() for c in cands)
    return InputError(
        where, f"ambiguous {what} topic: {len(cands)} candidates: {listing}; pick one with {flag}"
    )


class _Picker:
    """The rules of :func:`select_topics`, one method per choice; reasons collected in order."""

    def __init__(self, stats: list[TopicStat], where: str, mappings: dict):
        self.stats, self.where, self.mappings = stats, where, mappings
        self.nonempty = [s for s in stats if s.count > 0]
        self.reasons: list[str] = []

    def is_fix(self, s: TopicStat) -> bool:
        return s.msgtype == NAVSATFIX_TYPE or s.msgtype in self.mappings

    def find(self, topic: str, flag: str) -> TopicStat:
        for s in self.stats:
            if s.topic == topic:
                return s
        raise InputError(
            self.where,
            f"{flag} {topic}: no such topic in the bag (topics: "
            f"{', '.join(s.topic for s in self.stats) or 'none'})",
        )

    def check_fix(self, s: TopicStat, flag: str) -> None:
        if not self.is_fix(s):
            raise InputError(
                self.where,
                f"{flag} {s.topic} has type {s.msgtype}, which gnssacc cannot read as a "
                f"GNSS fix: give a field mapping for it (known: {NAVSATFIX_TYPE}, "
                f"{', '.join(sorted(self.mappings))})",
            )

    def imu(self, imu_topic: str | None) -> TopicStat:
        """The given topic, the only Imu topic, or the highest-rate one at >= 1.5x the next."""
        if imu_topic:
            imu = self.find(imu_topic, "--imu-topic")
            if imu.msgtype != IMU_TYPE:
                raise InputError(
                    self.where,
                    f"--imu-topic {imu.topic} has type {imu.msgtype}, expected {IMU_TYPE}",
                )
            self.reasons.append(f"IMU {imu.topic}: given by --imu-topic")
            return imu
        cands = sorted(
            [s for s in self.nonempty if s.msgtype == IMU_TYPE], key=lambda s: -s.rate_hz
        )
        if not cands:
            raise InputError(
                self.where,
                f"no IMU topic: no {IMU_TYPE} messages in the bag (topics: "
                f"{'; '.join(s.describe() for s in self.stats) or 'none'})",
            )
        if len(cands) > 1 and cands[0].rate_hz < 1.5 * cands[1].rate_hz:
            raise _ambiguous(self.where, "IMU", cands, "--imu-topic")
        self.reasons.append(
            f"IMU {cands[0].topic}: "
            + (
                "the only Imu topic"
                if len(cands) == 1
                else f"the highest-rate of {len(cands)} Imu topics"
            )
        )
        return cands[0]

    def given_truth(self, truth_topic: str | None):
        """(truth, kind) of ``--truth-topic``, or (None, None)."""
        if not truth_topic:
            return None, None
        truth = self.find(truth_topic, "--truth-topic")
        if truth.msgtype in POSE_TYPES:
            kind = "pose"
        else:
            self.check_fix(truth, "--truth-topic")
            kind = "fix"
        self.reasons.append(f"truth {truth.topic}: given by --truth-topic")
        return truth, kind

    def truth_for_gnss(self, truth, truth_kind, fixes: list[TopicStat], gnss_topic: str | None):
        """(truth, "fix") for ``--gnss-from-truth``: the given fix topic or the only one."""
        if gnss_topic:
            raise InputError(
                self.where,
                "give either --gnss-topic or --gnss-from-truth (the fixes are made from "
                "the truth topic), not both",
            )
        if truth is None:
            if len(fixes) == 1:
                self.reasons.append(
                    f"truth {fixes[0].topic}: the only fix topic (GNSS made from it by subsampling)"
                )
                return fixes[0], "fix"
            if not fixes:
                raise InputError(
                    self.where,
                    "--gnss-from-truth needs a truth fix topic, and the bag has no NavSatFix "
                    "or mapped fix topic",
                )
            raise _ambiguous(self.where, "truth (for --gnss-from-truth)", fixes, "--truth-topic")
        if truth_kind != "fix":
            raise InputError(
                self.where,
                f"--gnss-from-truth needs a fix-type truth topic; {truth.topic} is {truth.msgtype}",
            )
        return truth, truth_kind

    def gnss(self, gnss_topic: str | None, fixes: list[TopicStat], truth) -> TopicStat:
        """The given topic or the only fix topic left beside the truth."""
        if gnss_topic:
            gnss = self.find(gnss_topic, "--gnss-topic")
            self.check_fix(gnss, "--gnss-topic")
            self.reasons.append(f"GNSS {gnss.topic}: given by --gnss-topic")
            return gnss
        if not fixes:
            unknown = [
                s
                for s in self.nonempty
                if s.msgtype not in _NOT_FIX_TYPES and not s.msgtype.startswith(_NOT_FIX_PREFIXES)
            ]
            hint = (
                (
                    f"; topics of other types: {'; '.join(s.describe() for s in unknown)} -- if one is a fix, "
                    f"give --gnss-topic and a field mapping for its type"
                )
                if unknown
                else ""
            )
            raise InputError(
                self.where,
                f"no GNSS topic: no {NAVSATFIX_TYPE} or known custom fix type "
                f"({', '.join(sorted(self.mappings))}){hint}",
            )
        if len(fixes) > 1:
            raise _ambiguous(
                self.where,
                "GNSS",
                fixes,
                "--gnss-topic (and --truth-topic for a reference receiver)",
            )
        self.reasons.append(
            f"GNSS {fixes[0].topic}: the only fix topic" + (" besides the truth" if truth else "")
        )
        return fixes[0]

    def truth_candidates(
        self, fixes: list[TopicStat], gnss: TopicStat
    ) -> list[tuple[TopicStat, str]]:
        """The pose topics and the fix topics beside the GNSS: each becomes the truth only when it is
        geo-referenced and agrees with the fixes (decided when the bag is read)."""
        cands = [(s, "pose") for s in self.nonempty if s.msgtype in POSE_TYPES]
        cands += [(s, "fix") for s in fixes if s.topic != gnss.topic]
        if cands:
            self.reasons.append(
                "truth candidate(s) "
                + ", ".join(c.topic for c, _ in cands)
                + ": taken only if geo-referenced and agreeing with the fixes as given"
            )
        else:
            self.reasons.append("no truth topic")
        return cands

    def odometry(self, odom_topic: str | None, truth: TopicStat | None):
        """(the given wheel-odometry topic, None) or (None, the Odometry / TwistStamped candidates)."""
        if odom_topic:
            odom = self.find(odom_topic, "--odom-topic")
            if odom.msgtype not in ODOM_TYPES:
                raise InputError(
                    self.where,
                    f"--odom-topic {odom.topic} has type {odom.msgtype}, expected one of "
                    f"{', '.join(ODOM_TYPES)}",
                )
            if truth is not None and odom.topic == truth.topic:
                raise InputError(self.where, f"--odom-topic {odom.topic} is also the truth topic")
            self.reasons.append(f"wheel odometry {odom.topic}: given by --odom-topic")
            return odom, []
        cands = [
            s
            for s in self.nonempty
            if s.msgtype in ODOM_TYPES and (truth is None or s.topic != truth.topic)
        ]
        if cands:
            self.reasons.append(
                "wheel odometry candidate(s) "
                + ", ".join(c.topic for c in cands)
                + ": the one not taken as the truth (with a twist that moves)"
            )
        return None, cands


def select_topics(
    stats: list[TopicStat],
    where: str,
    *,
    imu_topic=None,
    gnss_topic=None,
    truth_topic=None,
    gnss_from_truth: bool = False,
    mappings: dict | None = None,
    odom_topic=None,
) -> Selection:
    """Pick the IMU, GNSS, truth and wheel-odometry topics.

    Rules: IMU = the only ``Imu`` topic, or the highest-rate one if at least 1.5x the rate of
    the next; GNSS = the only fix topic (NavSatFix or a mapped custom type) left after the truth;
    truth = the given topic, else candidates (every Odometry/Pose topic and every fix topic beside
    the GNSS) that the loader accepts only when geo-referenced and agreeing with the fixes. With
    ``gnss_from_truth`` the single fix topic is the truth. Wheel odometry = the given topic, else
    the Odometry / TwistStamped candidates (the loader keeps the one not taken as the truth).
    Anything else raises :class:`InputError` listing the candidates and the flag.

    Parameters
    ----------
    stats : list of TopicStat
        The bag's topics (:func:`survey`).
    where : str
        The bag, for error messages.
    imu_topic, gnss_topic, truth_topic : str, optional
        Topics given on the command line.
    gnss_from_truth : bool
        The GNSS is to be made from the truth (no GNSS topic is chosen).
    mappings : dict, optional
        Custom fix types (:func:`gnssacc.sources.bag_decode.merge_fix_mappings`); default the shipped ones.
    """
    pick = _Picker(stats, where, merge_fix_mappings(None) if mappings is None else mappings)
    imu = pick.imu(imu_topic)
    truth, truth_kind = pick.given_truth(truth_topic)
    fixes = [
        s for s in pick.nonempty if pick.is_fix(s) and (truth is None or s.topic != truth.topic)
    ]
    if gnss_from_truth:
        truth, truth_kind = pick.truth_for_gnss(truth, truth_kind, fixes, gnss_topic)
        odom, odoms = pick.odometry(odom_topic, truth)
        return Selection(imu, None, truth, truth_kind, pick.reasons, [], odom, odoms)
    gnss = pick.gnss(gnss_topic, fixes, truth)
    cands = pick.truth_candidates(fixes, gnss) if truth is None else []
    odom, odoms = pick.odometry(odom_topic, truth)
    vels = [
        s
        for s in pick.nonempty
        if s.msgtype in VELOCITY_TYPES and s.topic not in (getattr(odom, "topic", None),)
    ]
    if vels:
        pick.reasons.append(
            "GNSS velocity candidate(s) "
            + ", ".join(v.topic for v in vels)
            + ": taken only if not in a body or odometry frame, stamped with the fixes and "
            "agreeing with their differences (as ENU)"
        )
    return Selection(imu, gnss, truth, truth_kind, pick.reasons, cands, odom, odoms, vels)
