#!/usr/bin/env python3
"""How fresh the live view of a running fleet is: what the dashboard's page
(and any Foxglove client) receives from the collector's Foxglove server.

A client of the Foxglove WebSocket protocol (as ws_client.py, written from
the protocol's specification) subscribes to `/reference` and every
`/agent/K/state` (the JSON channels the dashboard draws from) for S seconds
and measures, for each state frame, its **lag**: when it arrived, in fleet
time, less the state's own fleet time `t` (how far behind the fleet's
present the robot drawn is), and per robot how many states arrived. Fleet
time on this client's clock is the reference's, from the reference sample
that arrived soonest after its time (the smallest arrival − `t`: the
offset with the least delay in it), so a lag is measured against the
fastest the reference itself came, and is ≥ 0 but for rounding. It also times the
dashboard page's HTTP answer (time to the last byte) when given --page.

Usage:
  live_lag.py WS_URL --seconds S [--page HTTP_URL] [--wait W]

Prints one JSON object: messages/s, references and robots seen, states per
robot (min, median), the lag's p50/p99/max (ms), the page's answer time
(ms). Exits 1, saying so on stderr, when no reference or no robot's state
arrived: a lag measured on nothing is no measurement.
"""

import argparse
import asyncio
import json
import sys
import time
import urllib.request

import websockets
from ws_client import connect, message, subscribe


def drawn(ch):
    """The channels the dashboard draws from."""
    topic = ch["topic"]
    return topic == "/reference" or (topic.startswith("/agent/") and topic.endswith("/state"))


def quantile(xs, q):
    """The nearest-rank quantile `q` of `xs` (sorted here); NaN if empty."""
    if not xs:
        return float("nan")
    xs = sorted(xs)
    return xs[min(len(xs) - 1, max(0, int(round(q * len(xs) + 0.5)) - 1))]


async def run(url, seconds, wait):
    ws = await connect(url, wait, max_size=None)
    subscribed = {}  # subscription id -> channel
    offset = float("inf")  # min over references of arrival − t (client clock)
    arrivals, per_robot = [], {}  # (arrival, t) of each state
    messages, references, start, deadline = 0, 0, None, None
    while True:
        timeout = 30 if deadline is None else deadline - time.monotonic()
        if timeout <= 0:
            break
        try:
            frame = await asyncio.wait_for(ws.recv(), timeout=timeout)
        except asyncio.TimeoutError:
            break
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg.get("op") == "advertise":
                await subscribe(ws, msg, subscribed, drawn)
                if start is None:
                    start = time.monotonic()
                    deadline = start + seconds
            continue
        got = message(frame, subscribed)
        if got is None:
            continue
        ch, payload = got
        topic = ch["topic"]
        messages += 1
        t = json.loads(payload)["t"]
        at = time.monotonic()
        if topic == "/reference":
            references += 1
            offset = min(offset, at - t)
        else:
            per_robot[topic] = per_robot.get(topic, 0) + 1
            arrivals.append((at, t))
    await ws.close()
    lags = [at - offset - t for at, t in arrivals]
    counts = sorted(per_robot.values())
    return {
        "seconds": seconds,
        "messages_per_s": messages / seconds,
        "references": references,
        "robots": len(per_robot),
        "states_per_robot_min": counts[0] if counts else 0,
        "states_per_robot_median": counts[len(counts) // 2] if counts else 0,
        "lag_ms_p50": 1e3 * quantile(lags, 0.5),
        "lag_ms_p99": 1e3 * quantile(lags, 0.99),
        "lag_ms_max": 1e3 * max(lags) if lags else float("nan"),
    }


def page_ms(url):
    start = time.monotonic()
    with urllib.request.urlopen(url, timeout=30) as r:
        r.read()
    return 1e3 * (time.monotonic() - start)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("url")
    p.add_argument("--seconds", type=float, required=True)
    p.add_argument("--page")
    p.add_argument("--wait", type=float, default=10.0)
    a = p.parse_args()
    try:
        out = asyncio.run(run(a.url, a.seconds, a.wait))
    except (OSError, websockets.exceptions.InvalidHandshake) as e:
        print(f"live_lag: nobody answered at {a.url} within {a.wait} s: {e}", file=sys.stderr)
        sys.exit(1)
    if a.page:
        try:
            out["page_ms"] = page_ms(a.page)
        except OSError as e:
            print(f"live_lag: the page {a.page} did not answer: {e}", file=sys.stderr)
            sys.exit(1)
    print(json.dumps(out))
    if out["references"] == 0 or out["robots"] == 0:
        print(
            f"live_lag: {out['references']} references and {out['robots']} robots' states in {a.seconds} s from {a.url}",
            file=sys.stderr,
        )
        sys.exit(1)


if __name__ == "__main__":
    main()
