#!/usr/bin/env python3
"""The ROS 2 side of echelon's interop tests: real ROS 2 Jazzy serialization.

Uses rclpy's `serialize_message` / `deserialize_message` (Fast-CDR through the
typesupport of the ROS 2 Jazzy wheels from PyPI, see
scripts/requirements-ros2.txt). No `rclpy.init()` and no ROS installation are
needed. Environment: the `ros-wheels-bootstrapper` wheel installs a `.pth`
hook that re-executes Python once with LD_LIBRARY_PATH covering
`<prefix>/lib` and `site-packages/ros_*.libs`, so `python3 this.py` just works;
the message definitions (`share/<pkg>/msg/<Type>.json`) are under `sys.prefix`
(AMENT_PREFIX_PATH is not set by the wheels; if it is set, it is searched first).

Commands (JSON on stdin/stdout):

  check                 prints {"ok": true, "python": ..., "rclpy": ...}
  hashes                prints {"pkg/msg/Type": "RIHS01_...", ...} from the
                        installed share/<pkg>/msg/<Type>.json files
  serialize             stdin [{"type": "pkg/msg/Type", "value": {...}}, ...]
                        stdout ["<hex of serialize_message>", ...]
  deserialize           stdin [{"type": "pkg/msg/Type", "hex": "..."}, ...]
                        stdout [{...value...}, ...]

Values mirror the message fields; every float64 travels as its IEEE-754 bit
pattern (an unsigned integer), so comparisons are bit-exact (NaN, -0.0, inf).
Exit status 3 with a message on stderr when rclpy or the messages are missing.
"""

import importlib
import json
import os
import struct
import sys

TYPES = {
    "geometry_msgs/msg/PoseStamped": ("geometry_msgs", "PoseStamped"),
    "geometry_msgs/msg/PoseWithCovarianceStamped": ("geometry_msgs", "PoseWithCovarianceStamped"),
    "geometry_msgs/msg/Twist": ("geometry_msgs", "Twist"),
    "geometry_msgs/msg/TwistStamped": ("geometry_msgs", "TwistStamped"),
    "nav_msgs/msg/Odometry": ("nav_msgs", "Odometry"),
    "std_msgs/msg/Header": ("std_msgs", "Header"),
}

INSTALL_HINT = (
    "ROS 2 Jazzy wheels missing: run scripts/test, or "
    "`python3 -m pip install -r scripts/requirements-ros2.txt` (Python 3.11)"
)


def fail(message):
    sys.stderr.write(f"{message}\n{INSTALL_HINT}\n")
    sys.exit(3)


def message_class(type_name):
    try:
        pkg, name = TYPES[type_name]
    except KeyError:
        fail(f"unknown type {type_name}")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except ImportError as e:
        fail(f"cannot import {pkg}.msg: {e}")


def bits(x):
    return struct.unpack("<Q", struct.pack("<d", x))[0]


def from_bits(b):
    return struct.unpack("<d", struct.pack("<Q", b))[0]


def to_plain(msg):
    """A message as a dict, floats as bit patterns."""
    out = {}
    for field, ftype in msg.get_fields_and_field_types().items():
        v = getattr(msg, field)
        if ftype == "double":
            out[field] = bits(v)
        elif ftype.startswith("double["):
            out[field] = [bits(x) for x in v]
        elif ftype in ("int32", "uint32"):
            out[field] = int(v)
        elif ftype == "string":
            out[field] = v
        else:
            out[field] = to_plain(v)
    return out


def fill(msg, value):
    """Sets the fields of `msg` from a dict made by `to_plain`."""
    for field, ftype in msg.get_fields_and_field_types().items():
        v = value[field]
        if ftype == "double":
            setattr(msg, field, from_bits(v))
        elif ftype.startswith("double["):
            setattr(msg, field, [from_bits(x) for x in v])
        elif ftype in ("int32", "uint32", "string"):
            setattr(msg, field, v)
        else:
            fill(getattr(msg, field), v)
    return msg


def share_dirs():
    dirs = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    dirs.append(sys.prefix)
    return [os.path.join(d, "share") for d in dirs]


def hashes():
    out = {}
    for type_name, (pkg, name) in TYPES.items():
        for share in share_dirs():
            path = os.path.join(share, pkg, "msg", f"{name}.json")
            if os.path.exists(path):
                with open(path, encoding="utf-8") as f:
                    doc = json.load(f)
                for entry in doc["type_hashes"]:
                    if entry["type_name"] == type_name:
                        out[type_name] = entry["hash_string"]
                break
        else:
            fail(f"no {pkg}/msg/{name}.json under {share_dirs()}")
    return out


def main():
    if len(sys.argv) != 2:
        sys.stderr.write(__doc__)
        sys.exit(2)
    command = sys.argv[1]
    try:
        import rclpy
        from rclpy.serialization import deserialize_message, serialize_message
    except ImportError as e:
        fail(f"cannot import rclpy: {e}")
    if command == "check":
        for type_name in TYPES:
            message_class(type_name)
        version = getattr(rclpy, "__version__", None)
        if version is None:
            from importlib.metadata import version as dist_version

            version = dist_version("ros-rclpy")
        result = {"ok": True, "python": sys.version.split()[0], "rclpy": version}
    elif command == "hashes":
        result = hashes()
    elif command == "serialize":
        result = [
            serialize_message(fill(message_class(item["type"])(), item["value"])).hex()
            for item in json.load(sys.stdin)
        ]
    elif command == "deserialize":
        result = [
            to_plain(deserialize_message(bytes.fromhex(item["hex"]), message_class(item["type"])))
            for item in json.load(sys.stdin)
        ]
    else:
        sys.stderr.write(__doc__)
        sys.exit(2)
    json.dump(result, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
