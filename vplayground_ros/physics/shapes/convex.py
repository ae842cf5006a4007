"""Convex: the convex hull of `points` (body frame; a scene's `mesh:` is read into them by the
loader). The hull is recentred on its centre of mass, so a convex body's `position` is its
centre of mass; its orientation is the mesh's. Mass properties are those of the solid hull.

The hulls of all convex bodies live in one table (Hulls) that the World owns; a body refers to
its hull by `bodies.hull`, and its dimensions are the half extents of the hull's bounding box.
Faces are the hull's planar polygons (coplanar triangles merged), counter-clockwise seen from
outside, so a convex body resting on a face gets that face's corners as its manifold.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .geometry import NO_HIT

SPEC_KEYS = ("points",)
DEFAULTS = {}

# A hull may have at most this many vertices: the support mapping scans them all, per GJK
# iteration. More is refused with the count (simplify the mesh, or use a box or a cylinder).
MAX_HULL_POINTS = 64

# Triangles of qhull whose planes agree this closely (unit normals, offsets in m relative to the
# hull's size) are one face.
COPLANAR_TOLERANCE = 1e-6

# A centre of mass this close to the origin (relative to the hull's size) is the origin: what the
# centre of points centred already (a saved hull's) rounds to, ~1e-16.
CENTRED = 1e-12

Hulls = namedtuple("Hulls", [
    "points",          # (P, 3) body frame, every hull's vertices end to end
    "point_start", "point_count",   # (H,) each hull's vertices in `points`
    "face_normal",     # (F, 3) outward unit normals
    "face_offset",     # (F,) n . x = offset on the face's plane
    "face_start", "face_count",     # (H,) each hull's faces
    "corner_start", "corner_count",  # (F,) each face's corners in `corners`
    "corners",         # (C,) indices into `points`, counter-clockwise seen from outside
    "triangles",       # (T, 3, 3) body frame, for drawing (TRIANGLE_LIST)
    "triangle_start", "triangle_count",  # (H,)
])

Hull = namedtuple("Hull", "points faces triangles volume centre unit_inertia")


def build_hull(points, path="points"):
    """The hull of points (V, 3) in the body frame: recentred vertices, faces as corner index
    lists, triangles, volume, the centre of mass it was moved by, and the inertia per kg (3, 3)
    about it. Raises SpecError for too few points, a flat or degenerate set, or too many hull
    vertices."""
    from scipy.spatial import ConvexHull, QhullError

    from ..specs import MIN_SIZE, SpecError
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise SpecError(path, f"a convex shape needs at least 4 points [x, y, z], got {len(points)}")
    size = float(np.max(np.ptp(points, axis=0)))
    if not size >= MIN_SIZE:
        raise SpecError(path, f"the points span {size:g} m, less than the smallest body size {MIN_SIZE:g} m")
    try:
        hull = ConvexHull(points)
    except QhullError:
        raise SpecError(path, "the points are flat or degenerate: a convex shape needs volume") from None
    if len(hull.vertices) > MAX_HULL_POINTS:
        raise SpecError(path, f"the convex hull has {len(hull.vertices)} vertices, more than the "
                              f"{MAX_HULL_POINTS} allowed (simplify the mesh)")
    triangles = []
    for simplex, equation in zip(hull.simplices, hull.equations):
        a, b, c = points[simplex]
        if np.dot(np.cross(b - a, c - a), equation[:3]) < 0.0:  # wind outwards
            b, c = c, b
        triangles.append((a, b, c))
    triangles = np.array(triangles)
    with np.errstate(divide="ignore", invalid="ignore"):  # no volume: refused just below
        volume, centre, second_moment = solid_moments(triangles)
    if not volume > 1e-12 * size ** 3:
        raise SpecError(path, "the points are flat or degenerate: a convex shape needs volume")
    # Points already centred (a saved hull's) stay as they are: their centre comes out as
    # rounding about the origin, and taking that off changed the points at every save.
    if np.abs(centre).max() <= CENTRED * size:
        centre = np.zeros(3)
    # Inertia per kg about the centre of mass: (trace(S) I - S) / V, S the second moment there.
    covariance = second_moment / volume - np.outer(centre, centre)
    unit_inertia = np.trace(covariance) * np.eye(3) - covariance
    vertices = points[hull.vertices] - centre
    index_of = {int(v): k for k, v in enumerate(hull.vertices)}
    faces, used = [], np.zeros(len(hull.simplices), dtype=bool)
    for k, equation in enumerate(hull.equations):
        if used[k]:
            continue
        same = ((np.abs(hull.equations[:, :3] - equation[:3]).max(axis=1) < COPLANAR_TOLERANCE)
                & (np.abs(hull.equations[:, 3] - equation[3]) < COPLANAR_TOLERANCE * size))
        used |= same
        corners = sorted({index_of[int(v)] for v in hull.simplices[same].ravel()})
        faces.append((equation[:3], ccw_order(vertices, corners, equation[:3])))
    return Hull(vertices, faces, triangles - centre, volume, centre, unit_inertia)


def solid_moments(triangles):
    """Volume, centroid and second moment (integral of x x^T) of the solid bounded by outward
    triangles (T, 3, 3), from the signed tetrahedra they make with the origin."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    volume = det.sum() / 6.0
    centre = (det[:, None] * (a + b + c)).sum(axis=0) / (24.0 * volume)
    # Each tetrahedron's integral of x x^T: det/120 (sum of v v^T + (sum v)(sum v)^T) over its
    # corners 0, a, b, c.
    total = a + b + c
    outer = (np.einsum("ti,tj->tij", a, a) + np.einsum("ti,tj->tij", b, b) + np.einsum("ti,tj->tij", c, c)
             + np.einsum("ti,tj->tij", total, total))
    second = (det[:, None, None] * outer).sum(axis=0) / 120.0
    return volume, centre, second


def ccw_order(vertices, corners, normal):
    """The corners of a planar face sorted counter-clockwise about its outward normal."""
    p = vertices[corners]
    middle = p.mean(axis=0)
    u = p[0] - middle
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    angles = np.arctan2((p - middle) @ v, (p - middle) @ u)
    return [corners[k] for k in np.argsort(angles)]


def pack_hulls(by_slot):
    """The Hulls table of a list of Hull or None, one per body slot (a convex body's hull is
    found by its slot)."""
    empty = Hull(np.zeros((0, 3)), [], np.zeros((0, 3, 3)), 0.0, None, None)
    hulls = [h if h is not None else empty for h in by_slot]
    point_count = np.array([len(h.points) for h in hulls], np.int64)
    face_count = np.array([len(h.faces) for h in hulls], np.int64)
    triangle_count = np.array([len(h.triangles) for h in hulls], np.int64)
    point_start = starts(point_count)
    faces = [(normal, [c + start for c in corners])
             for h, start in zip(hulls, point_start.tolist()) for normal, corners in h.faces]
    corner_count = np.array([len(c) for _, c in faces], np.int64)
    points = np.concatenate([h.points for h in hulls] + [np.zeros((0, 3))])
    corners = np.array([c for _, cs in faces for c in cs], np.int64)
    normals = np.array([n for n, _ in faces], np.float64).reshape(-1, 3)
    corner_start = starts(corner_count)
    offsets = np.einsum("fi,fi->f", normals, points[corners[corner_start]]) if len(faces) else np.zeros(0)
    return Hulls(points, point_start, point_count, normals, offsets, starts(face_count), face_count,
                 corner_start, corner_count, corners,
                 np.concatenate([h.triangles for h in hulls] + [np.zeros((0, 3, 3))]),
                 starts(triangle_count), triangle_count)


def starts(counts):
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if len(counts) else np.zeros(0, np.int64)


def dimensions(hull):
    """Half extents of the hull's bounding box about its centre of mass (symmetric, so the
    box bounds it in any orientation as for a box)."""
    return tuple(float(x) for x in np.abs(hull.points).max(axis=0))


def spec_fields(hull):
    return {"points": hull.points.tolist()}


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def farthest_along(rows, start, count, d):
    """The index in start..start + count of the row of `rows` (K, 3) with the largest dot with d."""
    best, best_dot = start, -np.inf
    for k in range(start, start + count):
        dot = rows[k, 0] * d[0] + rows[k, 1] * d[1] + rows[k, 2] * d[2]
        if dot > best_dot:
            best, best_dot = k, dot
    return best


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def support(hulls, h, d):
    p = hulls.points
    best = farthest_along(p, hulls.point_start[h], hulls.point_count[h], d)
    return (p[best, 0], p[best, 1], p[best, 2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def supporting_face(hulls, h, d, out):
    """The face whose outward normal is closest to d: its corners, counter-clockwise."""
    best = farthest_along(hulls.face_normal, hulls.face_start[h], hulls.face_count[h], d)
    count = min(hulls.corner_count[best], len(out))
    first = hulls.corner_start[best]
    for k in range(count):
        c = hulls.corners[first + k]
        out[k, 0], out[k, 1], out[k, 2] = hulls.points[c, 0], hulls.points[c, 1], hulls.points[c, 2]
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ray(hulls, h, o, d, reach):
    """Clips the ray against every face's half-space: (entry distance, the entry face's
    normal), or NO_HIT when it misses or starts inside."""
    t_in, t_out, entry = 0.0, reach, -1
    n = hulls.face_normal
    for f in range(hulls.face_start[h], hulls.face_start[h] + hulls.face_count[h]):
        distance = n[f, 0] * o[0] + n[f, 1] * o[1] + n[f, 2] * o[2] - hulls.face_offset[f]
        rate = n[f, 0] * d[0] + n[f, 1] * d[1] + n[f, 2] * d[2]
        if abs(rate) < 1e-14:
            if distance > 0.0:
                return NO_HIT, (0.0, 0.0, 0.0)
            continue
        t = -distance / rate
        if rate < 0.0:  # entering this half-space
            if t > t_in:
                t_in, entry = t, f
        elif t < t_out:
            t_out = t
        if t_in > t_out:
            return NO_HIT, (0.0, 0.0, 0.0)
    if entry < 0:
        return NO_HIT, (0.0, 0.0, 0.0)  # inside
    return t_in, (n[entry, 0], n[entry, 1], n[entry, 2])
