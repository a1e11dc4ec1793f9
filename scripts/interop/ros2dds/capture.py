#!/usr/bin/env python3
"""Records what a zenoh-bridge-ros2dds shows a Zenoh client: the golden
captures of echelon's bridge interop (crates/echelon-fleet/tests/fixtures/
ros2dds/*.jsonl, see the README there).

A Zenoh client (eclipse-zenoh) connects to the bridge's endpoint and, for
`--duration` s, records as JSON lines:

- every sample on `**` (key, payload hex, encoding, attachment hex or null,
  kind) from the bridge: the first `--max-per-key` of each key, then only
  those whose size changes (or, for payloads of at most 16 bytes, whose
  bytes change): state changes, up to as many again; so a capture stays
  small;
- every liveliness token under `@/**` and `@/*/@ros2_lv/**` (a `**`
  never matches a verbatim chunk such as `@ros2_lv`): those alive at start
  (`liveliness().get`, source "get") and every appearance/disappearance
  afterwards (`liveliness().declare_subscriber(history=True)`, source "sub";
  history replays the tokens alive when it is declared). The bridge's tokens
  are `@/<zid>/@ros2_lv/<MP|MS|SS|SC|AS|AC>/<key>/<type>[/<qos>]`, with `/`
  escaped as `§` in the key and type chunks.

With `--put-cmd V,W` it also plays echelon's part: once the bridge announces
the subscriber route for `--cmd-key` (its "MS" token), it puts a
geometry_msgs/msg/Twist (or TwistStamped, `--cmd-type`) with linear.x = V and
angular.z = W on that key at 10 Hz for `--put-for` s, payload serialized by
rclpy (full CDR with its 4-byte header, no attachment: what the bridge
expects). The DDS base's report then shows whether the commands arrived
(Zenoh -> DDS).

Lines: {"type": "meta", ...} first, then {"type": "token"|"sample"|"put", "t":
seconds since start, ...}. `--admin` adds the bridge's admin space
(`@/*/ros2/**`: nodes, routes) as {"type": "admin"} lines at the end.

Usage: capture.py --connect tcp/127.0.0.1:7460 [--duration 5]
       [--max-per-key 5] [--put-cmd 0.2,0.1 --cmd-key bot1/cmd_vel
       --cmd-type twist|twist-stamped --put-for 2] [--admin] --out capture.jsonl
"""

import argparse
import json
import sys
import threading
import time

LIVELINESS_KEYS = ["@/**", "@/*/@ros2_lv/**"]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", default="tcp/127.0.0.1:7460")
    p.add_argument("--duration", type=float, default=5.0)
    p.add_argument("--wait-for", action="append", default=[],
                   help="substring of a token to wait for (up to --wait-timeout s) before the clock starts")
    p.add_argument("--wait-timeout", type=float, default=20.0)
    p.add_argument("--max-per-key", type=int, default=5)
    p.add_argument("--put-cmd", default=None, help="V,W: put cmd_vel commands (linear.x, angular.z)")
    p.add_argument("--cmd-key", default="bot1/cmd_vel")
    p.add_argument("--cmd-type", choices=["twist", "twist-stamped"], default="twist")
    p.add_argument("--put-for", type=float, default=2.0)
    p.add_argument("--admin", action="store_true")
    p.add_argument("--out", required=True)
    args = p.parse_args()

    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
    session = zenoh.open(conf)

    lock = threading.Lock()
    lines = []
    per_key = {}
    kept = {}
    last_payload = {}
    tokens_alive = set()
    t0 = {"t": time.monotonic()}

    def now():
        return round(time.monotonic() - t0["t"], 3)

    def hexdump(zbytes):
        return None if zbytes is None else zbytes.to_bytes().hex()

    def on_sample(sample):
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        with lock:
            n = per_key.get(key, 0)
            per_key[key] = n + 1
            # The first --max-per-key samples of each key, and then (up to as
            # many again) each sample whose size differs from the last one
            # recorded: a state change such as a hazard vector that fills up.
            last = last_payload.get(key)
            # Small payloads (a Bool: no timestamp in them) count as changed
            # whenever they differ.
            changed = last is not None and (len(payload) != len(last) or (len(payload) <= 16 and payload != last))
            if n >= args.max_per_key and not (changed and kept.get(key, 0) < 2 * args.max_per_key):
                return
            kept[key] = kept.get(key, 0) + 1
            last_payload[key] = payload
            lines.append({
                "type": "sample",
                "t": now(),
                "key": key,
                "kind": str(sample.kind).split(".")[-1].lower(),
                "encoding": str(sample.encoding),
                "payload_hex": payload.hex(),
                "attachment_hex": hexdump(sample.attachment),
            })

    def on_token(source):
        def cb(sample):
            key = str(sample.key_expr)
            kind = str(sample.kind).split(".")[-1].lower()
            with lock:
                if kind == "put":
                    tokens_alive.add(key)
                else:
                    tokens_alive.discard(key)
                lines.append({"type": "token", "t": now(), "source": source, "kind": kind, "key": key})
        return cb

    # Remote samples only: capture.py's own cmd_vel puts are recorded as
    # "put" lines, not looped back as samples.
    sub = session.declare_subscriber("**", on_sample, allowed_origin=zenoh.Locality.REMOTE)
    # `**` matches no verbatim chunk (one starting with `@`): the bridge's
    # `@ros2_lv` needs its own expression.
    lv_subs = [session.liveliness().declare_subscriber(ke, on_token("sub"), history=True)
               for ke in LIVELINESS_KEYS]
    for ke in LIVELINESS_KEYS:
        for reply in session.liveliness().get(ke, timeout=2.0):
            if reply.ok is not None:
                on_token("get")(reply.ok)

    # Wait for the tokens the caller expects (the bridge discovers DDS
    # entities asynchronously), then start the clock.
    deadline = time.monotonic() + args.wait_timeout
    missing = list(args.wait_for)
    while missing and time.monotonic() < deadline:
        with lock:
            missing = [w for w in args.wait_for if not any(w in k for k in tokens_alive)]
        if missing:
            time.sleep(0.1)
    if missing:
        print(f"capture.py: tokens never seen: {missing}", file=sys.stderr, flush=True)

    publisher = None
    put_payload = None
    if args.put_cmd:
        from rclpy.serialization import serialize_message
        from geometry_msgs.msg import Twist, TwistStamped
        v, w = (float(x) for x in args.put_cmd.split(","))
        msg = TwistStamped() if args.cmd_type == "twist-stamped" else Twist()
        twist = msg.twist if args.cmd_type == "twist-stamped" else msg
        twist.linear.x = v
        twist.angular.z = w
        if args.cmd_type == "twist-stamped":
            msg.header.frame_id = "base_link"
        put_payload = serialize_message(msg)
        publisher = session.declare_publisher(args.cmd_key)

    start = time.monotonic()
    puts = 0
    while time.monotonic() - start < args.duration:
        if publisher is not None and time.monotonic() - start < args.put_for:
            publisher.put(put_payload)
            puts += 1
            with lock:
                if puts <= args.max_per_key:
                    lines.append({"type": "put", "t": now(), "key": args.cmd_key,
                                  "payload_hex": put_payload.hex(), "encoding": None, "attachment_hex": None})
        time.sleep(0.1)

    admin = []
    if args.admin:
        for reply in session.get("@/*/ros2/**", timeout=3.0):
            if reply.ok is not None:
                try:
                    value = json.loads(reply.ok.payload.to_bytes())
                except ValueError:
                    value = reply.ok.payload.to_bytes().hex()
                admin.append({"type": "admin", "key": str(reply.ok.key_expr), "value": value})

    sub.undeclare()
    for lv_sub in lv_subs:
        lv_sub.undeclare()
    session.close()

    with lock:
        meta = {
            "type": "meta",
            "tool": "scripts/interop/ros2dds/capture.py",
            "zenoh_python": getattr(zenoh, "__version__", "1.10.2"),
            "connect": args.connect,
            "duration": args.duration,
            "max_per_key": args.max_per_key,
            "samples_seen_per_key": dict(sorted(per_key.items())),
            "puts": puts,
            "cmd_key": args.cmd_key if args.put_cmd else None,
            "cmd_type": args.cmd_type if args.put_cmd else None,
        }
        out = [meta] + lines + sorted(admin, key=lambda a: a["key"])
    with open(args.out, "w", encoding="utf-8") as f:
        for line in out:
            f.write(json.dumps(line, ensure_ascii=False, sort_keys=True) + "\n")
    print(f"capture.py: {len(out)} lines, samples per key {meta['samples_seen_per_key']}, {puts} puts",
          file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
