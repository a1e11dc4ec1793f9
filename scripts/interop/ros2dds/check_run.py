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

  exec --record FILE -- CMD...
      Runs CMD, records its monotonic start and end, exit status, stdout and
      stderr in FILE (JSON), echoes its output, and exits with its status.

  put-resume --connect ROUTER --fleet NAME --token-file FILE --record FILE
      Plays an operator that skips `fleet resume`'s hazard check: asks the
      fleet's latches (`echelon/<fleet>/latch/**`) for the highest command
      number, puts a resume numbered one past it, signed with the operator
      token in --token-file (`fleet up`'s OUT/operator-token: HMAC-SHA256
      as crates/echelon-fleet/src/token.rs makes it), straight on
      `echelon/<fleet>/command`, and 0.5 s later asks the latches again.
      Records both answers (and the times) in FILE: the robot itself must
      refuse it while its base reports a hazard.

  check-converge | check-hazard | check-graph  (see --help of each)
      Read the reports and logs of one phase, print the measured numbers,
      append them to --summary (JSON), and exit 1 naming every failed check.
"""

import argparse
import hashlib
import hmac
import json
import os
import signal
import struct
import subprocess
import sys
import threading
import time

STOPPING = {1: "BUMP", 2: "CLIFF", 3: "STALL", 4: "WHEEL_DROP"}
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
    subs = [session.declare_subscriber(k, on_sample) for k in (cmd_key, hazard_key, odom_key)]
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
# put-resume


def command_proof(token_hex, command):
    """The operator token's proof of `command` (echelon-fleet's token.rs):
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


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd_name", required=True)

    w = sub.add_parser("watch")
    w.add_argument("--connect", required=True)
    w.add_argument("--ns", default="bot1")
    w.add_argument("--log", required=True)
    w.add_argument("--flags", required=True)

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

    r = sub.add_parser("put-resume")
    r.add_argument("--connect", required=True, help="the fleet's router")
    r.add_argument("--fleet", required=True)
    r.add_argument("--token-file", required=True, help="fleet up's OUT/operator-token")
    r.add_argument("--record", required=True)

    args = p.parse_args()
    {"watch": watch, "exec": exec_, "put-resume": put_resume, "check-converge": check_converge, "check-hazard": check_hazard,
     "check-graph": check_graph}[args.cmd_name](args)


if __name__ == "__main__":
    main()
