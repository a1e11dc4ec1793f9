#!/usr/bin/env python3
"""An independent client of the Foxglove WebSocket protocol, written from
the protocol's specification (github.com/foxglove/ws-protocol, "Spec"), not
from echelon's code: it connects with the subprotocol `foxglove.sdk.v1`
(or the older `foxglove.websocket.v1`), reads the server's JSON `serverInfo`
and `advertise` messages, subscribes to the channels, and decodes binary
"Message Data" frames (opcode 0x01: uint32 subscription id, uint64 receive
timestamp, payload; little-endian) with Foxglove's protobuf classes.

Usage:
  ws_client.py URL --seconds S [--wait W]            read for S seconds
  ws_client.py URL --seconds S --stall [--wait W]    subscribe, never read

Connects as soon as the server answers (retrying for up to W seconds).
Prints one JSON object:
  {"channels": {topic: [message encoding, schema name, schema encoding,
                        whether a protobuf schema defines the message as
                        foxglove-schemas-protobuf does]},
   "tf": {child frame: {"count": n, "rate": Hz over the window}},
   "scene": {entity id: {"count": n, "rate": Hz}},
   "last": {child frame: [x, y, yaw]},
   "messages": total message frames, "seconds": window}
"""

import argparse
import asyncio
import base64
import json
import math
import struct
import sys
import time

import websockets
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf import descriptor_pb2

TYPES = {"foxglove.FrameTransforms": FrameTransforms, "foxglove.SceneUpdate": SceneUpdate}
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def message(frame, subscribed):
    """A binary Message Data frame (opcode 0x01: uint32 subscription id,
    uint64 receive timestamp, payload) of one of the `subscribed` channels
    (subscription id → channel): that channel and the payload; None for any
    other frame."""
    if frame[0] != 0x01:
        return None
    sid, _stamp = struct.unpack_from("<IQ", frame, 1)
    ch = subscribed.get(sid)
    return None if ch is None else (ch, frame[13:])


def same_definition(schema_b64, cls):
    fds = descriptor_pb2.FileDescriptorSet()
    fds.ParseFromString(base64.b64decode(schema_b64))
    for f in fds.file:
        for m in f.message_type:
            if f"{f.package}.{m.name}" == cls.DESCRIPTOR.full_name:
                ours = {(x.name, x.number, x.type) for x in m.field}
                return ours == {(x.name, x.number, x.type) for x in cls.DESCRIPTOR.fields}
    return False


class Rate:
    def __init__(self):
        self.times = []

    def add(self, t):
        self.times.append(t)

    def out(self):
        n = len(self.times)
        span = self.times[-1] - self.times[0] if n > 1 else 0.0
        return {"count": n, "rate": (n - 1) / span if span > 0 else 0.0}


async def subscribe(ws, advertised, subscribed, want=lambda ch: True):
    """Subscribes to the channels of an `advertise` message that `want`
    accepts, numbering the subscriptions after those of `subscribed`
    (subscription id -> channel, updated)."""
    subs = []
    for ch in advertised["channels"]:
        if want(ch):
            sid = len(subscribed) + 1
            subscribed[sid] = ch
            subs.append({"id": sid, "channelId": ch["id"]})
    if subs:
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))


async def connect(url, wait, **kwargs):
    deadline = time.monotonic() + wait
    while True:
        try:
            return await websockets.connect(url, subprotocols=SUBPROTOCOLS, **kwargs)
        except (OSError, websockets.exceptions.InvalidHandshake):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.1)


async def run(url, seconds, stall, wait):
    # A stalled viewer: the smallest receive queue, and it never reads.
    kwargs = {"max_queue": 1, "max_size": None} if stall else {"max_size": None}
    ws = await connect(url, wait, **kwargs)
    channels = {}  # id -> advertised channel
    subscribed = {}  # subscription id -> channel
    tf, scene, last = {}, {}, {}
    messages = 0
    start = None
    deadline = None
    while True:
        timeout = None if deadline is None else deadline - time.monotonic()
        if timeout is not None and timeout <= 0:
            break
        try:
            frame = await asyncio.wait_for(ws.recv(), timeout=timeout if timeout else 30)
        except asyncio.TimeoutError:
            break
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg.get("op") == "advertise":
                for ch in msg["channels"]:
                    channels[ch["id"]] = ch
                await subscribe(ws, msg, subscribed)
                if stall:
                    # Subscribed to everything: now never read again.
                    await asyncio.sleep(seconds)
                    break
                if start is None:
                    start = time.monotonic()
                    deadline = start + seconds
            continue
        got = message(frame, subscribed)
        if got is None:
            continue
        ch, payload = got
        messages += 1
        cls = TYPES.get(ch.get("schemaName"))
        if cls is None or ch.get("encoding") != "protobuf":
            continue
        now = time.monotonic()
        m = cls()
        m.ParseFromString(payload)
        if cls is FrameTransforms:
            for t in m.transforms:
                tf.setdefault(t.child_frame_id, Rate()).add(now)
                q = t.rotation
                last[t.child_frame_id] = [t.translation.x, t.translation.y,
                                          2.0 * math.atan2(q.z, q.w)]
        elif ch["topic"] == "/scene":
            for e in m.entities:
                scene.setdefault(e.id, Rate()).add(now)
    await ws.close()
    out = {
        "channels": {
            ch["topic"]: [
                ch["encoding"],
                ch.get("schemaName"),
                ch.get("schemaEncoding"),
                ch.get("schemaName") in TYPES and ch.get("schemaEncoding") == "protobuf"
                and same_definition(ch["schema"], TYPES[ch["schemaName"]]),
            ]
            for ch in channels.values()
        },
        "tf": {k: v.out() for k, v in tf.items()},
        "scene": {k: v.out() for k, v in scene.items()},
        "last": last,
        "messages": messages,
        "seconds": seconds,
    }
    print(json.dumps(out))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("url")
    p.add_argument("--seconds", type=float, required=True)
    p.add_argument("--stall", action="store_true")
    p.add_argument("--wait", type=float, default=60.0)
    a = p.parse_args()
    asyncio.run(run(a.url, a.seconds, a.stall, a.wait))


if __name__ == "__main__":
    sys.exit(main())
