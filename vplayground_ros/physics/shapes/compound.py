"""Compound: one rigid body made of several parts, each a shape of its own (box, sphere,
capsule, cylinder, convex) at a pose in the body's frame: `parts: [{shape: box, size: [...],
position: [...], rpy: [...], mass or density}, ...]`. What a URDF link with several collision
elements is.

The body's frame is the one its spec places (`position`, `rpy`); the engine moves its centre of
mass, `centre` in that frame (so a compound's `position` in the engine arrays is not its
frame's). Mass, centre of mass and the full inertia tensor are the parts' sums (parallel axis
theorem, each part's tensor turned into the body's axes); the body keeps its frame's axes, the
tensor is not diagonalised.

The parts of all compound bodies live in one table (Parts) that the World owns, beside the hull
table: body slot s has rows start[s] .. start[s] + count[s], each part's pose relative to the
centre of mass in the body's axes. A convex part's hull is a row of the hull table (`hull`).
A compound's `dimensions` are the half extents of a box about its centre of mass that holds
every part in any orientation, as a convex body's are: the broad phase, the speculative reach
and the ray grid need no other case.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from ..math3d import quat_to_matrix, rpy_to_quat

SPEC_KEYS = ("parts", "inertial")
DEFAULTS = {}

# Parts of one body at most: the narrow phase's warm-start keys hold a part's index in 6 bits.
MAX_PARTS = 64

Parts = namedtuple("Parts", [
    "start", "count",  # (N,) int64 per body slot: its rows (count 0 for the other shapes)
    "shape",           # (P,) int64 shape code of each part (never compound)
    "dimensions",      # (P, 3) the part's shape's numbers (physics.shapes.<shape>)
    "position",        # (P, 3) the part's centre relative to the body's centre of mass, body axes, m
    "rotation",        # (P, 3, 3) part axes -> body axes
    "hull",            # (P,) int64 row of a convex part's hull in the hull table, else -1
    "radius",          # (P,) m, a sphere about `position` holding the part (culls part pairs)
])

# One part as the World keeps it: its validated spec (with its mass), its shapes.Solid, its
# centre and orientation (quaternion) in the body's frame, and its mass.
Part = namedtuple("Part", "spec code solid centre quaternion mass")

# What a compound body is beyond a shapes.Solid's numbers: its parts, its centre of mass in its
# frame, the mass of the parts (which a body's `mass` key scales), and its `inertial` spec when
# the mass properties are given rather than the parts' (a URDF link's), else None.
Compound = namedtuple("Compound", "parts centre mass inertial")

# A compound's parts as drawn (frame_parts).
FrameParts = namedtuple("FrameParts", "codes dimensions poses hull_triangles")


def combine(parts, half_extents_of, inertial=None):
    """The Compound of `parts` (Part), and the body's (dimensions, volume, inertia per kg (3, 3)
    about the centre of mass in the body's axes). `half_extents_of(code, dims)` is
    shapes.half_extents. A validated `inertial` (mass, centre, inertia) replaces the parts'
    sums."""
    masses = np.array([part.mass for part in parts])
    mass = float(masses.sum())
    centres = np.array([part.centre for part in parts])
    centre = (masses[:, None] * centres).sum(axis=0) / mass
    if inertial is not None:
        mass, centre = float(inertial["mass"]), np.asarray(inertial["centre"], dtype=np.float64)
    inertia, reach = np.zeros((3, 3)), np.zeros(3)
    for part, offset in zip(parts, centres - centre):
        turn = part_rotation(part)
        # its own tensor turned into the body's axes, and the parallel axis term
        inertia += part.mass * (turn @ part.solid.unit_inertia @ turn.T)
        inertia += part.mass * (offset @ offset * np.eye(3) - np.outer(offset, offset))
        # its bounding box turned into the body's axes, about the centre of mass
        reach = np.maximum(reach, np.abs(offset) + np.abs(turn) @ np.asarray(half_extents_of(part.code, part.solid.dimensions)))
    if inertial is not None:
        inertia = np.asarray(inertial["inertia"], dtype=np.float64)
    volume = float(sum(part.solid.volume for part in parts))
    return Compound(parts, centre, mass, inertial), tuple(float(r) for r in reach), volume, inertia / mass


def part_rotation(part):
    r = np.empty((3, 3))
    quat_to_matrix(part.quaternion, r)
    return r


def make_part(spec, code, solid, density):
    """A Part from a validated part spec and its shapes.Solid; `density` the body's, for a part
    that gives neither mass nor density. A convex part's hull is centred on its centre of mass,
    which lies at `position` plus the turned hull centre."""
    quaternion = np.asarray(spec["quaternion"] if "quaternion" in spec else rpy_to_quat(spec.get("rpy", (0, 0, 0))), float)
    centre = np.asarray(spec["position"], float)
    if solid.hull is not None:
        r = np.empty((3, 3))
        quat_to_matrix(quaternion, r)
        centre = centre + r @ solid.hull.centre
    mass = spec["mass"] if "mass" in spec else spec.get("density", density) * solid.volume
    # Saved with its mass alone (a mass wins over a density, as a body's does).
    kept = {key: value for key, value in spec.items() if key != "density"}
    return Part({**kept, "mass": float(mass)}, code, solid, centre, quaternion, float(mass))


def spec_fields(compound):
    """The keys a scene holds: each part as given, with its mass."""
    fields = {"parts": [dict(part.spec) for part in compound.parts]}
    if compound.inertial is not None:
        fields["inertial"] = compound.inertial
    return fields


def pack_parts(compounds, first_hull):
    """The Parts table of a list of Compound or None, one per body slot, and the hulls of its
    convex parts in row order; those take hull-table rows from `first_hull` on."""
    start = np.zeros(len(compounds), np.int64)
    count = np.zeros(len(compounds), np.int64)
    rows, hulls = [], []
    for slot, compound in enumerate(compounds):
        if compound is None:
            continue
        start[slot], count[slot] = len(rows), len(compound.parts)
        for part in compound.parts:
            hull = -1
            if part.solid.hull is not None:
                hull = first_hull + len(hulls)
                hulls.append(part.solid.hull)
            rows.append((part, part.centre - compound.centre, hull))
    n = len(rows)
    table = Parts(start, count, np.zeros(n, np.int64), np.zeros((n, 3)), np.zeros((n, 3)),
                  np.zeros((n, 3, 3)), np.full(n, -1, np.int64), np.zeros(n))
    for k, (part, offset, hull) in enumerate(rows):
        table.shape[k] = part.code
        table.dimensions[k] = part.solid.dimensions
        table.position[k] = offset
        quat_to_matrix(part.quaternion, table.rotation[k])
        table.hull[k] = hull
        table.radius[k] = part_radius(part)
    return table, hulls


def part_radius(part):
    """A sphere about the part's centre that holds it: a sphere's radius, else the half diagonal
    of its bounding box."""
    dims = part.solid.dimensions
    if part.spec["shape"] == "sphere":
        return dims[0]
    if part.spec["shape"] == "capsule":
        return dims[0] + dims[1]
    if part.spec["shape"] == "cylinder":
        return float(np.hypot(dims[0], dims[1]))
    return float(np.linalg.norm(dims))


def frame_parts(compound):
    """The parts as drawn, in the body's frame: (shape codes (K,), dimensions (K, 3), poses
    (K, 7) xyz + xyzw of each part's centre, hull triangles about that centre or None)."""
    parts = compound.parts
    return FrameParts(np.array([p.code for p in parts], np.int64), np.array([p.solid.dimensions for p in parts], float),
                      np.array([[*p.centre, *p.quaternion] for p in parts], float),
                      tuple(p.solid.hull.triangles if p.solid.hull is not None else None for p in parts))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def part_pose(parts, k, p, r):
    """Part row k of a body at position p, rotation r (tuples: rows) in the world: (shape code,
    position, rotation rows, dimensions, hull row), as the narrow phase takes a shape."""
    q, t = parts.position, parts.rotation
    position = (p[0] + r[0][0] * q[k, 0] + r[0][1] * q[k, 1] + r[0][2] * q[k, 2],
                p[1] + r[1][0] * q[k, 0] + r[1][1] * q[k, 1] + r[1][2] * q[k, 2],
                p[2] + r[2][0] * q[k, 0] + r[2][1] * q[k, 1] + r[2][2] * q[k, 2])
    rotation = ((r[0][0] * t[k, 0, 0] + r[0][1] * t[k, 1, 0] + r[0][2] * t[k, 2, 0],
                 r[0][0] * t[k, 0, 1] + r[0][1] * t[k, 1, 1] + r[0][2] * t[k, 2, 1],
                 r[0][0] * t[k, 0, 2] + r[0][1] * t[k, 1, 2] + r[0][2] * t[k, 2, 2]),
                (r[1][0] * t[k, 0, 0] + r[1][1] * t[k, 1, 0] + r[1][2] * t[k, 2, 0],
                 r[1][0] * t[k, 0, 1] + r[1][1] * t[k, 1, 1] + r[1][2] * t[k, 2, 1],
                 r[1][0] * t[k, 0, 2] + r[1][1] * t[k, 1, 2] + r[1][2] * t[k, 2, 2]),
                (r[2][0] * t[k, 0, 0] + r[2][1] * t[k, 1, 0] + r[2][2] * t[k, 2, 0],
                 r[2][0] * t[k, 0, 1] + r[2][1] * t[k, 1, 1] + r[2][2] * t[k, 2, 1],
                 r[2][0] * t[k, 0, 2] + r[2][1] * t[k, 1, 2] + r[2][2] * t[k, 2, 2]))
    dims = (parts.dimensions[k, 0], parts.dimensions[k, 1], parts.dimensions[k, 2])
    return parts.shape[k], position, rotation, dims, parts.hull[k]
