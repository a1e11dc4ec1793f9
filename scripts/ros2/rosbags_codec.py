#!/usr/bin/env python3
"""CDR of messages no ROS 2 wheel ships (irobot_create_msgs), from an
independent implementation: `rosbags` (pure Python) builds its codec and
its RIHS01 type hash from the `.msg` text alone. echelon-fleet's
tests/ros2_hazards.rs checks echelon's generated codecs against it.

Reads one JSON object on stdin:
  {"msgs": {"irobot_create_msgs/msg/HazardDetection": "<.msg text>", ...},
   "encode": [{"type": "...", "value": {...}}, ...],
   "decode": [{"type": "...", "hex": "..."}, ...],
   "hash": ["type", ...]}
and writes {"encoded": [hex...], "decoded": [value...], "hashes": {type: hash}}.
Values are plain JSON: nested messages as objects, sequences as lists,
Time as {"sec", "nanosec"}.
"""

import json
import sys

from rosbags.typesys import Stores, get_types_from_msg, get_typestore


def main():
    req = json.load(sys.stdin)
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in req.get("msgs", {}).items():
        types.update(get_types_from_msg(text, name))
    store.register(types)

    def build(typename, value):
        cls = store.types[typename]
        fields = {}
        msgdef = store.fielddefs[typename][1]
        for fname, (kind, spec) in msgdef:
            v = value[fname]
            fields[fname] = convert(kind, spec, v)
        return cls(**fields)

    def convert(kind, spec, v):
        # kind: 1 base, 2 name (nested), 3 array, 4 sequence (rosbags Nodetype)
        if kind == 2:
            return build(spec, v)
        if kind in (3, 4):
            inner_kind, inner_spec = spec[0]
            if inner_kind == 2:
                return [build(inner_spec, x) for x in v]
            import numpy as np
            return np.array(v)
        return v

    def dump(msg):
        out = {}
        for fname in msg.__dataclass_fields__:
            if fname == "__msgtype__" or fname.isupper():
                continue  # the type name, and the message's constants
            v = getattr(msg, fname)
            if hasattr(v, "__dataclass_fields__"):
                out[fname] = dump(v)
            elif isinstance(v, list):
                out[fname] = [dump(x) if hasattr(x, "__dataclass_fields__") else x for x in v]
            elif hasattr(v, "tolist"):
                out[fname] = v.tolist()
            else:
                out[fname] = v
        return out

    encoded = [
        bytes(store.serialize_cdr(build(e["type"], e["value"]), e["type"])).hex()
        for e in req.get("encode", [])
    ]
    decoded = [
        dump(store.deserialize_cdr(bytes.fromhex(d["hex"]), d["type"]))
        for d in req.get("decode", [])
    ]
    hashes = {t: store.hash_rihs01(t) for t in req.get("hash", [])}
    json.dump({"encoded": encoded, "decoded": decoded, "hashes": hashes}, sys.stdout)


if __name__ == "__main__":
    main()
