#!/usr/bin/env python3
"""An iRobot Create 3 base as a plain ROS 2 DDS node (rclpy, Fast DDS, from the
ROS 2 Jazzy wheels): the robot side of echelon's interop tests against a real
zenoh-bridge-ros2dds.

Unlike scripts/ros2/fake_base.py (a Zenoh peer that imitates rmw_zenoh), this
is an ordinary rclpy node: it speaks DDS and registers itself on
`ros_discovery_info` like every ROS 2 node, so whatever the bridge routes for
it is what the bridge routes for a real robot. With the bridge in front of it,
it proves:

- Zenoh -> DDS: a command put on the bridge's Zenoh key for `cmd_vel` reaches
  this node's `cmd_vel` subscription (geometry_msgs/msg/Twist, or TwistStamped
  with `--cmd-type twist-stamped`), and the report lists every command with its
  receive time and value;
- DDS -> Zenoh: nav_msgs/msg/Odometry published on `odom` (frame `odom`, child
  `base_link`) at the Create 3's 20 Hz comes out of the bridge.

The motion follows the Create 3's firmware rules: a unicycle `x' = v cos θ,
y' = v sin θ, θ' = ω` whose speeds slew towards the command with acceleration
at most 0.9 m/s² on v and 0.9/0.1175 rad/s² on ω (0.1175 m is half the wheel
separation), speed clamped to 0.306 m/s (and ω to 0.306/0.1175 rad/s), and
the wheels stop 0.5 s after the last command.

The Create 3 runs its nodes without a namespace and leaves the namespace to
the bridge (zenoh-bridge-ros2dds `namespace: "/bot1"` prefixes every routed
name): so `--namespace` defaults to `/`. `--namespace /bot1` puts the node in
/bot1 (its topics become /bot1/cmd_vel, /bot1/odom), as a robot configured with
a ROS namespace would be.

Environment: ROS_DOMAIN_ID is set from `--domain`; loopback-only discovery
comes from ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (set it, or pass
`--localhost`, which sets it before rclpy starts).

It runs for `--duration` s (or until SIGTERM/SIGINT) and then writes a JSON
report to `--report`: every command (monotonic receive time, value), the count
of non-zero commands, odometry messages published, the final pose; every
odometry sample it published (`odom`: monotonic time, speeds, pose, the path
length `s` travelled since start, and whether a fresh command drove the
wheels); and every command timeout (`timeouts`: the last command's arrival,
the moment 0.5 s later its wheels stopped driving, the speed then, and when
the base came to rest), all from its own integration.

Usage: create3_base.py [--namespace /] [--domain 42] [--localhost]
       [--cmd-type twist|twist-stamped] [--duration 10]
       [--x 0 --y 0 --yaw 0] --report out.json
"""

import argparse
import json
import math
import os
import signal
import sys
import time

ODOM_RATE = 20.0  # Hz, the Create 3's odometry rate
ACCEL = 0.9  # m/s², wheel acceleration limit
HALF_TRACK = 0.1175  # m, half the wheel separation (0.235 m)
ALPHA = ACCEL / HALF_TRACK  # rad/s², the matching angular acceleration limit
MAX_SPEED = 0.306  # m/s, the Create 3's top wheel speed
MAX_OMEGA = MAX_SPEED / HALF_TRACK  # rad/s
CMD_TIMEOUT = 0.5  # s without a command -> wheels stop
STEP = 0.005  # s, integration sub-step


def slew(current, target, limit, dt):
    delta = max(-limit * dt, min(limit * dt, target - current))
    return current + delta


def clamp(value, bound):
    return max(-bound, min(bound, value))


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--namespace", default="/")
    p.add_argument("--node-name", default="create3_base")
    p.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: environment, else 0)")
    p.add_argument("--localhost", action="store_true", help="ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST")
    p.add_argument("--cmd-type", choices=["twist", "twist-stamped"], default="twist")
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--x", type=float, default=0.0)
    p.add_argument("--y", type=float, default=0.0)
    p.add_argument("--yaw", type=float, default=0.0)
    p.add_argument("--report", required=True)
    args = p.parse_args()

    if args.domain is not None:
        os.environ["ROS_DOMAIN_ID"] = str(args.domain)
    if args.localhost:
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        os.environ.pop("ROS_LOCALHOST_ONLY", None)

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from geometry_msgs.msg import Twist, TwistStamped
    from nav_msgs.msg import Odometry

    rclpy.init(args=[])
    ns = "/" + args.namespace.strip("/") if args.namespace.strip("/") else "/"
    node = rclpy.create_node(args.node_name, namespace=ns)
    cmd_class = TwistStamped if args.cmd_type == "twist-stamped" else Twist

    start = time.monotonic()
    state = {
        "commands": [],
        "nonzero_commands": 0,
        "odom_published": 0,
        "cmd_topic": None,
        "odom_topic": None,
        "cmd_type": "geometry_msgs/msg/TwistStamped" if args.cmd_type == "twist-stamped" else "geometry_msgs/msg/Twist",
        "node": (ns.rstrip("/") + "/" + args.node_name),
        "domain": int(os.environ.get("ROS_DOMAIN_ID", "0")),
        "rmw": os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp (default)"),
    }
    target = {"v": 0.0, "omega": 0.0, "at": None}

    def on_cmd(msg):
        now = time.monotonic()
        twist = msg.twist if args.cmd_type == "twist-stamped" else msg
        value = {
            "linear": [twist.linear.x, twist.linear.y, twist.linear.z],
            "angular": [twist.angular.x, twist.angular.y, twist.angular.z],
        }
        if args.cmd_type == "twist-stamped":
            value["frame_id"] = msg.header.frame_id
            value["stamp"] = [msg.header.stamp.sec, msg.header.stamp.nanosec]
        state["commands"].append({"t": now, "t_rel": now - start, "value": value})
        if any(c != 0.0 for c in value["linear"] + value["angular"]):
            state["nonzero_commands"] += 1
        target["v"] = twist.linear.x
        target["omega"] = twist.angular.z
        target["at"] = now

    sub = node.create_subscription(cmd_class, "cmd_vel", on_cmd, 10)
    pub = node.create_publisher(Odometry, "odom", 10)
    state["cmd_topic"] = sub.topic_name
    state["odom_topic"] = pub.topic_name

    pose = {"x": args.x, "y": args.y, "yaw": args.yaw}
    speed = {"v": 0.0, "omega": 0.0}
    last = {"t": time.monotonic()}
    # Path length travelled, and the command timeouts (scripts/interop/ros2dds
    # run's robot-kill phase reads them): while a fresh command drives the
    # wheels `driving` is True; its going stale opens a timeout, closed when
    # both speeds reach zero.
    travel = {"s": 0.0, "driving": False}
    state["odom"] = []
    state["timeouts"] = []

    def integrate(now):
        while last["t"] + 1e-9 < now:
            dt = min(STEP, now - last["t"])
            t = last["t"] + dt
            fresh = target["at"] is not None and t - target["at"] <= CMD_TIMEOUT
            want_v = clamp(target["v"], MAX_SPEED) if fresh else 0.0
            want_w = clamp(target["omega"], MAX_OMEGA) if fresh else 0.0
            if travel["driving"] and not fresh:
                # Stale since exactly target["at"] + CMD_TIMEOUT (within this sub-step).
                state["timeouts"].append({"last_command_at": target["at"], "stopped_at": target["at"] + CMD_TIMEOUT,
                                          "v": speed["v"], "omega": speed["omega"], "rest_at": None})
            travel["driving"] = fresh
            speed["v"] = slew(speed["v"], want_v, ACCEL, dt)
            speed["omega"] = slew(speed["omega"], want_w, ALPHA, dt)
            yaw_mid = pose["yaw"] + 0.5 * speed["omega"] * dt
            pose["x"] += speed["v"] * math.cos(yaw_mid) * dt
            pose["y"] += speed["v"] * math.sin(yaw_mid) * dt
            pose["yaw"] += speed["omega"] * dt
            travel["s"] += abs(speed["v"]) * dt
            last["t"] = t
            timeouts = state["timeouts"]
            if (timeouts and timeouts[-1]["rest_at"] is None and not fresh
                    and speed["v"] == 0.0 and speed["omega"] == 0.0):
                timeouts[-1]["rest_at"] = t

    def on_tick():
        integrate(time.monotonic())
        odom = Odometry()
        odom.header.stamp = node.get_clock().now().to_msg()
        odom.header.frame_id = "odom"
        odom.child_frame_id = "base_link"
        odom.pose.pose.position.x = pose["x"]
        odom.pose.pose.position.y = pose["y"]
        odom.pose.pose.orientation.z = math.sin(pose["yaw"] / 2)
        odom.pose.pose.orientation.w = math.cos(pose["yaw"] / 2)
        odom.twist.twist.linear.x = speed["v"]
        odom.twist.twist.angular.z = speed["omega"]
        pub.publish(odom)
        state["odom_published"] += 1
        state["odom"].append({"t": last["t"], "v": speed["v"], "omega": speed["omega"], "x": pose["x"],
                              "y": pose["y"], "yaw": pose["yaw"], "s": travel["s"], "driving": travel["driving"]})

    node.create_timer(1.0 / ODOM_RATE, on_tick)

    stop = {"flag": False}
    signal.signal(signal.SIGTERM, lambda *_: stop.update(flag=True))
    signal.signal(signal.SIGINT, lambda *_: stop.update(flag=True))

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print(f"create3_base: node {state['node']} on domain {state['domain']}: "
          f"{state['cmd_topic']} ({state['cmd_type']}), {state['odom_topic']}", file=sys.stderr, flush=True)
    while not stop["flag"] and time.monotonic() - start < args.duration:
        executor.spin_once(timeout_sec=0.05)

    integrate(time.monotonic())
    state["final_pose"] = dict(pose)
    state["final_speed"] = dict(speed)
    state["elapsed"] = time.monotonic() - start
    with open(args.report, "w", encoding="utf-8") as f:
        json.dump(state, f, indent=1)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
