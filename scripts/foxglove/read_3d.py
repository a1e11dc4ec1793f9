#!/usr/bin/env python3
"""Reads the 3D channels of an echelon MCAP file (run.mcap or fleet.mcap)
independently of echelon: Python's `mcap` reader and Foxglove's own
protobuf classes (`foxglove-schemas-protobuf`).

Usage: read_3d.py FILE.mcap

Prints one JSON object:
  {"schemas": {topic: [schema encoding, schema name, message encoding,
               whether the schema's FileDescriptorSet defines that message
               exactly as foxglove-schemas-protobuf does]},
   "tf": [[t, child_frame_id, parent, x, y, z, yaw], ...],
   "scene": [[t, entity id, x, y], ...]            (bodies, slots)
   "links": [[t, entity id, x0, y0, x1, y1], ...]
   "static": [entity ids of /scene/static],
   "states": [[t, agent, x, y, theta, log_time ns, u1, u2], ...]}
                                                    (/agent/K/state JSON)
t is the message's publish time in seconds.
"""

import json
import math
import sys

from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf import descriptor_pb2
from mcap.reader import make_reader

TYPES = {"foxglove.FrameTransforms": FrameTransforms, "foxglove.SceneUpdate": SceneUpdate}


def same_definition(schema_data, cls):
    """Whether the FileDescriptorSet in the file defines cls's message with
    the fields (names, numbers, types) Foxglove's published class has."""
    fds = descriptor_pb2.FileDescriptorSet()
    fds.ParseFromString(schema_data)
    ours = {}
    for f in fds.file:
        for m in f.message_type:
            ours[f"{f.package}.{m.name}"] = {(x.name, x.number, x.type) for x in m.field}
    theirs = cls.DESCRIPTOR
    want = {(x.name, x.number, x.type) for x in theirs.fields}
    return ours.get(theirs.full_name) == want


def yaw(q):
    return 2.0 * math.atan2(q.z, q.w)


def main(path):
    out = {"schemas": {}, "tf": [], "scene": [], "links": [], "static": [], "states": []}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            t = message.publish_time * 1e-9
            if channel.message_encoding == "json":
                if channel.topic.startswith("/agent/") and channel.topic.endswith("/state"):
                    r = json.loads(message.data)
                    out["states"].append([r["t"], r["agent"], r["x"], r["y"], r["theta"],
                                          message.log_time, r["u1"], r["u2"]])
                continue
            cls = TYPES.get(schema.name)
            if channel.topic not in out["schemas"]:
                out["schemas"][channel.topic] = [
                    schema.encoding,
                    schema.name,
                    channel.message_encoding,
                    cls is not None and same_definition(schema.data, cls),
                ]
            if cls is None:
                continue
            msg = cls()
            msg.ParseFromString(message.data)
            if cls is FrameTransforms:
                for tr in msg.transforms:
                    v = tr.translation
                    out["tf"].append(
                        [t, tr.child_frame_id, tr.parent_frame_id, v.x, v.y, v.z, yaw(tr.rotation)]
                    )
            elif channel.topic == "/scene/static":
                out["static"].extend(e.id for e in msg.entities)
            else:
                for e in msg.entities:
                    for c in e.cylinders[:1] if not e.id.endswith("/safety") else []:
                        out["scene"].append([t, e.id, c.pose.position.x, c.pose.position.y])
                    for s in e.spheres[:1]:
                        out["scene"].append([t, e.id, s.pose.position.x, s.pose.position.y])
                    for line in e.lines[:1]:
                        p = line.points
                        out["links"].append([t, e.id, p[0].x, p[0].y, p[1].x, p[1].y])
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
