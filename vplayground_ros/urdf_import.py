"""Robots from URDF (issue 38): a robot description as the World's bodies and joints.

Each link becomes a compound body (its collision elements the parts: box, sphere, cylinder, and
meshes as their convex hulls) with the link's inertial as given; links held by fixed joints are
lumped into their parent's body (their parts and inertia added), as Gazebo does, so a sensor
frame costs no body and no joint. Revolute, continuous and prismatic joints become the World's
joints with their limits (effort and velocity bound the motors a controller sets later). The
robot stands where its spec puts its root link, every joint at 0. Names: `<robot>.<link>` for
bodies, `<robot>.<joint>` for joints.

A file is read with yourdfpy; xacro (`.xacro`, or `$(...)`/`${...}` in a .urdf) is expanded
when the xacro package is installed, else refused saying so. Everything is checked before the
World is touched: what is wrong names the file and the link or joint.
"""
import codecs
import logging
import math
import os
import re
from collections import namedtuple
from pathlib import Path

import numpy as np

from .physics import specs
from .physics.math3d import axis_rotation, matrix_to_quaternion, quaternions_to_matrices, rpy_to_quat
from .physics.shapes.convex import MAX_HULL_POINTS
from .resources import is_file
from .scene import read_capped, read_mesh
from .urdf_robots import is_description_text

# What a robot description becomes: body specs (the root's first), joint specs, each link's body
# and pose in that body's frame (4x4), and the description's text (for robot_description).
# `self_collide`: whether its links collide with each other. `link_parents`: {link: its parent
# link} (the root has none; parents before children); `joint_names`: {URDF name: the World's
# joint} of the revolute, continuous and prismatic joints, in the description's order.
RobotModel = namedtuple("RobotModel", "bodies joints link_frames description self_collide link_parents joint_names "
                                       "visuals mimics body_links")
# `mimics`: {joint: (the joint it follows, multiplier, offset)} of <mimic> joints (URDF names);
# `body_links`: {body: the link whose frame is its frame (the others are lumped into it)}.
# A link's visual element as it is drawn: `kind` box, sphere, cylinder or mesh; `pose` xyz + xyzw
# in the link's frame; `size` the box's edges, (diameter, diameter, length) of a cylinder along
# its z, a sphere's diameter thrice; a mesh's `triangles` (T, 3, 3) in the pose's frame; rgba.
Visual = namedtuple("Visual", "link kind pose size triangles rgba")
DEFAULT_RGBA = (0.7, 0.7, 0.72, 1.0)  # a visual without a colour (URDF says nothing of one)
MAX_VISUAL_TRIANGLES = 400_000  # over a whole robot: beyond it meshes are left undrawn, with a warning
MAX_VISUALS = 4096  # visual elements drawn of a robot
MAX_MIMIC_MULTIPLIER = 1.0e3

JOINT_TYPES = {"revolute": "revolute", "continuous": "continuous", "prismatic": "prismatic"}
MAX_LINKS = 256
POINT_RADIUS = 1.0e-3  # m: the sphere that stands for a link without collision geometry (it collides with nothing)
log = logging.getLogger(__name__)


class UrdfError(ValueError):
    """A robot description that cannot be loaded: the message names the file and what is wrong."""


class UnreadableUrdf(UrdfError):
    """Not a description at all: unreadable XML, a file that is not there, xacro failing."""


class MissingMesh(UrdfError):
    """A mesh the description names is not found."""


# A description file is read whole: at most this (a scene's limit; a robot of hundreds of links
# is ~1 MB of XML).
MAX_DESCRIPTION_BYTES = 16 << 20
XML_DECLARATION = re.compile(r"^\ufeff?\s*<\?xml\b[^>]*?\?>")
DECLARED_ENCODING = re.compile(rb"^\s*<\?xml\b[^>]*?encoding\s*=\s*[\"']([A-Za-z][A-Za-z0-9._-]*)[\"']")


def xml_text(data, label):
    """XML bytes as text: UTF-16 after its byte-order mark, else in the encoding its declaration
    names, else UTF-8 (a byte-order mark removed)."""
    declared = DECLARED_ENCODING.match(data)
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        encoding = "utf-16"
    else:
        encoding = declared.group(1).decode("ascii") if declared else "utf-8-sig"
    try:
        return data.decode(encoding)
    except LookupError:
        raise UnreadableUrdf(f"{label}: its XML declaration names the encoding {encoding!r}, which is "
                             "not one Python knows") from None
    except UnicodeDecodeError as error:
        hint = "" if declared else " (a file in another encoding says which in <?xml ... encoding=\"...\"?>)"
        raise UnreadableUrdf(f"{label}: byte {error.start} is not {encoding.removesuffix('-sig')} text{hint}") from None


def read_description(source, label, allow_xacro=True):
    """The URDF text of `source` (a path, or the text itself when it starts with '<'), xacro
    expanded (unless not `allow_xacro`: xacro reads environment variables and any file, so a
    description from a request is refused rather than expanded). Returns (text, folder relative
    paths are taken from)."""
    if is_description_text(source):
        text, folder = source, Path.cwd()
    else:
        path = Path(source)
        try:
            data = read_capped(path, MAX_DESCRIPTION_BYTES, "description")
        except ValueError as error:
            raise UnreadableUrdf(f"{label}: {error}") from None
        text, folder = xml_text(data, label), path.resolve().parent
    # Text now: an XML declaration naming an encoding is left out, since the XML reader refuses
    # text that has one (a description with the common `<?xml ... encoding="utf-8"?>` could
    # not be loaded at all).
    declaration = XML_DECLARATION.match(text)
    if declaration is not None and "encoding" in declaration.group(0):
        text = text[declaration.end():]
    if Path(str(source)).suffix == ".xacro" or re.search(r"\$[({]", text):
        if not allow_xacro:
            raise UnreadableUrdf(f"{label}: it uses xacro, which is expanded only for scenes given on the command "
                                 "line (xacro reads environment variables and any file): expand it first "
                                 "(xacro file.xacro > file.urdf)")
        text = expand_xacro(text, label)
    return text, folder


def expand_xacro(text, label):
    try:
        import xacro
    except ImportError:
        raise UrdfError(f"{label}: it uses xacro ($(...) or ${{...}}), and the xacro package is not "
                        "installed: pip install xacro, or expand it first (xacro file.xacro > file.urdf)") from None
    from xml.dom.minidom import parseString
    try:
        document = parseString(text)
        xacro.process_doc(document)
    except Exception as error:  # xacro raises its own and the XML parser's errors
        raise UnreadableUrdf(f"{label}: xacro could not expand it: {error}") from None
    return document.toxml()


def parse(text, label):
    import xml.etree.ElementTree as ElementTree
    import yourdfpy
    from io import StringIO
    # NUL characters after the document (pybullet_data's humanoid ends with one; PyBullet reads
    # it) are no part of it.
    text = text.rstrip("\0\r\n\t ")
    try:
        ElementTree.fromstring(text)  # (yourdfpy says little of what is wrong with the XML)
    except ElementTree.ParseError as error:
        raise UnreadableUrdf(f"{label}: not well-formed XML: {error}") from None
    try:
        robot = yourdfpy.URDF.load(StringIO(text), build_scene_graph=False, load_meshes=False,
                                   load_collision_meshes=False).robot
    except Exception as error:  # yourdfpy raises what its XML and number parsing raise
        raise UnreadableUrdf(f"{label}: not a URDF robot yourdfpy can read: {error}") from None
    for kind, elements in (("link", robot.links), ("joint", robot.joints)):  # one of them had been lost
        names = [element.name for element in elements]
        twice = next((name for name in names if names.count(name) > 1), None)
        if twice is not None:
            raise UrdfError(f"{label}: two {kind}s are named {twice!r}")
    return robot


def origin(element):
    """An element's origin as a 4x4 transform (identity when it has none)."""
    return np.eye(4) if element is None or element.origin is None else np.asarray(element.origin, dtype=np.float64)


def pose_matrix(position, rotation):
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = rotation, position
    return matrix


# Where a description's meshes are looked for: its folder, and (a request's) the only directories
# they may be read from (None: anywhere).
Where = namedtuple("Where", "folder directories")


def resolve_mesh_file(filename, where, label, link):
    """A mesh's file: `package://<package>/<path>` in the package's share folder (AMENT_PREFIX_PATH),
    in a folder of that name above the description, or as <package>/<path> in the description's
    folder (PyBullet's reading: pybullet_data's Franka Panda names `package://meshes/...` beside
    it); `file://` and plain paths relative to the description's folder; within
    `where.directories` when it names some."""
    folder = where.folder
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://"):].partition("/")
        candidates = [Path(prefix) / "share" / package / rest
                      for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if prefix]
        candidates += [parent / rest for parent in [folder, *folder.parents] if parent.name == package]
        candidates.append(folder / package / rest)
    else:
        path = Path(filename[len("file://"):] if filename.startswith("file://") else filename)
        candidates = [path if path.is_absolute() else folder / path]
    for candidate in candidates:
        if is_file(candidate):
            if where.directories is not None and not any(
                    candidate.resolve().is_relative_to(Path(d).resolve()) for d in where.directories):
                raise UrdfError(f"{label}: link {link!r}: mesh {filename!r} is outside the allowed directories "
                                "(scene_directories)")
            return candidate
    raise MissingMesh(f"{label}: link {link!r}: mesh {filename!r} not found (looked in "
                    f"{', '.join(str(c) for c in candidates) or 'no package folder'})")


def hull_points(vertices, what="the mesh"):
    """At most MAX_HULL_POINTS points whose convex hull stands for a collision mesh: its hull's
    vertices, thinned by farthest-point sampling when there are more (the hull of the kept ones
    lies inside the mesh's, by at most the gaps between them). UrdfError (naming `what`) for
    a mesh with no volume: flat, a line, fewer than 4 points (qhull's own report had come out
    of a spawn as an internal error)."""
    from scipy.spatial import ConvexHull, QhullError
    try:
        hull = ConvexHull(vertices)
    except (QhullError, ValueError):
        raise UrdfError(f"{what} has no volume (flat, a line or fewer than 4 points): a collision mesh "
                        "needs one") from None
    points = np.asarray(vertices, dtype=np.float64)[hull.vertices]
    if len(points) <= MAX_HULL_POINTS:
        return points
    kept = [int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1)))]
    distance = np.linalg.norm(points - points[kept[0]], axis=1)
    while len(kept) < MAX_HULL_POINTS:
        kept.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[kept[-1]], axis=1))
    return points[kept]


def collision_part(collision, pose, where, label, link):
    """A compound part spec for one collision element at `pose` (4x4) in the body's frame."""
    geometry = collision.geometry
    placed = pose @ origin(collision)
    part = {"position": placed[:3, 3].tolist(),
            "quaternion": matrix_to_quaternion(placed[:3, :3]).tolist()}
    if geometry.box is not None:
        return {**part, "shape": "box", "size": [float(v) for v in geometry.box.size]}
    if geometry.sphere is not None:
        return {**part, "shape": "sphere", "radius": float(geometry.sphere.radius)}
    if geometry.cylinder is not None:  # along z in URDF as here
        return {**part, "shape": "cylinder", "radius": float(geometry.cylinder.radius),
                "length": float(geometry.cylinder.length)}
    if geometry.mesh is not None:
        path = resolve_mesh_file(geometry.mesh.filename, where, label, link)
        try:
            vertices, _ = read_mesh(path, f"link {link!r} mesh")
        except ValueError as error:
            raise UrdfError(f"{label}: {error}") from None
        what = f"{label}: link {link!r}: mesh {geometry.mesh.filename!r}"
        return {**part, "shape": "convex",
                "points": hull_points(np.asarray(vertices) * mesh_scale(geometry.mesh, what), what).tolist()}
    raise UrdfError(f"{label}: link {link!r}: a collision element without a geometry")


def mesh_scale(mesh, what):
    """A mesh element's scale: three finite numbers, none zero (or 1 when it gives none)."""
    if mesh.scale is None:
        return 1.0
    scale = np.asarray(mesh.scale, dtype=np.float64).reshape(-1)
    if scale.shape != (3,) or not np.all(np.isfinite(scale)) or not np.all(scale != 0.0):
        raise UrdfError(f"{what}: scale {' '.join(f'{v:g}' for v in scale)} is not three finite numbers, "
                        "none zero")
    return scale


def joint_axis(joint, label):
    """A joint's axis in its frame as written (x when it gives none): three finite numbers, not
    all zero (`<axis xyz="0 1"/>` had come out as numpy's shape mismatch)."""
    axis = np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), dtype=np.float64).reshape(-1)
    if axis.shape != (3,) or not np.all(np.isfinite(axis)):
        raise UrdfError(f"{label}: joint {joint.name!r}: axis {' '.join(f'{v:g}' for v in axis)} is not three "
                        "finite numbers")
    if not np.linalg.norm(axis) > 0.0:
        raise UrdfError(f"{label}: joint {joint.name!r}: its axis has no length")
    return axis


def link_inertial(link, label):
    """(mass, centre (3,), inertia (3, 3) about the centre, in the link's axes) of a link, or
    None without an inertial. A mass that is not positive, or an inertia tensor that is not
    positive definite or breaks the triangle inequality, is refused naming the link."""
    inertial = link.inertial
    if inertial is None or inertial.mass is None or inertial.mass == 0.0:
        return None
    mass = float(inertial.mass)
    frame = origin(inertial)
    tensor = np.asarray(inertial.inertia if inertial.inertia is not None else np.zeros((3, 3)), dtype=np.float64)
    if not (np.all(np.isfinite(tensor)) and np.all(np.isfinite(frame))):  # (eigvalsh fails to converge on them)
        raise UrdfError(f"{label}: link {link.name!r}: its inertial's inertia or origin is not finite")
    tensor = frame[:3, :3] @ tensor @ frame[:3, :3].T
    moments = np.linalg.eigvalsh(0.5 * (tensor + tensor.T))
    if not (math.isfinite(mass) and mass > 0.0):
        raise UrdfError(f"{label}: link {link.name!r}: mass {mass:g} kg is not physical")
    if not (np.all(np.isfinite(moments)) and moments.min() > 0.0
            and 2.0 * moments.max() <= moments.sum() * (1.0 + 1e-9)):
        raise UrdfError(f"{label}: link {link.name!r}: inertia (principal moments "
                        f"{', '.join(f'{m:g}' for m in moments)} kg m^2) is not physical: each must be "
                        "positive and none more than the other two together")
    return mass, frame[:3, 3].copy(), tensor


def combine_inertials(inertials):
    """(mass, centre, inertia about it) of several (mass, centre, inertia) in one frame."""
    mass = sum(m for m, _, _ in inertials)
    centre = sum(m * c for m, c, _ in inertials) / mass
    tensor = np.zeros((3, 3))
    for m, c, inertia in inertials:
        d = c - centre
        tensor += inertia + m * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return mass, centre, tensor


def joint_limits(joint):
    """A URDF joint's (lower, upper), -inf and inf where it has none (a continuous joint, a
    limit without that side)."""
    limit = joint.limit
    if limit is None or joint.type == "continuous":
        return -math.inf, math.inf
    return (-math.inf if limit.lower is None else float(limit.lower),
            math.inf if limit.upper is None else float(limit.upper))


def robot_model(source, name, position=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0), fixed_base=None,
                self_collide=False, joint_positions=None, label=None, quaternion=None, directories=None,
                description=None):
    """The RobotModel of a URDF file or text, its root link placed at `position` and `rpy` (or
    `quaternion`, x y z w, when given).
    `fixed_base`: the root is fixed to the world (None: when the root's body, with the links
    lumped into it, has no mass). `self_collide`: its links collide with each other (off, as
    PyBullet and Gazebo load URDF robots). `joint_positions`: {joint: rad or m} for joints not
    at 0 (the links placed accordingly, each joint's coordinate that value). `directories`:
    a request's scene_directories, the only places its meshes may be read from (and then no
    xacro); None for a scene of the user's own. `description`: (text, folder) as
    read_description gave them for `source`, when the caller read it already."""
    label = label or (str(source) if not is_description_text(source) else "URDF text")
    text, folder = description or read_description(source, label, allow_xacro=directories is None)
    where = Where(folder, directories)
    robot = parse(text, label)
    links = {link.name: link for link in robot.links}
    if len(links) > MAX_LINKS:
        raise UrdfError(f"{label}: {len(links)} links, more than {MAX_LINKS}")
    children = {}
    parent_joint = {}
    for joint in robot.joints:
        for end in (joint.parent, joint.child):
            if end not in links:
                raise UrdfError(f"{label}: joint {joint.name!r}: no link named {end!r}")
        if joint.child in parent_joint:
            raise UrdfError(f"{label}: joint {joint.name!r}: link {joint.child!r} already has the parent "
                            f"joint {parent_joint[joint.child].name!r} (a URDF is a tree: no loops)")
        if joint.type not in JOINT_TYPES and joint.type != "fixed":
            raise UrdfError(f"{label}: joint {joint.name!r}: type {joint.type!r} is not supported "
                            "(revolute, continuous, prismatic, fixed)")
        parent_joint[joint.child] = joint
        children.setdefault(joint.parent, []).append(joint)
    roots = [link for link in links if link not in parent_joint]
    if len(roots) != 1:
        raise UrdfError(f"{label}: {'no root link (a loop)' if not roots else f'{len(roots)} root links {roots}'}: "
                        "a robot is one tree of links")
    root = roots[0]
    joint_positions = dict(joint_positions or {})
    movable = {joint.name for joint in robot.joints if joint.type != "fixed"}
    for joint in sorted(set(joint_positions) - movable):
        raise UrdfError(f"{label}: joint_positions: no revolute, continuous or prismatic joint named {joint!r}")
    # A joint starts within its limits: past one, its correction would launch it across its
    # range. A position asked outside them is refused (but for the little a saved robot's joint
    # may be past one, as a scene's joint may: specs.within_limits); a description whose zero
    # lies outside them (pybullet_data's a1: its calves) starts at the nearest one.
    for joint in robot.joints:
        if joint.name not in movable:
            continue
        lower, upper = joint_limits(joint)
        if joint.name in joint_positions:
            value = float(joint_positions[joint.name])
            if not specs.within_limits(value, lower, upper):
                raise UrdfError(f"{label}: joint_positions: {joint.name!r} at {value:g} is outside its limits "
                                f"[{lower:g}, {upper:g}]")
        elif lower <= upper and not lower <= 0.0 <= upper:
            joint_positions[joint.name] = min(max(0.0, lower), upper)
    # Link poses in the world with the joints at their positions, and the body each link is
    # lumped into.
    turn = np.asarray(quaternion, dtype=np.float64) if quaternion is not None else rpy_to_quat(rpy)
    base = pose_matrix(position, quaternions_to_matrices(turn[None])[0])
    world_pose, body_of, order = {root: base}, {root: root}, [root]
    for link in order:  # breadth first: parents before children
        for joint in children.get(link, []):
            world_pose[joint.child] = (world_pose[link] @ origin(joint)
                                       @ joint_motion(joint, joint_positions.get(joint.name, 0.0), label))
            body_of[joint.child] = body_of[link] if joint.type == "fixed" else joint.child
            order.append(joint.child)
    if len(order) != len(links):  # cannot happen for a tree with one root; kept as a check
        raise UrdfError(f"{label}: links not reached from the root {root!r}")
    bodies, link_frames = {}, {}
    for link in order:
        owner = body_of[link]
        pose = np.linalg.inv(world_pose[owner]) @ world_pose[link]  # the link in its body's frame
        link_frames[link] = (body_name(name, owner, label), pose)
        entry = bodies.setdefault(owner, {"parts": [], "inertials": []})
        entry["parts"] += [collision_part(c, pose, where, label, link) for c in links[link].collisions]
        inertial = link_inertial(links[link], label)
        if inertial is not None:
            mass, centre, tensor = inertial
            entry["inertials"].append((mass, pose[:3, :3] @ centre + pose[:3, 3],
                                       pose[:3, :3] @ tensor @ pose[:3, :3].T))
    # A root body without mass (PyBullet's and Gazebo's way of fixing a robot), or a root link
    # named world (Gazebo's), is fixed.
    fixed = (not bodies[root]["inertials"] or root == "world") if fixed_base is None else fixed_base
    named = {}
    for owner in bodies:
        other = named.setdefault(body_name(name, owner, label), owner)
        if other != owner:
            raise UrdfError(f"{label}: links {other!r} and {owner!r} both make the body "
                            f"{body_name(name, owner, label)!r}")
    body_specs = []
    for owner, entry in bodies.items():
        collides = bool(entry["parts"])
        if not collides:
            # No collision geometry (a steering hinge between a chassis and its wheel, a chassis
            # that only its wheels carry): a body that collides with nothing, as in Gazebo and
            # PyBullet; a point-like sphere at its centre of mass (or its origin) gives it the
            # shape every body has (its mass and inertia are the inertial's).
            centre = combine_inertials(entry["inertials"])[1] if entry["inertials"] else np.zeros(3)
            entry["parts"] = [{"shape": "sphere", "radius": POINT_RADIUS, "position": centre.tolist(),
                               "quaternion": [0.0, 0.0, 0.0, 1.0]}]
        spec = {"name": body_name(name, owner, label), "shape": "compound", "parts": entry["parts"],
                "position": world_pose[owner][:3, 3].tolist(),
                "quaternion": matrix_to_quaternion(world_pose[owner][:3, :3]).tolist()}
        if not collides:
            spec["collides"] = False
        if entry["inertials"]:
            mass, centre, tensor = combine_inertials(entry["inertials"])
            spec["inertial"] = {"mass": mass, "centre": centre.tolist(), "inertia": tensor.tolist()}
        elif not (owner == root and fixed):
            raise UrdfError(f"{label}: link {owner!r}: no inertial, or a mass of 0 (mass and inertia are "
                            "needed for every moving link)")
        if owner == root and fixed:
            spec["immovable"] = True
        body_specs.append(spec)
    joint_specs, joint_names = [], {}
    for link in order[1:]:
        joint = parent_joint[link]
        if joint.type == "fixed":
            continue
        frame = world_pose[joint.parent] @ origin(joint)
        axis = joint_axis(joint, label)
        axis = frame[:3, :3] @ axis / np.linalg.norm(axis)
        moved = float(joint_positions.get(joint.name, 0.0))
        # The child's anchor: where the joint's origin went (along the axis for a prismatic).
        anchor = frame[:3, 3] + (moved * axis if joint.type == "prismatic" else 0.0)
        spec = {"name": entity_name(name, joint.name, "joint", label), "type": JOINT_TYPES[joint.type],
                "parent": body_name(name, body_of[joint.parent], label),
                "child": body_name(name, link, label), "anchor": anchor.tolist(),
                "axis": axis.tolist(), "position": moved}
        for key, value in zip(("lower", "upper"), joint_limits(joint)):
            if math.isfinite(value):
                spec[key] = value
        limit = joint.limit
        motor = {}
        if limit is not None and limit.effort:
            motor["max_effort"] = float(limit.effort)
        if limit is not None and limit.velocity:
            motor["max_speed"] = float(limit.velocity)
        if motor:
            spec["motor"] = motor
        try:
            joint_specs.append(specs.validate_joint(spec, f"joint {joint.name!r}"))
        except specs.SpecError as error:
            raise UrdfError(f"{label}: {error}") from None
        joint_names[joint.name] = spec["name"]
    visuals = link_visuals(robot, where, label)
    link_parents = {link: parent_joint[link].parent for link in order[1:]}
    joint_names = {joint.name: joint_names[joint.name] for joint in robot.joints if joint.name in joint_names}
    mimics = {}
    for joint in robot.joints:
        if joint.mimic is None:
            continue
        if joint.name not in joint_names or joint.mimic.joint not in joint_names:
            raise UrdfError(f"{label}: joint {joint.name!r}: mimics {joint.mimic.joint!r}; both must be revolute, "
                            "continuous or prismatic joints of the description")
        multiplier = 1.0 if joint.mimic.multiplier is None else float(joint.mimic.multiplier)
        offset = 0.0 if joint.mimic.offset is None else float(joint.mimic.offset)
        if not (abs(multiplier) <= MAX_MIMIC_MULTIPLIER and abs(offset) <= specs.MAX_COORDINATE):
            raise UrdfError(f"{label}: joint {joint.name!r}: mimic multiplier {multiplier:g} or offset {offset:g} "
                            f"out of range (|multiplier| <= {MAX_MIMIC_MULTIPLIER:g}, |offset| <= "
                            f"{specs.MAX_COORDINATE:g})")
        mimics[joint.name] = (joint.mimic.joint, multiplier, offset)
    for joint, (leader, _, _) in mimics.items():
        if leader in mimics:
            raise UrdfError(f"{label}: joint {joint!r} mimics {leader!r}, which mimics another joint itself")
    body_links = {body_name(name, owner, label): owner for owner in bodies}
    return RobotModel(body_specs, joint_specs, link_frames, text, bool(self_collide), link_parents, joint_names,
                      visuals, mimics, body_links)


def link_visuals(robot, where, label):
    """Every link's <visual> elements as Visuals (what the node draws for the robot; collisions
    are the bodies'). A visual is only a picture: one whose mesh is missing or unreadable is
    left out with a warning, not refused; each mesh file is read once, none once
    MAX_VISUAL_TRIANGLES are drawn, and at most MAX_VISUALS elements are."""
    palette = {m.name: m.color.rgba for m in robot.materials if m.color is not None}
    out, triangles, meshes = [], 0, {}
    for link in robot.links:
        for visual in link.visuals:
            geometry, pose = visual.geometry, origin(visual)
            material = visual.material
            rgba = (material.color.rgba if material is not None and material.color is not None
                    else palette.get(material.name) if material is not None else None)
            rgba = tuple(float(v) for v in (rgba if rgba is not None else DEFAULT_RGBA))
            placed = [*pose[:3, 3].tolist(), *matrix_to_quaternion(pose[:3, :3]).tolist()]
            if geometry.box is not None:
                out.append(Visual(link.name, "box", placed, [float(v) for v in geometry.box.size], None, rgba))
            elif geometry.sphere is not None:
                out.append(Visual(link.name, "sphere", placed, [2.0 * float(geometry.sphere.radius)] * 3, None, rgba))
            elif geometry.cylinder is not None:
                d = 2.0 * float(geometry.cylinder.radius)
                out.append(Visual(link.name, "cylinder", placed, [d, d, float(geometry.cylinder.length)], None, rgba))
            elif geometry.mesh is not None and triangles <= MAX_VISUAL_TRIANGLES:
                try:
                    path = resolve_mesh_file(geometry.mesh.filename, where, label, link.name)
                    if path not in meshes:
                        vertices, faces = read_mesh(path, f"link {link.name!r} visual mesh")
                        meshes[path] = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
                except (UrdfError, ValueError) as error:
                    log.warning("%s (the link is drawn without it)", error)
                    continue
                mesh = meshes[path] * mesh_scale(geometry.mesh, f"{label}: link {link.name!r}: visual mesh "
                                                                f"{geometry.mesh.filename!r}")
                triangles += len(mesh)
                if triangles > MAX_VISUAL_TRIANGLES:
                    log.warning("%s: more than %d visual triangles: link %r and the rest drawn without meshes",
                                label, MAX_VISUAL_TRIANGLES, link.name)
                    continue
                out.append(Visual(link.name, "mesh", placed, [1.0, 1.0, 1.0], mesh, rgba))
            if len(out) >= MAX_VISUALS:
                log.warning("%s: more than %d visual elements: the rest are not drawn", label, MAX_VISUALS)
                return out
    return out


def joint_motion(joint, value, label):
    """The transform a joint at `value` adds after its origin: a turn about its axis (revolute,
    continuous) or a slide along it (prismatic)."""
    if value == 0.0 or joint.type == "fixed":
        return np.eye(4)
    axis = joint_axis(joint, label)
    axis = axis / np.linalg.norm(axis)
    motion = np.eye(4)
    if joint.type == "prismatic":
        motion[:3, 3] = value * axis
    else:
        motion[:3, :3] = axis_rotation(axis, value)
    return motion


def renamed(model, old, new):
    """The RobotModel of robot `old` with its bodies and joints named after `new` instead."""
    def rename(name):
        return new + name[len(old):]
    bodies = [{**spec, "name": rename(spec["name"])} for spec in model.bodies]
    joints = [{**spec, "name": rename(spec["name"]), "parent": rename(spec["parent"]), "child": rename(spec["child"])}
              for spec in model.joints]
    for spec in bodies + joints:
        if not specs.NAME_PATTERN.fullmatch(spec["name"]):
            raise UrdfError(f"the name {spec['name']!r} is longer than 64 characters (give the robot a shorter name)")
    return model._replace(bodies=bodies, joints=joints,
                          link_frames={link: (rename(body), pose) for link, (body, pose) in model.link_frames.items()},
                          joint_names={joint: rename(entity) for joint, entity in model.joint_names.items()},
                          body_links={rename(body): link for body, link in model.body_links.items()})


def body_name(robot, link, label):
    return entity_name(robot, link, "link", label)


def entity_name(robot, element, kind, label):
    """`<robot>.<element>`, the element's characters a name may not have as '_'."""
    name = f"{robot}.{re.sub(r'[^A-Za-z0-9_.-]', '_', element)}"
    if not specs.NAME_PATTERN.fullmatch(name):
        raise UrdfError(f"{label}: {kind} {element!r}: the name {name!r} is longer than 64 characters "
                        "(give the robot a shorter name)")
    return name


def add_robot(world, model):
    """Adds a RobotModel's bodies and joints to `world`, all or none: every body is checked and
    every name looked up first, and a refusal the World makes on the way (a body outside the
    world) removes what was added."""
    from .physics.world import prepare_body
    taken = set(world.body_names())
    for spec in model.bodies:
        if spec["name"] in taken:
            raise UrdfError(f"a body named {spec['name']!r} already exists")
        prepare_body(spec, spec["name"])
    joints = set(world.joint_names())
    for spec in model.joints:
        if spec["name"] in joints:
            raise UrdfError(f"a joint named {spec['name']!r} already exists")
    added = []
    try:
        for spec in model.bodies:
            added.append(world.add_body(spec, spec["name"]))
        for spec in model.joints:
            world.add_joint(spec, spec["name"])
        if not model.self_collide:
            world.disable_collisions(added)
    except ValueError:
        world.remove_bodies(added)  # and with them their joints
        raise
    return added
