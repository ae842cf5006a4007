"""Message and service definitions as text, and CDR encoders/decoders built from them, with no
rclpy involved: the bag, the ROS publishers and the Foxglove server all take the bytes made
here (or by cdr.py for the big arrays).

Definitions are read from `<prefix>/share/<package>/{msg,srv}/<Type>.{msg,srv}`: first a ROS
install's (AMENT_PREFIX_PATH) or the Jazzy wheels' (sys.prefix), then this package's own
copies in msg_definitions/ (every type the node uses, so the Foxglove server and the bags work
where no interface package is installed; a test checks they equal the installed ones), and in
a source checkout the vendored simulation_interfaces (interfaces/).

A schema (`ros2msg`) is the type's definition followed by every type it depends on, each after
a line of 80 '=' and `MSG: package/Type`, spelled as the .msg fields spell it (Foxglove's parser
rejects `package/msg/Type`); builtin_interfaces/Time and Duration too, as rosbag2 writes them
(SPEC 7: complete definitions; readers take them as the time types either way). A service's request and response are the parts of its .srv before and after `---`,
named `package/srv/Type_Request` and `package/srv/Type_Response` (as rosidl names them).
"""
import os
import re
import sys
from functools import lru_cache
from pathlib import Path

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

OWN_DEFINITIONS = Path(__file__).resolve().parent / "msg_definitions"
VENDORED = Path(__file__).resolve().parent.parent / "interfaces"
PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}
SEPARATOR = "=" * 80


def search_roots():
    roots = [Path(p) / "share" for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    roots.append(Path(sys.prefix) / "share")
    roots.append(OWN_DEFINITIONS)
    if VENDORED.is_dir():  # a source checkout: simulation_interfaces even where it is not built
        roots.append(VENDORED)
    return roots


@lru_cache(maxsize=None)
def definition(package, name, kind="msg"):
    """The .msg (or .srv) text of package/kind/name (comments kept, as rosbag2 writes them)."""
    for root in search_roots():
        path = root / package / kind / f"{name}.{kind}"
        if path.is_file():
            return path.read_text(encoding="utf-8")
    raise LookupError(f"no definition for {package}/{kind}/{name} (looked in the ament "
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


def own_text(type_name):
    """(package, the type's own definition text) of 'pkg/msg/Type' or 'pkg/srv/Type_Request'."""
    package, kind, name = type_name.split("/")
    if kind == "msg":
        return package, definition(package, name)
    service, _, part = name.rpartition("_")
    if kind != "srv" or part not in ("Request", "Response"):
        raise LookupError(f"{type_name} is neither package/msg/Type nor package/srv/Type_Request|_Response")
    request, response = re.split(r"^---\s*$", definition(package, service, "srv"), maxsplit=1, flags=re.M)
    return package, (request if part == "Request" else response).strip("\n") + "\n"


@lru_cache(maxsize=None)
def schema(type_name):
    """The full ros2msg schema text of e.g. 'visualization_msgs/msg/MarkerArray'."""
    package, text = own_text(type_name)
    order, seen = [], set()

    def visit(pkg, body):
        for dep in field_types(pkg, body):
            if dep in seen:
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


@lru_cache(maxsize=None)
def encoder(type_name):
    """fn(message as nested dicts or objects; missing fields are zero) -> CDR bytes,
    encapsulation header included."""
    return serialize_dynamic(type_name, schema(type_name))[type_name]


@lru_cache(maxsize=None)
def decoder(type_name):
    """fn(CDR bytes) -> the message as an object with attribute access."""
    return generate_dynamic(type_name, schema(type_name))[type_name]


def encode(type_name, message):
    return encoder(type_name)(message)
