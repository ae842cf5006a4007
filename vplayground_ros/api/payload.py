"""Request payloads: YAML or JSON text, size- and depth-limited, into plain data, and the
geometry_msgs spellings (points, quaternions, poses) into the body keys the specs validate.
"""
import json

import yaml

from ..physics import specs
from ..scene import load_yaml
from .results import FAILED, INVALID_POSE, RequestError

MAX_PAYLOAD = 1 << 20  # bytes of YAML a request may carry
YAML_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # replies and saved scenes


def parse(text, what="request"):
    if not isinstance(text, str):
        raise RequestError(FAILED, f"{what} must be YAML or JSON text")
    if len(text) > MAX_PAYLOAD or len(text.encode("utf-8", "surrogatepass")) > MAX_PAYLOAD:
        raise RequestError(FAILED, f"{what} is larger than {MAX_PAYLOAD} bytes")
    try:
        if text.lstrip()[:1] in ("{", "["):
            try:
                return json.loads(text)  # JSON, what programs send: ~50x faster than YAML
            except json.JSONDecodeError:
                pass  # flow-style YAML such as {name: a}
        return load_yaml(text)
    except yaml.YAMLError as error:
        raise RequestError(FAILED, f"{what} is not valid YAML/JSON: {str(error)[:300]}") from None
    except RecursionError:
        raise RequestError(FAILED, f"{what} is nested too deeply") from None
    except ValueError as error:  # integers of more than 4,300 digits, unencodable characters
        raise RequestError(FAILED, f"{what} is not valid YAML/JSON: {str(error)[:300]}") from None


def as_mapping(value, what):
    if not isinstance(value, dict):
        raise RequestError(FAILED, f"{what} must be a mapping, got {type(value).__name__}")
    return value


def xyz(value, path, length=3):
    """[x, y, z] or {x:, y:, z:} (the geometry_msgs spelling) as a list."""
    if isinstance(value, dict):
        keys = "xyzw"[:length]
        specs.mapping(value, path, set(keys))
        value = [value.get(k, 1.0 if k == "w" else 0.0) for k in keys]
    return specs.vector(value, path, length, -specs.MAX_COORDINATE, specs.MAX_COORDINATE)


def pose_fields(pose, path):
    """{position, orientation} (or a PoseStamped's {header, pose}) as body keys; INVALID_POSE
    naming the key when a value is bad."""
    try:
        specs.mapping(pose, path, {"position", "orientation", "header", "pose"})
        if "pose" in pose:
            path = f"{path}.pose"
            pose = specs.mapping(pose["pose"], path, {"position", "orientation"})
        fields = {}
        if "position" in pose:
            fields["position"] = xyz(pose["position"], f"{path}.position")
        if "orientation" in pose:
            fields["quaternion"] = specs.quaternion(xyz(pose["orientation"], f"{path}.orientation", 4),
                                                    f"{path}.orientation")
        return fields
    except specs.SpecError as error:
        raise RequestError(INVALID_POSE, str(error)) from None



def header_frame(stamped, path):
    """The `header.frame_id` of a stamped mapping (a PoseStamped, an EntityState): '' without
    one. The stamp is ignored (simulation_interfaces: the state is set now)."""
    if not isinstance(stamped, dict) or stamped.get("header") is None:
        return ""
    header = specs.mapping(stamped["header"], f"{path}.header", {"frame_id", "stamp"})
    frame = header.get("frame_id", "")
    if not isinstance(frame, str):
        raise RequestError(INVALID_POSE, f"{path}.header.frame_id: expected a frame name, got {specs.quote(frame)}")
    return frame
