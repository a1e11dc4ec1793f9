#!/usr/bin/env python3
"""The Create 3's hazard publisher as a Cyclone DDS peer (the `cyclonedds`
Python package, no rclpy): the second, independent DDS vendor in echelon's
interop tests against a real zenoh-bridge-ros2dds.

It publishes `irobot_create_msgs/msg/HazardDetectionVector` on
`rt/<ns>/hazard_detection` (DDS type
`irobot_create_msgs::msg::dds_::HazardDetectionVector_`), and optionally
`std_msgs/msg/Bool` on an e-stop topic (`--estop-topic`, default
`platform/emergency_stop`), with the QoS of a ROS 2 publisher at depth 10:
reliable, keep-last 10, volatile. The samples are plain CDR (XCDR1
little-endian, header 00 01 00 00), as rmw writes them.

zenoh-bridge-ros2dds routes only DDS writers/readers that belong to a ROS
node, and it learns nodes from the `ros_discovery_info` topic
(rmw_dds_common/msg/ParticipantEntitiesInfo). So, as rmw does, this peer
publishes one ParticipantEntitiesInfo (reliable, transient-local, keep-last
1) naming its participant, its node (`--namespace`, `--node-name`) and the
gids of its writers. A gid is the entity's DDS GUID, byte for byte (12-byte
GUID prefix + 4-byte entity id, as `dds_get_guid` returns it). Jazzy (and
Iron) carry it as `char[16]`; Humble as `char[24]`, the GUID followed by 8
zero bytes (`--distro humble`, or ROS_DISTRO=humble). From Iron on, ROS
writers and readers also carry `typehash=RIHS01_<sha256>;` in their
USER_DATA QoS, which the bridge forwards in its liveliness tokens; Humble
has no type hashes.

Behaviour comes from schedules, times in seconds from start:
  --schedule "0:none,3.0:bump,6.0:none"    hazard state ("none" is an empty
      vector; kinds: backup_limit, bump, cliff, stall, wheel_drop,
      object_proximity; several joined with '+', e.g. "bump+cliff")
  --estop-schedule "0:false,4:true"        e-stop state (creates the e-stop
      writer)
The current state is re-published at `--rate` Hz (default 10).

With `--with-base` it also stands in for the base's DDS interface (a
`cmd_vel` reader of geometry_msgs/msg/Twist, an `odom` writer at 20 Hz with
the robot at rest), registered in the same node: a Humble-flavoured base for
the Humble capture, since the Jazzy rclpy base (create3_base.py) announces
16-byte gids that a bridge started with ROS_DISTRO=humble cannot decode.

It runs for `--duration` s (or until SIGTERM/SIGINT) and writes a JSON report
to `--report`: the DDS names and gids, what ros_discovery_info said, how
many samples of each state were published and when each state started.

Usage: hazard_node.py [--namespace /] [--node-name hazard_node] [--domain 42]
       [--localhost] [--distro jazzy|humble] [--schedule ...]
       [--estop-schedule ...] [--estop-topic platform/emergency_stop]
       [--with-base] [--rate 10] [--duration 10] --report out.json
"""

import argparse
import json
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32

# irobot_create_msgs/msg/HazardDetection constants.
HAZARDS = {
    "backup_limit": 0,
    "bump": 1,
    "cliff": 2,
    "stall": 3,
    "wheel_drop": 4,
    "object_proximity": 5,
}
# The sensor frame the Create 3 names in each detection's header.
HAZARD_FRAMES = {
    "backup_limit": "base_link",
    "bump": "bump_front_center",
    "cliff": "cliff_front_left",
    "stall": "base_link",
    "wheel_drop": "wheel_drop_left",
    "object_proximity": "ir_intensity_front_center_left",
}

# RIHS01 type hashes (Jazzy): HazardDetectionVector computed with
# rosidl_generator_type_description from irobot_create_msgs' field definitions
# (HazardDetectionVector: std_msgs/Header header, HazardDetection[] detections;
# HazardDetection: std_msgs/Header header, uint8 type); the others are in the
# wheels' share/<pkg>/msg/<Type>.json.
HASH_HAZARD_VECTOR = "RIHS01_90913822b0a9155a64b12352ba73b2ca9248d73874ebf7700ed277b2dca57edd"
HASH_BOOL = "RIHS01_feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9"
HASH_TWIST = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
HASH_ODOMETRY = "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
HASH_PARTICIPANT_ENTITIES_INFO = "RIHS01_91a0593bacdcc50ea9bdcf849a938b128412cc1ea821245c663bcd26f83c295e"

# The XML that zenoh-bridge-ros2dds gives Cyclone DDS for ros_localhost_only /
# ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: loopback only, no multicast,
# unicast discovery of participant indices 0..32 on localhost.
LOCALHOST_XML = (
    "<CycloneDDS><Domain><General><Interfaces><NetworkInterface address=\"127.0.0.1\"/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
    "<Peers><Peer address=\"localhost\"/></Peers></Discovery></Domain></CycloneDDS>"
)


@dataclass
class Time_(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header_(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time_ = field(default_factory=Time_)
    frame_id: str = ""


@dataclass
class HazardDetection_(IdlStruct, typename="irobot_create_msgs::msg::dds_::HazardDetection_"):
    header: Header_ = field(default_factory=Header_)
    type: uint8 = 0


@dataclass
class HazardDetectionVector_(IdlStruct, typename="irobot_create_msgs::msg::dds_::HazardDetectionVector_"):
    header: Header_ = field(default_factory=Header_)
    detections: sequence[HazardDetection_] = field(default_factory=list)


@dataclass
class Bool_(IdlStruct, typename="std_msgs::msg::dds_::Bool_"):
    data: bool = False


@dataclass
class Vector3_(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Twist_(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3_ = field(default_factory=Vector3_)
    angular: Vector3_ = field(default_factory=Vector3_)


@dataclass
class Point_(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion_(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Pose_(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point_ = field(default_factory=Point_)
    orientation: Quaternion_ = field(default_factory=Quaternion_)


@dataclass
class PoseWithCovariance_(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose_ = field(default_factory=Pose_)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class TwistWithCovariance_(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist_ = field(default_factory=Twist_)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Odometry_(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header_ = field(default_factory=Header_)
    child_frame_id: str = ""
    pose: PoseWithCovariance_ = field(default_factory=PoseWithCovariance_)
    twist: TwistWithCovariance_ = field(default_factory=TwistWithCovariance_)


# rmw_dds_common/msg: Gid is `char[16] data` from Iron on, `char[24] data` in Humble.
def discovery_types(gid_len):
    """rmw_dds_common's Gid, NodeEntitiesInfo and ParticipantEntitiesInfo
    with a Gid of `gid_len` bytes (16: Iron and later; 24: Humble)."""

    @dataclass
    class Gid_(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
        data: array[uint8, gid_len] = field(default_factory=lambda: [0] * gid_len)

    @dataclass
    class NodeEntitiesInfo_(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
        node_namespace: str = "/"
        node_name: str = ""
        reader_gid_seq: sequence[Gid_] = field(default_factory=list)
        writer_gid_seq: sequence[Gid_] = field(default_factory=list)

    @dataclass
    class ParticipantEntitiesInfo_(IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
        gid: Gid_ = field(default_factory=Gid_)
        node_entities_info_seq: sequence[NodeEntitiesInfo_] = field(default_factory=list)

    return Gid_, NodeEntitiesInfo_, ParticipantEntitiesInfo_


def parse_schedule(text, parse_value):
    entries = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        t, _, value = item.partition(":")
        entries.append((float(t), parse_value(value.strip())))
    entries.sort(key=lambda e: e[0])
    if not entries:
        raise ValueError(f"empty schedule: {text!r}")
    return entries


def parse_hazards(value):
    if value in ("", "none"):
        return ()
    kinds = tuple(v.strip() for v in value.split("+"))
    for k in kinds:
        if k not in HAZARDS:
            raise ValueError(f"unknown hazard {k!r} (known: none, {', '.join(HAZARDS)})")
    return kinds


def parse_bool(value):
    if value.lower() in ("true", "1", "on"):
        return True
    if value.lower() in ("false", "0", "off"):
        return False
    raise ValueError(f"not a boolean: {value!r}")


def state_at(schedule, t):
    current = schedule[0][1]
    for at, value in schedule:
        if at <= t:
            current = value
    return current


def ros_topic(namespace, name):
    ns = namespace.strip("/")
    name = name.strip("/")
    return f"/{ns}/{name}" if ns else f"/{name}"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--namespace", default="/")
    p.add_argument("--node-name", default="hazard_node")
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "0")))
    p.add_argument("--localhost", action="store_true", help="Cyclone DDS on loopback only (as the bridge's ros_localhost_only)")
    p.add_argument("--distro", choices=["jazzy", "humble"],
                   default="humble" if os.environ.get("ROS_DISTRO", "").startswith("humble") else "jazzy")
    p.add_argument("--schedule", default="0:none")
    p.add_argument("--estop-schedule", default=None)
    p.add_argument("--estop-topic", default="platform/emergency_stop")
    p.add_argument("--with-base", action="store_true",
                   help="also stand in for the base's DDS interface: a cmd_vel reader (Twist) and an odom writer (20 Hz, pose at rest)")
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--report", required=True)
    args = p.parse_args()

    hazard_schedule = parse_schedule(args.schedule, parse_hazards)
    estop_schedule = parse_schedule(args.estop_schedule, parse_bool) if args.estop_schedule else None

    if args.localhost:
        os.environ["CYCLONEDDS_URI"] = LOCALHOST_XML + ("," + os.environ["CYCLONEDDS_URI"] if os.environ.get("CYCLONEDDS_URI") else "")

    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.qos import Policy, Qos
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    humble = args.distro == "humble"
    ns = "/" + args.namespace.strip("/") if args.namespace.strip("/") else "/"

    def writer_qos(depth, transient_local, type_hash):
        policies = [
            Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
            Policy.Durability.TransientLocal if transient_local else Policy.Durability.Volatile,
            Policy.History.KeepLast(depth),
            # Plain CDR (header 00 01): what rmw writes and what ROS readers take.
            Policy.DataRepresentation(use_cdrv0_representation=True),
        ]
        if not humble:
            policies.append(Policy.Userdata(data=f"typehash={type_hash};".encode()))
        return Qos(*policies)

    dp = DomainParticipant(args.domain)

    hazard_name = ros_topic(ns, "hazard_detection")
    hazard_topic = Topic(dp, "rt" + hazard_name, HazardDetectionVector_)
    hazard_writer = DataWriter(dp, hazard_topic, qos=writer_qos(10, False, HASH_HAZARD_VECTOR))
    writers = [hazard_writer]
    estop_writer = None
    estop_name = None
    if estop_schedule is not None:
        estop_name = ros_topic(ns, args.estop_topic)
        estop_topic = Topic(dp, "rt" + estop_name, Bool_)
        estop_writer = DataWriter(dp, estop_topic, qos=writer_qos(10, False, HASH_BOOL))
        writers.append(estop_writer)

    readers = []
    cmd_reader = odom_writer = None
    if args.with_base:
        from cyclonedds.sub import DataReader
        cmd_topic = Topic(dp, "rt" + ros_topic(ns, "cmd_vel"), Twist_)
        cmd_reader = DataReader(dp, cmd_topic, qos=writer_qos(10, False, HASH_TWIST))
        readers.append(cmd_reader)
        odom_topic = Topic(dp, "rt" + ros_topic(ns, "odom"), Odometry_)
        odom_writer = DataWriter(dp, odom_topic, qos=writer_qos(10, False, HASH_ODOMETRY))
        writers.append(odom_writer)

    # ros_discovery_info, as rmw publishes it.
    Gid_, NodeEntitiesInfo_, ParticipantEntitiesInfo_ = discovery_types(24 if humble else 16)

    def gid_of(entity):
        raw = entity.guid.bytes  # dds_get_guid: 12-byte prefix + 4-byte entity id
        return Gid_(data=list(raw + bytes(8)) if humble else list(raw))

    info_types = (ParticipantEntitiesInfo_, NodeEntitiesInfo_)
    info_topic = Topic(dp, "ros_discovery_info", info_types[0])
    info_writer = DataWriter(dp, info_topic, qos=writer_qos(1, True, HASH_PARTICIPANT_ENTITIES_INFO))
    info = info_types[0](
        gid=gid_of(dp),
        node_entities_info_seq=[info_types[1](
            node_namespace=ns,
            node_name=args.node_name,
            reader_gid_seq=[gid_of(r) for r in readers],
            writer_gid_seq=[gid_of(w) for w in writers],
        )],
    )
    info_writer.write(info)

    report = {
        "distro": args.distro,
        "domain": args.domain,
        "node": {"namespace": ns, "name": args.node_name},
        "participant_gid": bytes(info.gid.data).hex(),
        "ros_discovery_info_cdr": info.serialize().hex(),
        "writers": [
            {"topic": "rt" + hazard_name, "ros_name": hazard_name,
             "type": "irobot_create_msgs::msg::dds_::HazardDetectionVector_",
             "gid": bytes(gid_of(hazard_writer).data).hex(),
             "user_data": None if humble else f"typehash={HASH_HAZARD_VECTOR};"},
        ],
        "hazard": {"published": 0, "by_state": {}, "transitions": []},
        "estop": None,
    }
    if estop_writer is not None:
        report["writers"].append(
            {"topic": "rt" + estop_name, "ros_name": estop_name, "type": "std_msgs::msg::dds_::Bool_",
             "gid": bytes(gid_of(estop_writer).data).hex(),
             "user_data": None if humble else f"typehash={HASH_BOOL};"})
        report["estop"] = {"published": 0, "by_state": {}, "transitions": []}
    if args.with_base:
        report["writers"].append(
            {"topic": "rt" + ros_topic(ns, "odom"), "ros_name": ros_topic(ns, "odom"), "type": "nav_msgs::msg::dds_::Odometry_",
             "gid": bytes(gid_of(odom_writer).data).hex(),
             "user_data": None if humble else f"typehash={HASH_ODOMETRY};"})
        report["readers"] = [
            {"topic": "rt" + ros_topic(ns, "cmd_vel"), "ros_name": ros_topic(ns, "cmd_vel"), "type": "geometry_msgs::msg::dds_::Twist_",
             "gid": bytes(gid_of(cmd_reader).data).hex(),
             "user_data": None if humble else f"typehash={HASH_TWIST};"}]
        report["commands"] = []
        report["nonzero_commands"] = 0
        report["odom_published"] = 0
    print(f"hazard_node: {args.distro} node {ns} {args.node_name}: "
          + ", ".join(w["ros_name"] for w in report["writers"]), file=sys.stderr, flush=True)

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())

    def record(section, label, t):
        sec = report[section]
        sec["published"] += 1
        sec["by_state"][label] = sec["by_state"].get(label, 0) + 1
        if not sec["transitions"] or sec["transitions"][-1]["state"] != label:
            sec["transitions"].append({"state": label, "t_rel": round(t, 3)})

    start = time.monotonic()
    period = 1.0 / args.rate
    next_tick = start
    next_odom = [start]
    while not stop.is_set():
        t = time.monotonic() - start
        if t >= args.duration:
            break
        stamp_ns = time.time_ns()
        stamp = Time_(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
        kinds = state_at(hazard_schedule, t)
        hazard_writer.write(HazardDetectionVector_(
            header=Header_(stamp=stamp, frame_id="base_link"),
            detections=[HazardDetection_(header=Header_(stamp=stamp, frame_id=HAZARD_FRAMES[k]), type=HAZARDS[k])
                        for k in kinds],
        ))
        record("hazard", "+".join(kinds) or "none", t)
        if estop_writer is not None:
            value = state_at(estop_schedule, t)
            estop_writer.write(Bool_(data=value))
            record("estop", str(value).lower(), t)
        if args.with_base:
            for cmd in cmd_reader.take(N=100):
                value = {"linear": [cmd.linear.x, cmd.linear.y, cmd.linear.z],
                         "angular": [cmd.angular.x, cmd.angular.y, cmd.angular.z]}
                now = time.monotonic()
                report["commands"].append({"t": now, "t_rel": now - start, "value": value})
                if any(c != 0.0 for c in value["linear"] + value["angular"]):
                    report["nonzero_commands"] += 1
        next_tick += period
        # 20 Hz odometry in between (--with-base).
        while odom_writer is not None and not stop.is_set() and next_odom[0] < next_tick:
            stop.wait(max(0.0, next_odom[0] - time.monotonic()))
            stamp_ns = time.time_ns()
            odom_writer.write(Odometry_(
                header=Header_(stamp=Time_(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000),
                               frame_id="odom"),
                child_frame_id="base_link"))
            report["odom_published"] += 1
            next_odom[0] += 1.0 / 20
        stop.wait(max(0.0, next_tick - time.monotonic()))

    report["elapsed"] = time.monotonic() - start
    with open(args.report, "w", encoding="utf-8") as f:
        json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
