"""Message definitions as text (`ros2msg` schemas for MCAP and Foxglove), read from the
installed .msg files: `<prefix>/share/<package>/msg/<Type>.msg` of a ROS install or of the
Jazzy wheels, or this package's own copies (tf2_msgs, which the wheels do not ship).

A schema is the type's definition followed by every type it depends on, each after a line of
80 '=' and `MSG: package/Type`, spelled as the .msg fields spell it (Foxglove's parser rejects
`package/msg/Type`). builtin_interfaces/Time and Duration are ROS 2 primitives: not listed.
"""
import os
import re
import sys
from functools import lru_cache
from pathlib import Path

OWN_DEFINITIONS = Path(__file__).resolve().parent / "msg_definitions"
PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}
BUILTIN = {"builtin_interfaces/Time", "builtin_interfaces/Duration"}
SEPARATOR = "=" * 80


def search_roots():
    roots = [Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    roots.append(Path(sys.prefix) / "share")
    roots.append(OWN_DEFINITIONS)
    return roots


@lru_cache(maxsize=None)
def definition(package, name):
    """The .msg text of package/name (comments kept, as rosbag2 writes them)."""
    for root in search_roots():
        path = root / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path.read_text(encoding="utf-8")
    raise LookupError(f"no message definition for {package}/msg/{name} (looked in the ament "
                      f"prefixes, {sys.prefix}/share and {OWN_DEFINITIONS})")


def field_types(package, text):
    """package/Type of every non-primitive field of a definition."""
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or "=" in line.split()[0] or len(line.split()) < 2:
            continue
        kind = re.sub(r"\[.*\]$", "", line.split()[0])
        kind = re.sub(r"<=\d+$", "", kind)
        if kind in PRIMITIVES or kind.split("<=")[0] in PRIMITIVES:
            continue
        if kind == "Header":
            kind = "std_msgs/Header"
        yield kind if "/" in kind else f"{package}/{kind}"


@lru_cache(maxsize=None)
def schema(type_name):
    """The full ros2msg schema text of e.g. 'visualization_msgs/msg/MarkerArray'."""
    package, _, name = type_name.partition("/msg/")
    text = definition(package, name)
    order, seen = [], set()

    def visit(pkg, body):
        for dep in field_types(pkg, body):
            if dep in seen or dep in BUILTIN:
                continue
            seen.add(dep)
            dep_pkg, dep_name = dep.split("/")
            dep_text = definition(dep_pkg, dep_name)
            order.append((dep, dep_text))
            visit(dep_pkg, dep_text)
    visit(package, text)
    parts = [text.rstrip("\n")]
    for dep, dep_text in order:
        parts.append(f"{SEPARATOR}\nMSG: {dep}\n{dep_text.rstrip(chr(10))}")
    return "\n".join(parts) + "\n"
