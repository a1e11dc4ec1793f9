#!/usr/bin/env python3
"""A ROS 2 MCAP bag of a simulated lagged velocity base, for `echelon identify`.

The base follows its command through two first-order lags,
`tau_v dv/dt + v = v_cmd` and `tau_omega domega/dt + omega = omega_cmd`,
integrated exactly on a 1 ms grid (the command is piecewise constant). The
command is published at --cmd-rate on /robot1/cmd_vel
(`geometry_msgs/msg/TwistStamped`, or `Twist` with --twist): random steps of
v in [-0.5, 0.5] m/s and of omega in [-1.2, 1.2] rad/s, each held 0.3-1.5 s,
with a chirp of omega in the middle third. Odometry (`nav_msgs/msg/Odometry`,
body twist, pose integrated) is published on /robot1/odom at --odom-rate,
offset by 7 ms from the commands, with Gaussian noise of --noise-v (m/s) and
--noise-omega (rad/s) on the twist. With --a-max / --alpha-max the base's
rates are also limited (`dv/dt = clamp((v_cmd - v)/tau_v, +-a_max)`, as
diff_drive_controller's acceleration limits act; integrated exactly), and with
--dead-time a command takes effect that long after it is published (a
transport delay: the base's driver, its bus, its motor controller).

Messages are serialized by rclpy's `serialize_message` (the ROS 2 Jazzy
wheels, Fast-CDR) and written with foxglove's `mcap` writer as rosbag2 writes
them: schema encoding `ros2msg` (the full definition text built by
msg_definitions.py), message encoding `cdr`. Stamps start at 1.7e9 s (a wall
clock); each message's log time is its stamp plus 2 ms.

Usage: lagged_base_bag.py OUT.mcap [--tau-v S] [--tau-omega S] [--noise-v X]
       [--noise-omega X] [--seed N] [--duration S] [--twist]
       [--a-max A] [--alpha-max A] [--dead-time S] [--odom-rate HZ]
Prints {"messages": N, "cmd": n, "odom": n}. Exit status 3 when rclpy or mcap
is missing.
"""

import argparse
import json
import math
import os
import random
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

INSTALL_HINT = (
    "ROS 2 Jazzy wheels or mcap missing: run scripts/test, or "
    "`python3 -m pip install -r scripts/requirements-test.txt` (Python 3.11)"
)

try:
    from rclpy.serialization import serialize_message
    from geometry_msgs.msg import Twist, TwistStamped
    from nav_msgs.msg import Odometry
    from mcap.writer import Writer
    import msg_definitions
except ImportError as e:  # pragma: no cover
    sys.stderr.write(f"{e}\n{INSTALL_HINT}\n")
    sys.exit(3)

EPOCH_NS = 1_700_000_000 * 10**9
LATENCY_NS = 2_000_000


def command_profile(rng, duration_ms):
    """(v, omega) per millisecond: held random steps, a chirp of omega in the middle third."""
    v = [0.0] * duration_ms
    w = [0.0] * duration_ms
    t = 500
    while t < duration_ms:
        hold = rng.randint(300, 1500)
        vs = rng.uniform(-0.5, 0.5)
        ws = rng.uniform(-1.2, 1.2)
        for k in range(t, min(t + hold, duration_ms)):
            v[k] = vs
            w[k] = ws
        t += hold
    third = duration_ms // 3
    for k in range(third, 2 * third):
        s = (k - third) / 1000.0
        w[k] = 0.8 * math.sin(2 * math.pi * (0.2 * s + 0.05 * s * s))
    # Stop at the end.
    for k in range(duration_ms - 1000, duration_ms):
        v[k] = 0.0
        w[k] = 0.0
    return v, w


def lag_step(x, u, tau, limit, h):
    """x after h s of `dx/dt = clamp((u - x)/tau, +-limit)` (u constant): at
    the limit until |u - x| = limit*tau, then the lag's exponential. A zero
    lag is an ideal axis: at u at once (through the limit, if any)."""
    if tau <= 0.0:
        if limit is None or abs(u - x) <= limit * h:
            return u
        return x + math.copysign(limit * h, u - x)
    if limit is not None and abs(u - x) > limit * tau:
        sign = 1.0 if u > x else -1.0
        t_sat = (abs(u - x) - limit * tau) / limit
        if t_sat >= h:
            return x + sign * limit * h
        x += sign * limit * t_sat
        h -= t_sat
    return u - (u - x) * math.exp(-h / tau)


def stamp(msg_header, ns):
    msg_header.stamp.sec = ns // 10**9
    msg_header.stamp.nanosec = ns % 10**9


def main():
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--tau-v", type=float, default=0.1)
    p.add_argument("--tau-omega", type=float, default=0.15)
    p.add_argument("--noise-v", type=float, default=0.01)
    p.add_argument("--noise-omega", type=float, default=0.02)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--duration", type=float, default=40.0)
    p.add_argument("--cmd-rate", type=float, default=20.0)
    p.add_argument("--odom-rate", type=float, default=50.0)
    p.add_argument("--twist", action="store_true")
    p.add_argument("--a-max", type=float, default=None)
    p.add_argument("--alpha-max", type=float, default=None)
    p.add_argument("--dead-time", type=float, default=0.0)
    a = p.parse_args()
    dead_ms = int(round(a.dead_time * 1000))

    rng = random.Random(a.seed)
    duration_ms = int(a.duration * 1000)
    profile = command_profile(rng, duration_ms)
    cmd_every = int(round(1000 / a.cmd_rate))
    odom_every = int(round(1000 / a.odom_rate))
    cmd_type = "geometry_msgs/msg/Twist" if a.twist else "geometry_msgs/msg/TwistStamped"
    defs = {t: msg_definitions.full_text(t) for t in (cmd_type, "nav_msgs/msg/Odometry")}

    with open(a.out, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="echelon lagged_base_bag.py")
        ids = {}
        for topic, ty in (("/robot1/cmd_vel", cmd_type), ("/robot1/odom", "nav_msgs/msg/Odometry")):
            sid = w.register_schema(name=ty, encoding="ros2msg", data=defs[ty].encode())
            ids[topic] = w.register_channel(topic=topic, message_encoding="cdr", schema_id=sid)

        def write(topic, ns, msg):
            w.add_message(
                channel_id=ids[topic],
                log_time=ns + LATENCY_NS,
                publish_time=ns,
                data=serialize_message(msg),
            )

        v = omega = 0.0
        x = y = theta = 0.0
        held = (0.0, 0.0)
        # Commands published, each applied dead_ms after: (apply at ms, cmd).
        pending = []
        counts = {"cmd": 0, "odom": 0}
        for k in range(duration_ms):
            ns = EPOCH_NS + k * 10**6
            if k % cmd_every == 0:
                cmd = (profile[0][k], profile[1][k])
                pending.append((k + dead_ms, cmd))
                tw = Twist()
                tw.linear.x = cmd[0]
                tw.angular.z = cmd[1]
                if a.twist:
                    msg = tw
                else:
                    msg = TwistStamped()
                    stamp(msg.header, ns)
                    msg.header.frame_id = "base_link"
                    msg.twist = tw
                write("/robot1/cmd_vel", ns, msg)
                counts["cmd"] += 1
            if k % odom_every == 7:
                o = Odometry()
                stamp(o.header, ns)
                o.header.frame_id = "odom"
                o.child_frame_id = "base_link"
                o.pose.pose.position.x = x
                o.pose.pose.position.y = y
                o.pose.pose.orientation.z = math.sin(theta / 2)
                o.pose.pose.orientation.w = math.cos(theta / 2)
                o.twist.twist.linear.x = v + rng.gauss(0.0, a.noise_v)
                o.twist.twist.angular.z = omega + rng.gauss(0.0, a.noise_omega)
                write("/robot1/odom", ns, o)
                counts["odom"] += 1
            while pending and pending[0][0] <= k:
                held = pending.pop(0)[1]
            # One exact step of the lags (and limits) over the next millisecond.
            v = lag_step(v, held[0], a.tau_v, a.a_max, 0.001)
            omega = lag_step(omega, held[1], a.tau_omega, a.alpha_max, 0.001)
            x += 0.001 * v * math.cos(theta)
            y += 0.001 * v * math.sin(theta)
            theta += 0.001 * omega
        w.finish()
    counts["messages"] = counts["cmd"] + counts["odom"]
    print(json.dumps(counts))


if __name__ == "__main__":
    main()
