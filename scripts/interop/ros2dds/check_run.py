#!/usr/bin/env python3
"""The Python side of scripts/interop/ros2dds/run: watches the real
zenoh-bridge-ros2dds while echelon drives a Create 3 behind it, times the
operator's commands, and checks each phase's outcome.

Subcommands:

  watch --connect EP --ns bot1 --log FILE --flags DIR
      A Zenoh client of the bridge's router. Appends one JSON line per
      sample of `<ns>/cmd_vel` (echelon's commands, as the bridge receives
      them), `<ns>/hazard_detection` and `<ns>/odom` (as the bridge delivers
      them from DDS) to FILE, each with `t`, time.monotonic() on arrival (the
      clock create3_base.py stamps its commands with: one clock per host).
      Writes flag files into DIR as things happen: `graph` once the bridge's
      liveliness tokens announce the routes (MS cmd_vel, MP odom, MP
      hazard_detection), `moving` at the first non-zero command, `bump` at the
      first hazard vector with a BUMP, `clear` at the first vector without a
      stopping hazard after that. Runs until SIGTERM/SIGINT.
      With --no-cmd-vel it does not subscribe to `<ns>/cmd_vel` (a subscriber
      there is a reader of echelon's commands: it would hide the bridge's
      own from the robot's output watchdog); it declares a publisher on the
      key instead, never putting anything, and logs its matching status
      (`matching`: whether a subscriber, the bridge's route, is there, as
      the robot's cmd_vel publisher sees it), and sets `moving` at the first
      odometry with a non-zero speed. Every line also has `wall`,
      time.time() (the clock of the collector's fleet.mcap log times).

  kill --pid PID --record FILE [--signal KILL|TERM]
      Sends SIGKILL (or SIGTERM) to PID and records the monotonic and wall
      times just before it (JSON).

  exec --record FILE -- CMD...
      Runs CMD, records its monotonic start and end, exit status, stdout and
      stderr in FILE (JSON), echoes its output, and exits with its status.

  put-resume --connect ROUTER --fleet NAME --token-file FILE --record FILE
      Plays an operator that skips `fleet resume`'s hazard check: asks the
      fleet's latches (`echelon/<fleet>/latch/**`) for the highest command
      number, puts a resume numbered one past it, signed with the operator
      token in --token-file (`fleet up`'s OUT/operator-token: HMAC-SHA256
      as crates/echelon-fleet/src/command.rs makes it), straight on
      `echelon/<fleet>/command`, and 0.5 s later asks the latches again.
      Records both answers (and the times) in FILE: the robot itself must
      refuse it while its base reports a hazard.

  check-converge | check-hazard | check-graph | check-robot-kill |
  check-base-kill  (see --help of each)
      Read the reports and logs of one phase, print the measured numbers,
      append them to --summary (JSON), and exit 1 naming every failed check.
"""

import argparse
import datetime
import hashlib
import hmac
import json
import os
import re
import signal
import struct
import subprocess
import sys
import threading
import time

STOPPING = {1: "BUMP", 2: "CLIFF", 3: "STALL", 4: "WHEEL_DROP"}
# create3_base.py's Create 3: odometry rate, command timeout, wheel acceleration.
ODOM_RATE = 20.0
CMD_TIMEOUT = 0.5
ACCEL = 0.9
KINDS = {0: "BACKUP_LIMIT", 1: "BUMP", 2: "CLIFF", 3: "STALL", 4: "WHEEL_DROP", 5: "OBJECT_PROXIMITY"}


# --------------------------------------------------------------------------
# CDR decoding (plain CDR little-endian, 4-byte encapsulation header)


class Cdr:
    def __init__(self, payload):
        if payload[:2] != b"\x00\x01":
            raise ValueError(f"not CDR little-endian: {payload[:4].hex()}")
        self.b = payload[4:]
        self.o = 0

    def align(self, n):
        self.o += (-self.o) % n

    def u8(self):
        v = self.b[self.o]
        self.o += 1
        return v

    def u32(self):
        self.align(4)
        v = struct.unpack_from("<I", self.b, self.o)[0]
        self.o += 4
        return v

    def f64(self):
        self.align(8)
        v = struct.unpack_from("<d", self.b, self.o)[0]
        self.o += 8
        return v

    def string(self):
        n = self.u32()
        s = self.b[self.o:self.o + n - 1].decode()
        self.o += n
        return s

    def header(self):
        sec = self.u32()
        nsec = self.u32()
        return sec, nsec, self.string()


def decode_twist(payload):
    c = Cdr(payload)
    lin = [c.f64() for _ in range(3)]
    ang = [c.f64() for _ in range(3)]
    return {"linear": lin, "angular": ang}


def decode_hazards(payload):
    c = Cdr(payload)
    c.header()
    kinds = []
    for _ in range(c.u32()):
        c.header()
        kinds.append(KINDS.get(c.u8(), "UNKNOWN"))
    return kinds


def decode_odom_twist(payload):
    c = Cdr(payload)
    c.header()
    c.string()  # child_frame_id
    for _ in range(3 + 4 + 36):  # pose: position, orientation, covariance
        c.f64()
    v = c.f64()
    c.f64()
    c.f64()
    c.f64()
    c.f64()
    w = c.f64()
    return v, w


def nonzero(value):
    return any(x != 0.0 for x in value["linear"] + value["angular"])


# --------------------------------------------------------------------------
# watch


def watch(args):
    import zenoh

    os.makedirs(args.flags, exist_ok=True)
    lock = threading.Lock()
    out = open(args.log, "a", encoding="utf-8")
    state = {"bump": False, "clear": False, "moving": False, "graph": False}

    def flag(name, t, extra=None):
        with open(os.path.join(args.flags, name + ".tmp"), "w", encoding="utf-8") as f:
            json.dump({"t": t, **(extra or {})}, f)
        os.replace(os.path.join(args.flags, name + ".tmp"), os.path.join(args.flags, name))

    def write(line):
        line["wall"] = time.time()
        with lock:
            out.write(json.dumps(line) + "\n")
            out.flush()

    cmd_key, hazard_key, odom_key = (f"{args.ns}/cmd_vel", f"{args.ns}/hazard_detection", f"{args.ns}/odom")

    def on_sample(sample):
        t = time.monotonic()
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        try:
            if key == cmd_key:
                value = decode_twist(payload)
                write({"t": t, "topic": "cmd_vel", "value": value})
                if nonzero(value) and not state["moving"]:
                    state["moving"] = True
                    flag("moving", t)
            elif key == hazard_key:
                kinds = decode_hazards(payload)
                write({"t": t, "topic": "hazards", "kinds": kinds})
                stopping = [k for k in kinds if k in STOPPING.values()]
                if "BUMP" in kinds and not state["bump"]:
                    state["bump"] = True
                    flag("bump", t)
                elif state["bump"] and not stopping and not state["clear"]:
                    state["clear"] = True
                    flag("clear", t)
            elif key == odom_key:
                v, w = decode_odom_twist(payload)
                write({"t": t, "topic": "odom", "v": v, "w": w})
                if args.no_cmd_vel and (v != 0.0 or w != 0.0) and not state["moving"]:
                    state["moving"] = True
                    flag("moving", t)
        except (ValueError, IndexError, struct.error) as e:
            write({"t": t, "topic": "undecodable", "key": key, "error": str(e), "hex": payload.hex()})

    want = [f"/MS/{args.ns}§cmd_vel/", f"/MP/{args.ns}§odom/", f"/MP/{args.ns}§hazard_detection/"]
    tokens = set()

    def on_token(sample):
        key = str(sample.key_expr)
        kind = str(sample.kind).split(".")[-1].lower()
        with lock:
            (tokens.add if kind == "put" else tokens.discard)(key)
            complete = all(any(w in k for k in tokens) for w in want)
        write({"t": time.monotonic(), "topic": "token", "kind": kind, "key": key})
        if complete and not state["graph"]:
            state["graph"] = True
            flag("graph", time.monotonic())

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
    session = zenoh.open(conf)
    keys = (hazard_key, odom_key) if args.no_cmd_vel else (cmd_key, hazard_key, odom_key)
    subs = [session.declare_subscriber(k, on_sample) for k in keys]
    publisher = listener = None
    if args.no_cmd_vel:
        def on_matching(status):
            write({"t": time.monotonic(), "topic": "matching", "matching": status.matching})

        publisher = session.declare_publisher(cmd_key)
        listener = publisher.declare_matching_listener(on_matching)
        write({"t": time.monotonic(), "topic": "matching", "matching": publisher.matching_status.matching, "initial": True})
    lv = session.liveliness().declare_subscriber("@/*/@ros2_lv/**", on_token, history=True)

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    flag("watching", time.monotonic())
    while not stop.is_set():
        stop.wait(0.2)
    lv.undeclare()
    for s in subs:
        s.undeclare()
    if listener is not None:
        listener.undeclare()
        publisher.undeclare()
    session.close()
    out.close()


# --------------------------------------------------------------------------
# exec


def exec_(args):
    cmd = args.cmd[1:] if args.cmd and args.cmd[0] == "--" else args.cmd
    start = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True)
    end = time.monotonic()
    with open(args.record, "w", encoding="utf-8") as f:
        json.dump({"cmd": cmd, "start": start, "end": end, "rc": p.returncode,
                   "stdout": p.stdout, "stderr": p.stderr}, f, indent=1)
    sys.stdout.write(p.stdout)
    sys.stderr.write(p.stderr)
    sys.exit(p.returncode)


# --------------------------------------------------------------------------
# kill


def kill(args):
    t = time.monotonic()
    wall = time.time()
    os.kill(args.pid, getattr(signal, "SIG" + args.signal))
    with open(args.record, "w", encoding="utf-8") as f:
        json.dump({"pid": args.pid, "signal": args.signal, "t": t, "wall": wall}, f, indent=1)


# --------------------------------------------------------------------------
# put-resume


def command_proof(token_hex, command):
    """The operator token's proof of `command` (echelon-fleet's command.rs):
    HMAC-SHA256, keyed by the token's 16 bytes, of a fixed prefix, the
    version, order, seq, stamp, sender and reason (integers big-endian,
    each text preceded by its length in bytes, 4 bytes big-endian)."""

    def text(s):
        b = s.encode()
        return struct.pack(">I", len(b)) + b

    data = (b"echelon.FleetCommand.proof.v1\0" + struct.pack(">I", command["version"])
            + text(command["order"]) + struct.pack(">QQ", command["seq"], command["stamp_unix_ns"])
            + text(command["by"]) + text(command["reason"]))
    return hmac.new(bytes.fromhex(token_hex), data, hashlib.sha256).hexdigest()


def put_resume(args):
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
    session = zenoh.open(conf)

    def latches():
        answers = {}
        for reply in session.get(f"echelon/{args.fleet}/latch/**", timeout=1.0):
            if reply.ok is not None:
                answers[str(reply.ok.key_expr)] = json.loads(reply.ok.payload.to_bytes())
        return answers

    before = latches()
    seq = max((a["command"]["seq"] for a in before.values() if a.get("command")), default=0) + 1
    command = {"version": 1, "order": "resume", "seq": seq, "stamp_unix_ns": time.time_ns(),
               "by": "operator", "reason": "interop: a resume that skips fleet resume's hazard check"}
    with open(args.token_file, encoding="utf-8") as f:
        command["proof"] = command_proof(f.read().strip(), command)
    put_at = time.monotonic()
    session.put(f"echelon/{args.fleet}/command", json.dumps(command).encode())
    time.sleep(0.5)
    after = latches()
    session.close()
    with open(args.record, "w", encoding="utf-8") as f:
        json.dump({"put_at": put_at, "end": time.monotonic(), "command": command, "before": before,
                   "after": after}, f, indent=1)
    print(json.dumps({"command": command, "after": after}))


# --------------------------------------------------------------------------
# checks


def read_jsonl(path):
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def last_json_line(path):
    with open(path, encoding="utf-8") as f:
        lines = [line for line in f if line.strip().startswith("{")]
    return json.loads(lines[-1])


def quantile(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, max(0, int(round(q * (len(xs) - 1)))))] if xs else float("nan")


def delivery(watched, base_cmds):
    """Zenoh -> DDS delivery delays: each command as the watcher saw it on
    the bridge's router, matched in order and by value with the base's
    receipt. Returns (delays, matched, mismatched)."""
    seen = [w for w in watched if w["topic"] == "cmd_vel"]
    delays = []
    mismatched = 0
    j = 0
    for c in base_cmds:
        # The next watched command with the same value (skipping any the base
        # never got).
        k = j
        while k < len(seen) and seen[k]["value"] != c["value"]:
            k += 1
        if k == len(seen):
            mismatched += 1
            continue
        delays.append(c["t"] - seen[k]["t"])
        j = k + 1
    return delays, len(delays), mismatched


class Checks:
    def __init__(self, phase):
        self.phase = phase
        self.failed = []
        self.numbers = {}

    def check(self, ok, what):
        print(f"  [{'ok' if ok else 'FAIL'}] {what}")
        if not ok:
            self.failed.append(what)
        return ok

    def finish(self, summary_path):
        summary = {}
        if summary_path and os.path.exists(summary_path):
            with open(summary_path, encoding="utf-8") as f:
                summary = json.load(f)
        summary[self.phase] = {"ok": not self.failed, "failed": self.failed, **self.numbers}
        if summary_path:
            with open(summary_path, "w", encoding="utf-8") as f:
                json.dump(summary, f, indent=1)
        if self.failed:
            print(f"{self.phase}: FAILED: " + "; ".join(self.failed))
            sys.exit(1)
        print(f"{self.phase}: passed")


def fmt_cmd(value):
    return f"v={value['linear'][0]:.4f} m/s, w={value['angular'][2]:.4f} rad/s"


def check_converge(args):
    ch = Checks("converge")
    base = json.load(open(args.base, encoding="utf-8"))
    robot = last_json_line(args.robot_report)
    watched = read_jsonl(args.watch)
    cmds = base["commands"]
    sent = robot["ros2"]["cmd_sent"]
    expected = args.duration * args.control_rate
    delays, matched, _ = delivery(watched, cmds)
    err = robot["final_error"]
    n = ch.numbers
    n.update({
        "cmd_sent_by_echelon": sent,
        "cmd_received_by_base": len(cmds),
        "nonzero_received": base["nonzero_commands"],
        "last_command": cmds[-1]["value"] if cmds else None,
        "final_error_m": err,
        "final_pose_base": base["final_pose"],
        "final_state_echelon": robot["final_state"],
        "odom_accepted": robot["ros2"]["odom_accepted"],
        "odom_refused": robot["ros2"]["odom_received"] - robot["ros2"]["odom_accepted"],
        "delivery_zenoh_to_dds_s": {"p50": quantile(delays, 0.5), "max": max(delays) if delays else None,
                                    "matched": matched},
    })
    print(f"converge: echelon sent {sent} commands, the base received {len(cmds)} "
          f"({base['nonzero_commands']} non-zero); last {fmt_cmd(cmds[-1]['value']) if cmds else 'none'}; "
          f"final error {err * 1e6:.1f} um; odometry accepted {n['odom_accepted']}, refused {n['odom_refused']}; "
          f"bridge -> base delivery p50 {quantile(delays, 0.5) * 1000:.1f} ms, max {max(delays, default=float('nan')) * 1000:.1f} ms")
    ch.check(len(cmds) >= 0.8 * expected,
             f"the base received many commands: {len(cmds)} >= 80% of {expected:.0f} ({args.duration} s at {args.control_rate} Hz)")
    ch.check(len(cmds) >= 0.98 * sent, f"the base received what echelon sent: {len(cmds)} of {sent}")
    ch.check(bool(cmds) and not nonzero(cmds[-1]["value"]), "the last command the base received is zero")
    ch.check(err < args.max_error, f"final tracking error {err * 1e6:.1f} um < {args.max_error * 1000:.0f} mm")
    ch.check(n["odom_refused"] == 0, f"no odometry refused ({n['odom_refused']})")
    ch.finish(args.summary)


def check_hazard(args):
    ch = Checks("hazard")
    base = json.load(open(args.base, encoding="utf-8"))
    hazard_node = json.load(open(args.hazard_node, encoding="utf-8"))
    robot = last_json_line(args.robot_report)
    watched = read_jsonl(args.watch)
    refused = json.load(open(args.refused, encoding="utf-8"))
    resumed = json.load(open(args.resumed, encoding="utf-8"))
    raw = json.load(open(args.raw_resume, encoding="utf-8"))
    cmds = base["commands"]
    period = 1.0 / args.control_rate

    vectors = [w for w in watched if w["topic"] == "hazards"]
    bump_at = next((w["t"] for w in vectors if "BUMP" in w["kinds"]), None)
    clear_at = next((w["t"] for w in vectors if bump_at and w["t"] > bump_at
                     and not any(k in STOPPING.values() for k in w["kinds"])), None)
    if not ch.check(bump_at is not None, "the bridge delivered a BUMP"):
        ch.finish(args.summary)
    delays, matched, _ = delivery([w for w in watched if w["t"] < bump_at], [c for c in cmds if c["t"] < bump_at])
    margin = (max(delays) if delays else 0.0) + args.slack
    deadline = bump_at + period + margin
    moving_before = [c for c in cmds if nonzero(c["value"]) and c["t"] < bump_at]
    last_nonzero_before_resume = max((c["t"] for c in cmds if nonzero(c["value"]) and c["t"] < resumed["start"]),
                                     default=None)
    first_zero = next((c["t"] for c in cmds if c["t"] > bump_at and not nonzero(c["value"])), None)
    raw_after = raw["after"].get(f"echelon/{args.fleet}/latch/robot/1")
    nonzero_late = [c for c in cmds if nonzero(c["value"]) and deadline < c["t"] < resumed["start"]]
    after_resume = [c for c in cmds if nonzero(c["value"]) and c["t"] > resumed["start"]]
    odom = [w for w in watched if w["topic"] == "odom"]
    # Standing still: every odometry between the bump (plus the time the base
    # takes to brake, 0.306 m/s at 0.9 m/s^2 < 0.35 s, plus the deadline) and
    # the successful resume.
    still_from = deadline + 0.5
    moving_odom = [o for o in odom if still_from < o["t"] < resumed["start"] and (abs(o["v"]) > 1e-6 or abs(o["w"]) > 1e-6)]
    events = robot["hazards"]["events"]
    bumps = [e for e in events if e["hazard"] == "BUMP"]
    commands = robot["commands"]
    n = ch.numbers
    n.update({
        "bump_delivered_rel_s": None,
        "control_period_s": period,
        "delivery_margin_s": margin,
        "delivery_zenoh_to_dds_s": {"p50": quantile(delays, 0.5), "max": max(delays) if delays else None,
                                    "matched": matched},
        "nonzero_before_bump": len(moving_before),
        "last_nonzero_after_bump_s": None if last_nonzero_before_resume is None else last_nonzero_before_resume - bump_at,
        "deadline_after_bump_s": deadline - bump_at,
        "first_zero_after_bump_s": None if first_zero is None else first_zero - bump_at,
        "raw_resume": {"seq": raw["command"]["seq"], "after_bump_s": raw["put_at"] - bump_at,
                       "robot_latch_after": raw_after},
        "nonzero_after_deadline_before_resume": len(nonzero_late),
        "odom_moving_while_stopped": len(moving_odom),
        "bump_cleared_after_s": None if clear_at is None else clear_at - bump_at,
        "refused_resume": {"rc": refused["rc"], "after_bump_s": refused["start"] - bump_at,
                           "stderr": refused["stderr"].strip()},
        "resume": {"rc": resumed["rc"], "after_clear_s": None if clear_at is None else resumed["start"] - clear_at,
                   "stdout": resumed["stdout"].strip()[-400:]},
        "nonzero_after_resume": len(after_resume),
        "first_nonzero_after_resume_s": (after_resume[0]["t"] - resumed["start"]) if after_resume else None,
        "robot_hazards": robot["hazards"],
        "robot_commands": commands,
        "hazard_node_transitions": hazard_node["hazard"]["transitions"],
        "cmd_received_by_base": len(cmds),
        "last_command": cmds[-1]["value"] if cmds else None,
        "final_error_m": robot["final_error"],
    })
    if moving_before:
        n["bump_delivered_rel_s"] = bump_at - moving_before[0]["t"]
    lnz = n["last_nonzero_after_bump_s"]
    print(f"hazard: {len(moving_before)} non-zero commands before the BUMP; the bridge delivered it "
          f"{n['bump_delivered_rel_s'] or float('nan'):.2f} s after the base's first non-zero command; "
          f"last non-zero command at the base {lnz * 1000 if lnz is not None else float('nan'):+.1f} ms after it, "
          f"first zero {(n['first_zero_after_bump_s'] or float('nan')) * 1000:+.1f} ms "
          f"(limit {(deadline - bump_at) * 1000:.1f} ms = period {period * 1000:.0f} ms + delivery margin "
          f"{margin * 1000:.1f} ms: max measured bridge->base delay {max(delays, default=0) * 1000:.1f} ms + "
          f"{args.slack * 1000:.0f} ms slack); odometry moving while stopped: {len(moving_odom)} samples")
    print(f"hazard: robot events {bumps}; commands {commands}")
    print(f"hazard: refused resume rc={refused['rc']} {refused['start'] - bump_at:.2f} s after the BUMP: "
          f"{refused['stderr'].strip()}")
    print(f"hazard: a resume put straight on the command key {raw['put_at'] - bump_at:.2f} s after the BUMP; "
          f"robot/1's latch then answered {raw_after}")
    print(f"hazard: resume rc={resumed['rc']} "
          f"{(resumed['start'] - clear_at) if clear_at else float('nan'):.2f} s after the clearing; "
          f"{len(after_resume)} non-zero commands after it, the first "
          f"{(n['first_nonzero_after_resume_s'] or float('nan')) * 1000:.0f} ms after the resume started")

    ch.check(len(moving_before) >= args.control_rate * 2,
             f"echelon drove the base before the BUMP ({len(moving_before)} non-zero commands >= {2 * args.control_rate:.0f})")
    ch.check(lnz is not None and lnz <= deadline - bump_at,
             f"no non-zero command reached the base later than {(deadline - bump_at) * 1000:.1f} ms after the BUMP "
             f"(last: {lnz * 1000 if lnz is not None else float('nan'):+.1f} ms)")
    ch.check(not nonzero_late, f"nothing non-zero reached the base between then and the resume ({len(nonzero_late)})")
    ch.check(not moving_odom, f"the base's odometry stood still from {still_from - bump_at:.2f} s after the BUMP "
             f"until the resume ({len(moving_odom)} moving samples)")
    ch.check(commands["stops"] >= 1, f"the robot's report counts a fleet stop (commands.stops = {commands['stops']})")
    ch.check(len(bumps) >= 1 and bumps[0].get("cleared") is not None and bumps[0]["cleared"] > bumps[0]["at"],
             f"the robot's report has a BUMP event with onset and clearing ({bumps})")
    ch.check(robot["hazards"]["in_force"] == [], f"no hazard in force at the end ({robot['hazards']['in_force']})")
    ch.check(refused["start"] > bump_at and (clear_at is None or refused["end"] < clear_at),
             "the refused resume ran while the BUMP was reported")
    ch.check(refused["rc"] == 2, f"fleet resume during the BUMP exits 2 (rc={refused['rc']})")
    ch.check("robot/1" in refused["stderr"] and "BUMP" in refused["stderr"]
             and "fleet resume refused" in refused["stderr"],
             "its message names robot/1 and BUMP")
    ch.check(raw["put_at"] > bump_at and (clear_at is None or raw["end"] < clear_at),
             "the resume put straight on the command key went while the BUMP was reported")
    ch.check(commands.get("refused_resumes", 0) >= 1,
             f"the robot refused that resume itself (commands.refused_resumes = {commands.get('refused_resumes')})")
    ch.check(raw_after is not None and raw_after.get("stopped") is True and "BUMP" in raw_after.get("hazards", []),
             f"its latch still answered stopped, naming BUMP, after it ({raw_after})")
    ch.check(clear_at is not None and resumed["start"] > clear_at, "the second resume ran after the BUMP cleared")
    ch.check(resumed["rc"] == 0, f"fleet resume after the clearing exits 0 (rc={resumed['rc']})")
    ch.check(commands["resumes"] >= 1, f"the robot's report counts the resume (commands.resumes = {commands['resumes']})")
    ch.check(len(after_resume) >= args.control_rate,
             f"the base received non-zero commands again after the resume ({len(after_resume)})")
    ch.check(bool(cmds) and not nonzero(cmds[-1]["value"]), "the last command the base received is zero")
    ch.finish(args.summary)


def check_graph(args):
    ch = Checks("graph")
    for spec in args.case:
        name, record, want = spec.split("=", 2)
        r = json.load(open(record, encoding="utf-8"))
        err = r["stderr"]
        lines = [line for line in err.splitlines() if want in line]
        ch.numbers[name] = {"rc": r["rc"], "seconds": r["end"] - r["start"], "line": lines[0] if lines else err.strip()}
        print(f"graph {name}: rc={r['rc']} after {r['end'] - r['start']:.1f} s: {lines[0] if lines else err.strip()!r}")
        ch.check(r["rc"] == 2, f"{name}: fleet up exits 2 (rc={r['rc']})")
        ch.check(bool(lines), f"{name}: it prints \"{want}\"")
    if args.base:
        base = json.load(open(args.base, encoding="utf-8"))
        ch.numbers["base_commands"] = len(base["commands"])
        ch.check(base["nonzero_commands"] == 0,
                 f"the base received no non-zero command from the refused runs ({base['nonzero_commands']})")
    ch.finish(args.summary)


def interpolate(samples, t, key):
    """`key` of time-ordered `samples` (dicts with `t`) at time t, linear
    between the two around it (clamped at the ends)."""
    before = [x for x in samples if x["t"] <= t]
    after = [x for x in samples if x["t"] > t]
    if not before:
        return after[0][key]
    if not after:
        return before[-1][key]
    a, b = before[-1], after[0]
    return a[key] + (b[key] - a[key]) * (t - a["t"]) / (b["t"] - a["t"])


def check_robot_kill(args):
    ch = Checks("robot-kill")
    base = json.load(open(args.base, encoding="utf-8"))
    robot = json.load(open(args.robot, encoding="utf-8"))
    watched = read_jsonl(args.watch)
    cmds = base["commands"]
    odom = base["odom"]
    period = 1.0 / args.control_rate
    odom_period = 1.0 / ODOM_RATE
    t_kill = robot["end"]
    died = [line for line in robot["stderr"].splitlines() if "--die-at reached" in line]
    delays, matched, _ = delivery(watched, cmds)
    d_max = max(delays, default=0.0)
    last = cmds[-1] if cmds else None
    # The last command's own delivery delay (the watcher saw it on the
    # bridge's router, the base received it over DDS; the watcher, a client
    # of that router, may see it a little after the base: then it is < 0).
    seen = [w for w in watched if w["topic"] == "cmd_vel"]
    d_last = None
    if last is not None:
        same = [w for w in seen if w["value"] == last["value"]]
        d_last = min((last["t"] - w["t"] for w in same), key=abs) if same else None
    # The last command as it left echelon (the watcher's time): the kill came
    # one control period later, at the robot's next tick.
    sent_last = max((w["t"] for w in seen), default=None)
    last_nonzero = next((c for c in reversed(cmds) if nonzero(c["value"])), None)
    timeout = next((x for x in base["timeouts"] if last is not None and x["last_command_at"] == last["t"]), None)
    v_kill = interpolate(odom, t_kill, "v") if odom else None
    s_kill = interpolate(odom, t_kill, "s") if odom else None
    travel = (base["odom"][-1]["s"] - s_kill) if odom else None
    bound = None if v_kill is None else v_kill * (CMD_TIMEOUT + odom_period) + v_kill ** 2 / (2 * ACCEL)
    stop_limit = CMD_TIMEOUT + odom_period + max(d_last or 0.0, 0.0)
    stopped_after = None if timeout is None else timeout["stopped_at"] - t_kill
    rest_after = None if timeout is None or timeout["rest_at"] is None else timeout["rest_at"] - t_kill
    rest_limit = stop_limit + (abs(timeout["v"]) / ACCEL if timeout else 0.0)
    # The base's odometry: first sample no longer driven, first at rest, and
    # none moving after that.
    undriven = next((o for o in odom if o["t"] > t_kill and not o["driving"]), None)
    at_rest = next((o for o in odom if o["t"] > t_kill and o["v"] == 0.0 and o["omega"] == 0.0), None)
    moving_late = [o for o in odom if at_rest and o["t"] > at_rest["t"] and (o["v"] != 0.0 or o["omega"] != 0.0)]
    n = ch.numbers
    n.update({
        "die_at_line": died[0] if died else None,
        "robot_rc": robot["rc"],
        "robot_report_printed": any(line.strip().startswith("{") for line in robot["stdout"].splitlines()),
        "control_period_s": period,
        "odom_period_s": odom_period,
        "cmd_received_by_base": len(cmds),
        "nonzero_received": base["nonzero_commands"],
        "delivery_zenoh_to_dds_s": {"p50": quantile(delays, 0.5), "max": d_max if delays else None, "matched": matched},
        "last_command_delay_s": d_last,
        "last_command_seen_before_kill_s": None if sent_last is None else t_kill - sent_last,
        "last_command": last["value"] if last else None,
        "last_command_after_kill_s": None if last is None else last["t"] - t_kill,
        "last_nonzero_after_kill_s": None if last_nonzero is None else last_nonzero["t"] - t_kill,
        "speed_at_kill_mps": v_kill,
        "timeout": timeout,
        "wheels_stopped_after_kill_s": stopped_after,
        "wheels_stopped_after_last_command_s": None if timeout is None else timeout["stopped_at"] - timeout["last_command_at"],
        "stop_limit_s": stop_limit,
        "odom_undriven_after_kill_s": None if undriven is None else undriven["t"] - t_kill,
        "at_rest_after_kill_s": rest_after,
        "odom_at_rest_after_kill_s": None if at_rest is None else at_rest["t"] - t_kill,
        "rest_limit_s": rest_limit,
        "travel_after_kill_m": travel,
        "travel_bound_m": bound,
        "odom_moving_after_rest": len(moving_late),
        "rest_of_run_s": None if not odom else odom[-1]["t"] - t_kill,
    })
    ms = lambda x: float("nan") if x is None else x * 1000
    print(f"robot-kill: {died[0] if died else 'no --die-at line'} (exit {robot['rc']}); the base had received "
          f"{len(cmds)} commands ({base['nonzero_commands']} non-zero), the last {ms(n['last_command_after_kill_s']):+.1f} ms "
          f"after the kill, {fmt_cmd(last['value']) if last else 'none'} (bridge -> base {ms(d_last):+.2f} ms; the watcher "
          f"saw it {ms(n['last_command_seen_before_kill_s']):.1f} ms before the kill); "
          f"speed at the kill {v_kill or float('nan'):.4f} m/s")
    print(f"robot-kill: the base's timeout stopped its wheels {ms(stopped_after):.1f} ms after the kill "
          f"({ms(n['wheels_stopped_after_last_command_s']):.1f} ms after the last command; limit {ms(stop_limit):.1f} ms = "
          f"0.5 s + odometry period {odom_period * 1000:.0f} ms + the last command's delay), seen in its odometry "
          f"{ms(n['odom_undriven_after_kill_s']):.1f} ms after the kill; at rest {ms(rest_after):.1f} ms after the kill "
          f"(odometry: {ms(n['odom_at_rest_after_kill_s']):.1f} ms; limit {ms(rest_limit):.1f} ms with the braking time); "
          f"travelled {(travel or 0) * 1000:.2f} mm after the kill (bound {(bound or 0) * 1000:.2f} mm)")

    ch.check(bool(died) and robot["rc"] == -signal.SIGKILL,
             f"the robot killed itself with SIGKILL at --die-at (rc {robot['rc']}: {died[0] if died else 'no line'})")
    ch.check(not n["robot_report_printed"], "a killed robot prints no report")
    ch.check(base["nonzero_commands"] >= 2 * args.control_rate,
             f"echelon drove the base before the kill ({base['nonzero_commands']} non-zero commands)")
    ch.check(last is not None and nonzero(last["value"]),
             "the last command the base received is non-zero (a killed robot sends no stop)")
    ch.check(last is not None and last["t"] <= t_kill + d_max + args.slack,
             f"nothing reached the base after the kill (last {ms(n['last_command_after_kill_s']):+.1f} ms after it, "
             f"limit {ms(d_max + args.slack):.1f} ms)")
    ch.check(v_kill is not None and v_kill > 0.05, f"the base was moving at the kill ({v_kill} m/s)")
    ch.check(timeout is not None, "the base's own 0.5 s timeout took the last command out")
    ch.check(stopped_after is not None and stopped_after <= stop_limit,
             f"its wheels stopped driving {ms(stopped_after):.1f} ms after the kill <= {ms(stop_limit):.1f} ms")
    ch.check(rest_after is not None and rest_after <= rest_limit,
             f"the base was at rest {ms(rest_after):.1f} ms after the kill <= {ms(rest_limit):.1f} ms "
             f"(+ braking {(abs(timeout['v']) / ACCEL if timeout else 0) * 1000:.1f} ms at {ACCEL} m/s^2)")
    ch.check(travel is not None and bound is not None and travel <= bound,
             f"travel after the kill {(travel or 0) * 1000:.2f} mm <= v*(0.5 s + 0.05 s) + v^2/(2*{ACCEL}) = "
             f"{(bound or 0) * 1000:.2f} mm")
    ch.check(at_rest is not None and not moving_late,
             f"its odometry stayed at rest to the end ({n['rest_of_run_s'] or 0:.1f} s after the kill; "
             f"{len(moving_late)} moving samples)")
    ch.finish(args.summary)


def mcap_records(path, topic):
    """The collector's records on `topic` in fleet.mcap: (log time in UNIX
    s, the JSON record), in log order."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(msg.log_time / 1e9, json.loads(msg.data))
                for _, _, msg in make_reader(f).iter_messages(topics=[topic], log_time_order=True)]


def check_base_kill(args):
    """The robot's hold, from what the collector logged: its states
    (`/agent/1/state`, every tick it has a state to publish, with the fleet
    time `t` and the collector's UNIX receive time) and its stats
    (`/agent/1/stats`, once per fleet second: `link` and the `watchdogs`
    counts). The kill's fleet time is its wall time less the states' offset
    (receive time - fleet time, the median of those before the kill); the
    first held tick is the first held stats' t less (held_ticks - 1) control
    periods."""
    ch = Checks("base-kill")
    killed = json.load(open(args.kill, encoding="utf-8"))
    robot = last_json_line(args.robot_report)
    robot_log = open(args.robot_log, encoding="utf-8").read().splitlines()
    watched = read_jsonl(args.watch)
    states = mcap_records(args.mcap, "/agent/1/state")
    stats = mcap_records(args.mcap, "/agent/1/stats")
    period = 1.0 / args.control_rate
    t_kill, wall_kill = killed["t"], killed["wall"]
    ms = lambda x: float("nan") if x is None else x * 1000
    sec = lambda x: "never" if x is None else f"{x:.2f} s"

    before = [(w, st) for w, st in states if w < wall_kill and st["link"] != "waiting"]
    offsets = [w - st["t"] for w, st in before[-40:]]
    kill_fleet = wall_kill - quantile(offsets, 0.5) if offsets else None
    # The stats in log order, while their t grows: the last one, sent at
    # exit, is the report's, whose t and link may be older (its last state's).
    ticking = []
    for _, st in stats:
        if not ticking or st["t"] > ticking[-1]["t"]:
            ticking.append(st)
    held_stats = [st for st in ticking if st["link"] == "held"]
    first_held = held_stats[0] if held_stats else None
    t_hold = None if first_held is None else first_held["t"] - (first_held["watchdogs"]["held_ticks"] - 1) * period
    # Its last state before the hold (held, it publishes its last known
    # state with the link `held`).
    last_state_t = max((st["t"] for _, st in states if st["link"] != "held"), default=None)
    hold_after = None if t_hold is None or kill_fleet is None else t_hold - kill_fleet
    limit = args.odom_timeout + period + args.slack
    not_held_after = [st for st in ticking if t_hold is not None and st["t"] > t_hold + period / 2
                      and st["link"] != "held"]
    states_after_hold = [st for _, st in states if t_hold is not None and st["t"] >= t_hold - 1e-6]
    last_held = held_stats[-1] if held_stats else None
    wd = robot["watchdogs"]
    r2 = robot.get("ros2") or {}
    # Every tick from the hold on commanded zero: the non-zero commands
    # sent fit in the ticks before it.
    nonzero_sent = r2.get("cmd_sent", 0) - r2.get("cmd_zero", 0)
    ticks_before_hold = None if t_hold is None else t_hold / period
    odom = [w for w in watched if w["topic"] == "odom"]
    last_odom = max((o["t"] for o in odom if o["t"] <= t_kill), default=None)
    odom_after = [o for o in odom if o["t"] > t_kill + args.slack]
    # The bridge's routes for the dead node: its liveliness tokens (MS
    # cmd_vel, MP odom) withdrawn, and the matching status of a publisher on
    # the cmd_vel key (what the robot's publisher sees).
    tokens = [w for w in watched if w["topic"] == "token" and w["kind"] == "delete" and w["t"] > t_kill]
    cmd_token_gone = next((w["t"] - t_kill for w in tokens if "/MS/" in w["key"] and "cmd_vel" in w["key"]), None)
    odom_token_gone = next((w["t"] - t_kill for w in tokens if "/MP/" in w["key"] and "odom" in w["key"]), None)
    matching = [w for w in watched if w["topic"] == "matching"]
    matched_at_kill = next((w["matching"] for w in reversed(matching) if w["t"] <= t_kill), None)
    unmatched = next((w["t"] - t_kill for w in matching if w["t"] > t_kill and not w["matching"]), None)
    end = max((w["t"] for w in watched), default=t_kill)
    # The bridge's own word (its log, RUST_LOG info): when it undiscovered
    # the base's node, on its UTC timestamps.
    undiscovered = None
    for line in open(args.bridge_log, encoding="utf-8", errors="replace").read().splitlines():
        line = re.sub(r"\x1b\[[0-9;]*m", "", line)
        if "Undiscovered ROS Node /create3_base" in line:
            stamp = datetime.datetime.fromisoformat(line.split()[0].replace("Z", "+00:00")).timestamp()
            undiscovered = {"line": line[line.index("Undiscovered"):], "after_kill_s": stamp - wall_kill}
            break
    no_reader = [line for line in robot_log if "no reader" in line]
    n = ch.numbers
    n.update({
        "control_period_s": period,
        "odom_timeout_s": args.odom_timeout,
        "link_before_kill": before[-1][1]["link"] if before else None,
        "kill_fleet_time_s": kill_fleet,
        "last_odom_before_kill_s": None if last_odom is None else last_odom - t_kill,
        "odom_after_kill": len(odom_after),
        "held_at_fleet_time_s": t_hold,
        "held_after_kill_s": hold_after,
        "held_limit_s": limit,
        "last_state_t_s": last_state_t,
        "states_published_after_hold": len(states_after_hold),
        "held_stats": len(held_stats),
        "stats_not_held_after_hold": len(not_held_after),
        "held_ticks": wd["held_ticks"],
        "held_until_s": None if last_held is None else last_held["t"],
        "nonzero_cmds_sent": nonzero_sent,
        "ticks_before_hold": ticks_before_hold,
        "watchdogs": wd,
        "robot_ros2": r2,
        "robot_report": {"t": robot["t"], "link": robot["link"], "ticks": robot["ticks"],
                         "published": robot["published"], "final_error": robot["final_error"]},
        "robot_no_reader_lines": no_reader,
        "cmd_vel_matching_at_kill": matched_at_kill,
        "cmd_vel_unmatched_after_kill_s": unmatched,
        "cmd_vel_token_withdrawn_after_kill_s": cmd_token_gone,
        "odom_token_withdrawn_after_kill_s": odom_token_gone,
        "watched_after_kill_s": end - t_kill,
        "bridge_undiscovered": undiscovered,
    })
    print(f"base-kill: the base killed at fleet time {kill_fleet or float('nan'):.3f} s; last odometry "
          f"{ms(n['last_odom_before_kill_s']):+.1f} ms from the kill, {len(odom_after)} after it; robot/1 held from "
          f"{t_hold or float('nan'):.3f} s, {ms(hold_after):.1f} ms after the kill (limit {ms(limit):.1f} ms = "
          f"odom_timeout + period + {args.slack * 1000:.0f} ms), to {sec(n['held_until_s'])} "
          f"({wd['held_ticks']} held ticks); its last state t = {last_state_t}, "
          f"{len(states_after_hold)} states published after the hold")
    print(f"base-kill: watchdogs {wd}; {nonzero_sent} non-zero commands sent in {ticks_before_hold or 0:.1f} ticks "
          f"before the hold; robot stderr 'no reader' lines: {no_reader}; its report: {n['robot_report']}")
    print(f"base-kill: the bridge's cmd_vel route: matched at the kill {matched_at_kill}; unmatched "
          f"{sec(unmatched)} after the kill; its MS token withdrawn {sec(cmd_token_gone)}, the MP odom token "
          f"{sec(odom_token_gone)} after it (watched for {end - t_kill:.1f} s); the bridge logged "
          f"{undiscovered['line'] + ' ' + sec(undiscovered['after_kill_s']) + ' after it' if undiscovered else 'nothing'}")

    ch.check(bool(before) and before[-1][1]["link"] == "tracking",
             f"robot/1 was following before the kill (link {before[-1][1]['link'] if before else None})")
    ch.check(not odom_after, f"no odometry came out of the bridge after the kill ({len(odom_after)})")
    ch.check(hold_after is not None and args.odom_timeout - period <= hold_after <= limit,
             f"robot/1 held {ms(hold_after):.1f} ms after the kill, within [odom_timeout - period, "
             f"{ms(limit):.1f} ms]")
    ch.check(t_hold is not None and last_state_t is not None and abs(t_hold - (last_state_t + period)) < period / 2,
             f"its first held tick ({t_hold}) follows its last state ({last_state_t}) by one period")
    ch.check(bool(states_after_hold) and all(st["link"] == "held" for st in states_after_hold),
             f"the fleet sees it held: {len(states_after_hold)} states published from the hold on, every one "
             f"`held` ({sum(st['link'] != 'held' for st in states_after_hold)} not)")
    ch.check(first_held is not None and wd["odometry"] >= 1 and first_held["watchdogs"]["odometry"] >= 1,
             f"held by the odometry watchdog, counted in its report (watchdogs.odometry {wd['odometry']})")
    ch.check(last_held is not None and not not_held_after and last_held["t"] >= args.duration - 1.0
             and abs(wd["held_ticks"] * period - (last_held["t"] - t_hold + period)) <= 2 * period,
             f"held to the end: every stats after the hold says held ({len(not_held_after)} not), the last at "
             f"{sec(n['held_until_s'])}, {wd['held_ticks']} held ticks")
    ch.check(ticks_before_hold is not None and nonzero_sent <= ticks_before_hold + 1
             and r2.get("cmd_zero", 0) >= wd["held_ticks"],
             f"commanding zero from the hold on ({r2.get('cmd_zero')} zero commands >= {wd['held_ticks']} held ticks; "
             f"{nonzero_sent} non-zero, all before it)")
    # The output watchdog: what the real bridge did with the cmd_vel route.
    ch.check(matched_at_kill is True, "the robot's cmd_vel publisher matched the bridge's subscriber at the kill")
    ch.check(unmatched is None or unmatched > limit,
             f"the bridge kept its cmd_vel subscriber past the odometry hold (unmatched {sec(unmatched)} after "
             f"the kill: a SIGKILLed DDS reader is forgotten at its participant's lease expiry)")
    ch.check(wd["output"] == 0 and not no_reader,
             f"so the output watchdog never held robot/1 (watchdogs.output {wd['output']}): the odometry watchdog "
             f"holds first, and a reader lost while held is not counted")
    ch.finish(args.summary)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd_name", required=True)

    w = sub.add_parser("watch")
    w.add_argument("--connect", required=True)
    w.add_argument("--ns", default="bot1")
    w.add_argument("--log", required=True)
    w.add_argument("--flags", required=True)
    w.add_argument("--no-cmd-vel", action="store_true",
                   help="no cmd_vel subscriber: a publisher's matching status on the key instead")

    k = sub.add_parser("kill")
    k.add_argument("--pid", type=int, required=True)
    k.add_argument("--record", required=True)
    k.add_argument("--signal", choices=["KILL", "TERM"], default="KILL")

    e = sub.add_parser("exec")
    e.add_argument("--record", required=True)
    e.add_argument("cmd", nargs=argparse.REMAINDER)

    c = sub.add_parser("check-converge")
    c.add_argument("--base", required=True, help="create3_base.py's report")
    c.add_argument("--robot-report", required=True, help="DIR/logs/robot-1.out of fleet up")
    c.add_argument("--watch", required=True)
    c.add_argument("--duration", type=float, required=True)
    c.add_argument("--control-rate", type=float, required=True)
    c.add_argument("--max-error", type=float, default=0.02)
    c.add_argument("--summary")

    h = sub.add_parser("check-hazard")
    h.add_argument("--base", required=True)
    h.add_argument("--hazard-node", required=True)
    h.add_argument("--robot-report", required=True)
    h.add_argument("--watch", required=True)
    h.add_argument("--refused", required=True, help="exec record of the resume during the BUMP")
    h.add_argument("--resumed", required=True, help="exec record of the resume after it cleared")
    h.add_argument("--raw-resume", required=True, help="put-resume's record")
    h.add_argument("--fleet", required=True)
    h.add_argument("--control-rate", type=float, required=True)
    h.add_argument("--slack", type=float, default=0.010, help="s added to the measured delivery delay")
    h.add_argument("--summary")

    g = sub.add_parser("check-graph")
    g.add_argument("--case", action="append", required=True, help="NAME=EXEC_RECORD=EXPECTED_TEXT")
    g.add_argument("--base", help="create3_base.py's report: nothing may have moved")
    g.add_argument("--summary")

    rk = sub.add_parser("check-robot-kill")
    rk.add_argument("--base", required=True, help="create3_base.py's report")
    rk.add_argument("--robot", required=True, help="exec record of the fleet robot that killed itself")
    rk.add_argument("--watch", required=True)
    rk.add_argument("--control-rate", type=float, required=True)
    rk.add_argument("--slack", type=float, default=0.010, help="s added to the measured delivery delay")
    rk.add_argument("--summary")

    bk = sub.add_parser("check-base-kill")
    bk.add_argument("--kill", required=True, help="kill's record")
    bk.add_argument("--robot-report", required=True, help="DIR/logs/robot-1.out of fleet up")
    bk.add_argument("--robot-log", required=True, help="DIR/logs/robot-1.log of fleet up (its stderr)")
    bk.add_argument("--mcap", required=True, help="DIR/fleet.mcap of fleet up")
    bk.add_argument("--watch", required=True)
    bk.add_argument("--bridge-log", required=True)
    bk.add_argument("--odom-timeout", type=float, required=True)
    bk.add_argument("--control-rate", type=float, required=True)
    bk.add_argument("--duration", type=float, required=True, help="fleet up's --duration")
    bk.add_argument("--slack", type=float, default=0.010, help="s added for the state's way to the collector")
    bk.add_argument("--summary")

    r = sub.add_parser("put-resume")
    r.add_argument("--connect", required=True, help="the fleet's router")
    r.add_argument("--fleet", required=True)
    r.add_argument("--token-file", required=True, help="fleet up's OUT/operator-token")
    r.add_argument("--record", required=True)

    args = p.parse_args()
    {"watch": watch, "exec": exec_, "kill": kill, "put-resume": put_resume, "check-converge": check_converge,
     "check-hazard": check_hazard, "check-graph": check_graph, "check-robot-kill": check_robot_kill,
     "check-base-kill": check_base_kill}[args.cmd_name](args)


if __name__ == "__main__":
    main()
