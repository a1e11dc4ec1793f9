#!/usr/bin/env python3
"""Reads the ROS 2 channels of an MCAP file with foxglove's independent
readers: `mcap` for the records and `mcap-ros2-support` to decode the CDR
messages with the channel's `ros2msg` schema (its own parser of the message
definition text and its own CDR decoder; nothing of echelon's).

Usage: read_mcap.py FILE.mcap

Prints one JSON document:

  {"profile": ..., "channels": {topic: {"message_encoding", "schema_name",
     "schema_encoding", "schema_data", "metadata", "qos": [parsed
     offered_qos_profiles YAML]}},
   "messages": [{"topic", "sequence", "log_time", "publish_time",
                 "message": {...decoded fields...}}, ...]}

for the channels whose message encoding is `cdr` (echelon's JSON channels
are skipped). Decoded floats travel as their IEEE-754 bit patterns (unsigned
integers) so comparisons are exact. Exit status 3 with a message on stderr
when a package is missing, 4 when a message does not decode.
"""

import json
import struct
import sys

INSTALL_HINT = (
    "mcap-ros2-support missing: run scripts/test, or "
    "`python3 -m pip install -r scripts/requirements-test.txt`"
)

try:
    import yaml
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
except ImportError as e:
    sys.stderr.write(f"cannot import: {e}\n{INSTALL_HINT}\n")
    sys.exit(3)


def plain(value):
    """A decoded message as JSON values, floats as bit patterns."""
    if isinstance(value, float):
        return struct.unpack("<Q", struct.pack("<d", value))[0]
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "__slots__"):
        return {f: plain(getattr(value, f)) for f in value.__slots__}
    raise TypeError(f"unexpected decoded value {value!r}")


def main():
    path = sys.argv[1]
    factory = DecoderFactory()
    decoders = {}
    channels = {}
    messages = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.message_encoding != "cdr":
                continue
            if channel.topic not in channels:
                channels[channel.topic] = {
                    "message_encoding": channel.message_encoding,
                    "schema_name": schema.name,
                    "schema_encoding": schema.encoding,
                    "schema_data": schema.data.decode("utf-8"),
                    "metadata": dict(channel.metadata),
                    "qos": yaml.safe_load(channel.metadata.get("offered_qos_profiles", "")),
                }
            decode = decoders.get(channel.id)
            if decode is None:
                decode = factory.decoder_for(channel.message_encoding, schema)
                if decode is None:
                    sys.stderr.write(f"{channel.topic}: no decoder for {schema.encoding}\n")
                    sys.exit(4)
                decoders[channel.id] = decode
            try:
                decoded = decode(message.data)
            except Exception as e:  # noqa: BLE001 - any decoder failure is reported
                sys.stderr.write(f"{channel.topic} #{message.sequence}: {e}\n")
                sys.exit(4)
            messages.append(
                {
                    "topic": channel.topic,
                    "sequence": message.sequence,
                    "log_time": message.log_time,
                    "publish_time": message.publish_time,
                    "message": plain(decoded),
                }
            )
    json.dump({"profile": header.profile, "channels": channels, "messages": messages}, sys.stdout)


if __name__ == "__main__":
    main()
