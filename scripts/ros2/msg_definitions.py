#!/usr/bin/env python3
"""Full ROS 2 message definitions, as `ros2 bag record -s mcap` stores them.

rosbag2 (`LocalMessageDefinitionSource::get_full_text`, rosbag2_cpp) writes
an MCAP schema of encoding `ros2msg` whose data is the type's `.msg` file,
then, depth first, for every dependency not written yet (in sorted order of
the names as the `.msg` files spell them, a name without a package taking
the package of the file that uses it):

    "\n" + "=" * 80 + "\n" + "MSG: <pkg>/<Type>\n" + <that type's full text>

Dependencies are found as rosbag2 finds them: a word (letters, digits, `_`,
`/`) at the start of a line, optionally followed by `[...]`, then
whitespace, that is not a primitive type.

This script rebuilds that text from the installed ROS 2 Jazzy wheels'
`share/<pkg>/msg/<Type>.msg` files (under AMENT_PREFIX_PATH, then
sys.prefix), independently of echelon's embedded constants.

Usage: msg_definitions.py pkg/msg/Type ...   prints {"pkg/msg/Type": "<full text>", ...}
Exit status 3 with a message on stderr when a .msg file is missing.
"""

import json
import os
import re
import sys

INSTALL_HINT = (
    "ROS 2 Jazzy message packages missing: run scripts/test, or "
    "`python3 -m pip install -r scripts/requirements-ros2.txt` (Python 3.11)"
)

FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16",
    "uint16", "int32", "uint32", "int64", "uint64", "string",
}
DELIMITER = "=" * 80 + "\n"


def fail(message):
    sys.stderr.write(f"{message}\n{INSTALL_HINT}\n")
    sys.exit(3)


def share_dirs():
    dirs = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    dirs.append(sys.prefix)
    return [os.path.join(d, "share") for d in dirs]


def msg_text(type_name):
    parts = type_name.split("/")
    if len(parts) == 2:
        pkg, ns, name = parts[0], "msg", parts[1]
    elif len(parts) == 3:
        pkg, ns, name = parts
    else:
        fail(f"type name not understood: {type_name}")
    for share in share_dirs():
        path = os.path.join(share, pkg, ns, f"{name}.msg")
        if os.path.exists(path):
            # rosbag2 reads the file as bytes: no newline translation.
            with open(path, "rb") as f:
                return pkg, f.read().decode("utf-8")
    fail(f"no {pkg}/{ns}/{name}.msg under {share_dirs()}")


def dependencies(text, package):
    deps = set()
    for m in FIELD_TYPE.finditer(text):
        t = m.group(1)
        if t in PRIMITIVES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)


def full_text(root):
    seen = set()

    def append(type_name):
        package, text = msg_text(type_name)
        out = text
        for dep in dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                out += "\n" + DELIMITER + f"MSG: {dep}\n" + append(dep)
        return out

    return append(root)


def main():
    json.dump({t: full_text(t) for t in sys.argv[1:]}, sys.stdout)


if __name__ == "__main__":
    main()
