#!/usr/bin/env python3
"""An independent ROS 2 base on Zenoh, as rmw_zenoh (Jazzy) would put it on
the wire: the far side of echelon's ROS 2 interop tests.

It is written only from rmw_zenoh's documented formats, the ROS 2 Jazzy
wheels (rclpy serialization, type hashes from share/<pkg>/msg/<Type>.json)
and eclipse-zenoh (its zenoh.ext serializer writes the attachment), with no
code from echelon:

- subscribes to `<domain>/<ns>/cmd_vel/<pkg>::msg::dds_::<Type>_/<RIHS01 hash>`
  (TwistStamped or Twist), deserializes each command with rclpy and parses
  its attachment with `zenoh.ext.z_deserialize(tuple[Int64, Int64, list[UInt8]])`;
- integrates a unicycle `x' = v cos θ, y' = v sin θ, θ' = ω` exactly with the last
  command (zero after `--cmd-timeout` s without one, as diff_drive_controller
  does), and publishes nav_msgs/Odometry on `.../odom/...` at `--rate` Hz with
  an rmw_zenoh attachment;
- declares its own liveliness tokens (node, odom publisher, cmd_vel
  subscription) and records every `@ros2_lv/<domain>/**` token it sees;
- under `--scheme bridge` uses zenoh-bridge-ros2dds's plain keys
  (`<ns>/cmd_vel`, `<ns>/odom`), no attachment, and the bridge's route
  tokens instead of rmw_zenoh's (`@/<zid>/@ros2_lv/MP|MS/<key>/<type>/<qos>`,
  `/` written `§`, as the real bridge declares them:
  crates/echelon-fleet/tests/fixtures/ros2dds/);
- under `--scheme rmw_zenoh_humble` is a Humble robot: rmw_zenoh's humble
  branch writes `TypeHashNotSupported` where Jazzy writes the RIHS01 hash, in
  keys and liveliness tokens (Humble has no type hashes).

It runs for `--duration` s (or until SIGTERM/SIGINT) and then writes a JSON
report to `--report`: commands received, attachments valid/invalid, the last
command and its attachment, tokens seen, the final pose.

Usage: fake_base.py --connect tcp/127.0.0.1:7447 [--listen ...] [--domain 0]
       [--namespace /robot1] [--cmd-type twist-stamped|twist]
       [--scheme rmw_zenoh|rmw_zenoh_humble|bridge] [--rate 50] [--duration 10]
       [--x 0 --y 0 --yaw 0] [--cmd-timeout 0.5] --report out.json
"""

import argparse
import json
import math
import os
import signal
import sys
import threading
import time

TYPES = {
    "twist-stamped": ("geometry_msgs", "TwistStamped"),
    "twist": ("geometry_msgs", "Twist"),
    "odometry": ("nav_msgs", "Odometry"),
}


def type_hash(pkg, name):
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in prefixes + [sys.prefix]:
        path = os.path.join(prefix, "share", pkg, "msg", f"{name}.json")
        if os.path.exists(path):
            with open(path, encoding="utf-8") as f:
                doc = json.load(f)
            for entry in doc["type_hashes"]:
                if entry["type_name"] == f"{pkg}/msg/{name}":
                    return entry["hash_string"]
    sys.exit(f"no type hash for {pkg}/msg/{name}: install scripts/requirements-ros2.txt")


def topic_key(args, topic, pkg, name):
    ns = args.namespace.strip("/")
    path = f"{ns}/{topic}" if ns else topic
    if args.scheme == "bridge":
        return path
    return f"{args.domain}/{path}/{pkg}::msg::dds_::{name}_/{key_hash(args, pkg, name)}"


def key_hash(args, pkg, name):
    """The type hash's chunk of keys and tokens: Humble has none."""
    if args.scheme == "rmw_zenoh_humble":
        return "TypeHashNotSupported"
    return type_hash(pkg, name)


def mangle(name):
    return name.replace("/", "%") if name else "%"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", action="append", default=[])
    p.add_argument("--listen", action="append", default=[])
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--namespace", default="/")
    p.add_argument("--cmd-type", choices=["twist-stamped", "twist"], default="twist-stamped")
    p.add_argument("--scheme", choices=["rmw_zenoh", "rmw_zenoh_humble", "bridge"], default="rmw_zenoh")
    p.add_argument("--rate", type=float, default=50.0)
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--x", type=float, default=0.0)
    p.add_argument("--y", type=float, default=0.0)
    p.add_argument("--yaw", type=float, default=0.0)
    p.add_argument("--cmd-timeout", type=float, default=0.5)
    p.add_argument("--report", required=True)
    args = p.parse_args()

    import zenoh
    from zenoh.ext import Int64, UInt8, z_deserialize, z_serialize
    from rclpy.serialization import deserialize_message, serialize_message
    from geometry_msgs.msg import Twist, TwistStamped
    from nav_msgs.msg import Odometry

    cmd_pkg, cmd_name = TYPES[args.cmd_type]
    cmd_class = TwistStamped if args.cmd_type == "twist-stamped" else Twist
    cmd_key = topic_key(args, "cmd_vel", cmd_pkg, cmd_name)
    odom_key = topic_key(args, "odom", "nav_msgs", "Odometry")

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps(args.connect))
    conf.insert_json5("listen/endpoints", json.dumps(args.listen))
    session = zenoh.open(conf)

    lock = threading.Lock()
    state = {
        "samples": 0,
        "commands": 0,
        "errors": [],
        "attachments_valid": 0,
        "attachments_invalid": 0,
        "undecodable": 0,
        "last_command": None,
        "last_attachment": None,
        "last_command_at": None,
        "sequence_numbers": [],
        "tokens": [],
        "cmd_key": cmd_key,
        "odom_key": odom_key,
        "zid": str(session.zid()),
    }

    def on_cmd(sample):
        try:
            handle_cmd(sample)
        except Exception as e:  # recorded in the report, never lost in a callback
            with lock:
                state["errors"].append(repr(e))

    def handle_cmd(sample):
        with lock:
            state["samples"] += 1
        payload = sample.payload.to_bytes()
        try:
            msg = deserialize_message(payload, cmd_class)
        except Exception:  # rclpy raises on malformed CDR
            with lock:
                state["undecodable"] += 1
            return
        twist = msg.twist if args.cmd_type == "twist-stamped" else msg
        att = None
        if sample.attachment is not None:
            try:
                seq, ts, gid = z_deserialize(tuple[Int64, Int64, list[UInt8]], sample.attachment)
                if len(gid) == 16 and len(sample.attachment.to_bytes()) == 33:
                    att = {"sequence_number": seq, "source_timestamp": ts, "gid": bytes(gid).hex()}
            except Exception:
                att = None
        with lock:
            state["commands"] += 1
            if att is None:
                state["attachments_invalid"] += 1
            else:
                state["attachments_valid"] += 1
                state["sequence_numbers"].append(att["sequence_number"])
            command = {"v": twist.linear.x, "omega": twist.angular.z}
            if args.cmd_type == "twist-stamped":
                command["frame_id"] = msg.header.frame_id
                command["stamp"] = [msg.header.stamp.sec, msg.header.stamp.nanosec]
            state["last_command"] = command
            state["last_attachment"] = att
            state["last_command_at"] = time.monotonic()

    def on_token(sample):
        with lock:
            if sample.kind == zenoh.SampleKind.PUT:
                state["tokens"].append(str(sample.key_expr))

    cmd_sub = session.declare_subscriber(cmd_key, on_cmd)  # kept alive for the whole run
    publisher = session.declare_publisher(odom_key)
    tokens = []
    gid = bytes(range(0xB0, 0xC0))
    if args.scheme == "bridge":
        # The bridge's route tokens: odom published (MP), cmd_vel subscribed (MS).
        ns_key = args.namespace.strip("/")
        route = lambda kind, topic, pkg, name: (
            f"@/{session.zid()}/@ros2_lv/{kind}/{(ns_key + '/' + topic).strip('/').replace('/', '§')}/"
            f"{pkg}§msg§{name}/:1:::typehash={key_hash(args, pkg, name)};")
        tokens.append(session.liveliness().declare_token(route("MP", "odom", "nav_msgs", "Odometry")))
        tokens.append(session.liveliness().declare_token(route("MS", "cmd_vel", cmd_pkg, cmd_name)))
    if args.scheme != "bridge":
        session.liveliness().declare_subscriber(f"@ros2_lv/{args.domain}/**", on_token, history=True)
        ns = "/" + args.namespace.strip("/") if args.namespace.strip("/") else "/"
        node = f"@ros2_lv/{args.domain}/{session.zid()}/0/0/NN/%/{mangle(ns)}/fake_base"
        prefix = lambda eid, kind: f"@ros2_lv/{args.domain}/{session.zid()}/0/{eid}/{kind}/%/{mangle(ns)}/fake_base"
        ns_topic = lambda t: (ns.rstrip("/") + "/" + t)
        tokens.append(session.liveliness().declare_token(node))
        tokens.append(session.liveliness().declare_token(
            f"{prefix(1, 'MP')}/{mangle(ns_topic('odom'))}/nav_msgs::msg::dds_::Odometry_/"
            f"{key_hash(args, 'nav_msgs', 'Odometry')}/::,:,:,:,,"))
        tokens.append(session.liveliness().declare_token(
            f"{prefix(2, 'MS')}/{mangle(ns_topic('cmd_vel'))}/{cmd_pkg}::msg::dds_::{cmd_name}_/"
            f"{key_hash(args, cmd_pkg, cmd_name)}/::,:,:,:,,"))

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())

    x, y, yaw = args.x, args.y, args.yaw
    dt = 1.0 / args.rate
    seq = 1
    start = time.monotonic()
    next_tick = start
    while not stop.is_set() and time.monotonic() - start < args.duration:
        now = time.monotonic()
        with lock:
            cmd = state["last_command"]
            fresh = state["last_command_at"] is not None and now - state["last_command_at"] <= args.cmd_timeout
        v, omega = (cmd["v"], cmd["omega"]) if (cmd and fresh) else (0.0, 0.0)
        # Exact for a command held over the step: arcs of radius v/ω.
        if abs(omega) > 1e-12:
            x += v / omega * (math.sin(yaw + omega * dt) - math.sin(yaw))
            y -= v / omega * (math.cos(yaw + omega * dt) - math.cos(yaw))
        else:
            x += v * math.cos(yaw) * dt
            y += v * math.sin(yaw) * dt
        yaw += omega * dt
        odom = Odometry()
        stamp_ns = time.time_ns()
        odom.header.stamp.sec = stamp_ns // 1_000_000_000
        odom.header.stamp.nanosec = stamp_ns % 1_000_000_000
        odom.header.frame_id = "odom"
        odom.child_frame_id = "base_link"
        odom.pose.pose.position.x = x
        odom.pose.pose.position.y = y
        odom.pose.pose.orientation.z = math.sin(yaw / 2)
        odom.pose.pose.orientation.w = math.cos(yaw / 2)
        odom.twist.twist.linear.x = v
        odom.twist.twist.angular.z = omega
        payload = serialize_message(odom)
        if args.scheme != "bridge":
            attachment = z_serialize((Int64(seq), Int64(stamp_ns), [UInt8(b) for b in gid]))
            publisher.put(payload, attachment=attachment)
        else:
            publisher.put(payload)
        seq += 1
        next_tick += dt
        stop.wait(max(0.0, next_tick - time.monotonic()))

    with lock:
        state["final_pose"] = {"x": x, "y": y, "yaw": yaw}
        state["odom_published"] = seq - 1
        state["gid"] = gid.hex()
        report = dict(state)
    report.pop("last_command_at")
    with open(args.report, "w", encoding="utf-8") as f:
        json.dump(report, f, indent=1)
    for t in tokens:
        t.undeclare()
    session.close()


if __name__ == "__main__":
    main()
