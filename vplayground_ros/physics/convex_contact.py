"""The narrow phase's general convex path: any two shapes of physics.shapes, a shape and a
playground triangle, a shape and the ground, through their support mappings alone.

GJK finds the distance between the two shapes' cores (a sphere's centre, a capsule's segment,
the whole box or cylinder); separated cores give the normal from their closest points. Cores
overlapping by little (resting boxes and cylinders) are measured again shrunk (see SHRINK),
and deeper ones go to EPA for the normal and depth of least penetration. The core radii then
put the points on the surfaces. The manifold is Jolt's: the supporting faces of both shapes
along the normal, the incident one clipped against the side planes of the reference one, each
point's depth measured along the normal, those within the margin kept; and the exact deepest
point when the faces miss it (a cylinder's end is an 8-gon inside its circle, so a tilted
cylinder's lowest rim point can lie between two corners).

A shape is passed as (kind, position, rotation as a tuple of rows, dims, slot): tuples, and the
body's slot, where a convex body's hull is found in the hull table (`hulls`, shapes/convex.py)
that every function taking shapes gets first. A convex hull has no shrunk copy (SHRINK): a
shallow overlap of two hulls, or of a hull and a round shape, goes to EPA. The arrays the
algorithms work in come from allocate_scratch, once per collide call.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .constants import SEAM_TOLERANCE
from .math3d import cross
from .shapes import BOX, CYLINDER, MAX_FACE_POINTS, core_radius, core_support, supporting_face

# Not a body shape: a playground triangle in the convex path. Its "rotation" maps the unit
# triangle (0, e_x, e_y) onto it: columns edge v1 - v0, edge v2 - v0, face normal.
TRIANGLE = -1
# The slot passed for a shape that has no hull (the triangle); bodies pass their own slot.
NO_HULL = -1

# The intersection of two convex 8-gons (two cylinder ends) has up to 16 corners, and the exact
# deepest point may join them.
MAX_CLIP_POINTS = 2 * MAX_FACE_POINTS + 1

GJK_MAX_ITERATIONS = 64
# GJK stops when a new support point brings the squared distance closer by less than this
# fraction of it: the distance is then exact to half this fraction of itself. Tighter, the
# last simplices grow flat enough for rounding to spoil them.
GJK_RELATIVE_TOLERANCE = 1e-10
# Cores closer than this count as overlapping: their closest points no longer give a reliable
# direction, and the shrunk shapes' or EPA's does.
GJK_OVERLAP_DISTANCE = 1e-7  # m

# Boxes and cylinders overlapping by less than about twice this are measured on copies shrunk
# by it (Jolt's convex radius): GJK between the shrunk shapes gives the normal (exact between
# faces) in a few iterations, where EPA needs dozens to follow a cylinder's curved side, and
# resting contacts overlap a few millimetres (LINEAR_SLOP). It is also how far the deepest
# point can sit beside a true rim or corner: small against the shapes.
SHRINK = 0.01  # m, at most a quarter of the shape's smallest half dimension

EPA_MAX_VERTICES = 64
EPA_MAX_FACES = 2 * EPA_MAX_VERTICES  # a closed triangulated polytope has 2 V - 4 faces
EPA_TOLERANCE = 1e-9  # m: a new support point must push the closest face out by more

# Two segment features (a cylinder's or a capsule's side on another's) give a two-point
# manifold when their directions, seen along the normal, are within this sine of parallel;
# crossing, they touch at one point.
PARALLEL_SINE = 0.05
# The exact deepest point joins the clipped ones when they are all shallower than it by more
# than this (m): a flat face resting on another matches it to rounding error.
DEEPEST_POINT_TOLERANCE = 1e-4

# gjk's outcomes
BEYOND, SEPARATED, OVERLAPPING = 0, 1, 2

Scratch = namedtuple("Scratch", [
    "poly_a", "poly_b",    # (MAX_CLIP_POINTS, 3) polygons being clipped (ping-pong)
    "face_a", "face_b",    # (MAX_FACE_POINTS, 3) supporting faces, world
    "simplex",             # (12, 3) GJK's simplex: rows 0-3 points of A - B, 4-7 A's, 8-11 B's
    "polytope",            # (3 EPA_MAX_VERTICES, 3) EPA's points of A - B, then A's, then B's
    "epa_face",            # (EPA_MAX_FACES, 3) int64 vertex indices, counter-clockwise outside
    "epa_plane",           # (EPA_MAX_FACES, 4) unit outward normal and distance from the origin
    "epa_edge",            # (3 EPA_MAX_FACES, 2) int64 horizon edges
])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def allocate_scratch():
    return Scratch(np.empty((MAX_CLIP_POINTS, 3)), np.empty((MAX_CLIP_POINTS, 3)),
                   np.empty((MAX_FACE_POINTS, 3)), np.empty((MAX_FACE_POINTS, 3)),
                   np.empty((12, 3)), np.empty((3 * EPA_MAX_VERTICES, 3)),
                   np.empty((EPA_MAX_FACES, 3), np.int64), np.empty((EPA_MAX_FACES, 4)),
                   np.empty((3 * EPA_MAX_FACES, 2), np.int64))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def add_scaled(a, s, b):
    """a + s b"""
    return (a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def scaled(s, a):
    return (s * a[0], s * a[1], s * a[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def row(m, i):
    return (m[i, 0], m[i, 1], m[i, 2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def set_row(m, i, v):
    m[i, 0], m[i, 1], m[i, 2] = v[0], v[1], v[2]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def to_local(r, d):
    """R^T d: a world direction in the frame whose axes are r's columns."""
    return (r[0][0] * d[0] + r[1][0] * d[1] + r[2][0] * d[2],
            r[0][1] * d[0] + r[1][1] * d[1] + r[2][1] * d[2],
            r[0][2] * d[0] + r[1][2] * d[1] + r[2][2] * d[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def to_world(p, r, x):
    return (p[0] + r[0][0] * x[0] + r[0][1] * x[1] + r[0][2] * x[2],
            p[1] + r[1][0] * x[0] + r[1][1] * x[1] + r[1][2] * x[2],
            p[2] + r[2][0] * x[0] + r[2][1] * x[1] + r[2][2] * x[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def triangle_frame(tri, normal):
    """(origin, rotation) of a triangle as a TRIANGLE shape (see TRIANGLE)."""
    v0, v1, v2 = tri[0], tri[1], tri[2]
    return v0, ((v1[0] - v0[0], v2[0] - v0[0], normal[0]),
                (v1[1] - v0[1], v2[1] - v0[1], normal[1]),
                (v1[2] - v0[2], v2[2] - v0[2], normal[2]))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def core_point(hulls, kind, p, r, dims, slot, d):
    """The point of the shape's core farthest along the world direction d (support mapping;
    for a linear map M, support_MK(d) = M support_K(M^T d), so a triangle's frame works too)."""
    local = to_local(r, d)
    if kind == TRIANGLE:
        s = (0.0, 0.0, 0.0)
        if local[0] > 0.0 and local[0] >= local[1]:
            s = (1.0, 0.0, 0.0)
        elif local[1] > 0.0:
            s = (0.0, 1.0, 0.0)
    else:
        s = core_support(kind, dims, hulls, slot, local)
    return to_world(p, r, s)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def radius_of(kind, dims):
    return 0.0 if kind == TRIANGLE else core_radius(kind, dims)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def surface_point(hulls, kind, p, r, dims, slot, d):
    """The point of the whole shape farthest along the unit world direction d."""
    return add_scaled(core_point(hulls, kind, p, r, dims, slot, d), radius_of(kind, dims), d)


# --- GJK --------------------------------------------------------------------------------------
# A point store holds `block` rows of points of A - B, then as many of A's, then B's.

@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def segment_weights(a, b):
    """Barycentric weights of the point of segment ab closest to the origin."""
    ab = sub(b, a)
    length_sq = dot(ab, ab)
    if length_sq < 1e-30:
        return 1.0, 0.0
    t = -dot(a, ab) / length_sq
    if t <= 0.0:
        return 1.0, 0.0
    if t >= 1.0:
        return 0.0, 1.0
    return 1.0 - t, t


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def triangle_weights(a, b, c):
    """Barycentric weights of the point of triangle abc closest to the origin (Ericson's
    Voronoi-region walk; a degenerate triangle falls back to its best edge)."""
    ab, ac = sub(b, a), sub(c, a)
    d1, d2 = -dot(ab, a), -dot(ac, a)
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    d3, d4 = -dot(ab, b), -dot(ac, b)
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    # The edge regions' denominators vanish only when two corners coincide.
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3) if d1 > d3 else 0.0
        return 1.0 - v, v, 0.0
    d5, d6 = -dot(ab, c), -dot(ac, c)
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6) if d2 > d6 else 0.0
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6)) if d4 - d3 + d5 - d6 > 0.0 else 0.0
        return 0.0, 1.0 - w, w
    denom = va + vb + vc
    if denom > 1e-30:
        v, w = vb / denom, vc / denom
        return 1.0 - v - w, v, w
    # Collinear corners: the best of the three edges.
    s0, t0 = segment_weights(a, b)
    s1, t1 = segment_weights(b, c)
    s2, t2 = segment_weights(c, a)
    x0 = add_scaled(scaled(s0, a), t0, b)
    x1 = add_scaled(scaled(s1, b), t1, c)
    x2 = add_scaled(scaled(s2, c), t2, a)
    if dot(x0, x0) <= dot(x1, x1) and dot(x0, x0) <= dot(x2, x2):
        return s0, t0, 0.0
    if dot(x1, x1) <= dot(x2, x2):
        return 0.0, s1, t1
    return t2, 0.0, s2


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def keep_weighted(simplex, n, weights):
    """Drops the simplex points of zero weight, moving the others (and their points on A and B)
    down. Returns (count, the kept points' weights padded with zeros)."""
    kept = 0
    w0 = w1 = w2 = 0.0
    for k in range(n):
        if weights[k] > 0.0:
            if kept != k:
                for block in range(0, 12, 4):
                    for e in range(3):
                        simplex[block + kept, e] = simplex[block + k, e]
            if kept == 0:
                w0 = weights[k]
            elif kept == 1:
                w1 = weights[k]
            else:
                w2 = weights[k]
            kept += 1
    return kept, (w0, w1, w2, 0.0)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def face_weights(i, j, k, u, v, w):
    """Weights u, v, w of points i, j, k among four (the fourth 0)."""
    return (u if i == 0 else (v if j == 0 else (w if k == 0 else 0.0)),
            u if i == 1 else (v if j == 1 else (w if k == 1 else 0.0)),
            u if i == 2 else (v if j == 2 else (w if k == 2 else 0.0)),
            u if i == 3 else (v if j == 3 else (w if k == 3 else 0.0)))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def closest_on_simplex(simplex, n):
    """Reduces GJK's simplex (rows 0..n-1) to the smallest one holding its point closest to
    the origin. Returns (count, weights); count 4 means the origin is inside the tetrahedron."""
    w0, w1 = row(simplex, 0), row(simplex, 1)
    if n == 2:
        s, t = segment_weights(w0, w1)
        return keep_weighted(simplex, 2, (s, t, 0.0, 0.0))
    w2 = row(simplex, 2)
    if n == 3:
        u, v, w = triangle_weights(w0, w1, w2)
        return keep_weighted(simplex, 3, (u, v, w, 0.0))
    points = (w0, w1, w2, row(simplex, 3))
    best, weights = np.inf, (0.0, 0.0, 0.0, 0.0)
    inside = True
    # Each face with the vertex opposite it: the origin beyond the face's plane (or on it, or
    # a flat tetrahedron) makes the face a candidate.
    for i, j, k, opposite in ((0, 1, 2, 3), (0, 2, 3, 1), (0, 3, 1, 2), (1, 3, 2, 0)):
        a, b, c = points[i], points[j], points[k]
        normal = cross(sub(b, a), sub(c, a))
        if -dot(normal, a) * dot(normal, sub(points[opposite], a)) > 0.0:
            continue
        inside = False
        u, v, w = triangle_weights(a, b, c)
        x = add_scaled(add_scaled(scaled(u, a), v, b), w, c)
        if dot(x, x) < best:
            best, weights = dot(x, x), face_weights(i, j, k, u, v, w)
    if inside:
        return 4, (0.25, 0.25, 0.25, 0.25)
    return keep_weighted(simplex, 4, weights)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def put_support(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, d, store, block, i):
    """Writes as point i of `store` the point of A - B farthest along d, with its points on the
    cores of A and B (rows block + i, 2 block + i). Returns the point of A - B."""
    a = core_point(hulls, kind_a, pa, ra, da, slot_a, d)
    b = core_point(hulls, kind_b, pb, rb, db, slot_b, (-d[0], -d[1], -d[2]))
    w = sub(a, b)
    set_row(store, i, w)
    set_row(store, block + i, a)
    set_row(store, 2 * block + i, b)
    return w


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def in_simplex(simplex, n, w):
    """w is (to 1e-12 m) a point of the simplex already: rounding in v kept the test on v . w
    from seeing it, and a repeated point would make the simplex degenerate."""
    for k in range(n):
        gap = sub(row(simplex, k), w)
        if dot(gap, gap) <= 1e-24:
            return True
    return False


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def gjk(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, limit, simplex):
    """Distance between the cores of A and B (van den Bergen's GJK). Returns (outcome, simplex
    size, closest point on A's core, closest point on B's core): BEYOND as soon as a direction
    proves them farther apart than `limit`, OVERLAPPING when they intersect (or are closer than
    GJK_OVERLAP_DISTANCE; the simplex is then EPA's start), else SEPARATED."""
    d = sub(pb, pa)
    if dot(d, d) < 1e-24:
        d = (1.0, 0.0, 0.0)
    v = put_support(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, d, simplex, np.int64(4), np.int64(0))
    point_a, point_b = row(simplex, 4), row(simplex, 8)  # v's points on A and B
    n = 1
    for _ in range(GJK_MAX_ITERATIONS):
        vv = dot(v, v)
        if vv < GJK_OVERLAP_DISTANCE * GJK_OVERLAP_DISTANCE:
            return OVERLAPPING, n, point_a, point_b
        w = put_support(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b,
                        (-v[0], -v[1], -v[2]), simplex, np.int64(4), n)
        vw = dot(v, w)
        if vw > 0.0 and vw * vw > vv * limit * limit:
            return BEYOND, n, point_a, point_b  # w's plane separates them by more than limit
        if vv - vw <= GJK_RELATIVE_TOLERANCE * vv or in_simplex(simplex, n, w):
            break  # no support point is nearer than v: it is the closest point
        n, weights = closest_on_simplex(simplex, n + 1)
        if n == 4:
            return OVERLAPPING, n, point_a, point_b
        closer, closer_a, closer_b = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        for k in range(n):
            closer = add_scaled(closer, weights[k], row(simplex, k))
            closer_a = add_scaled(closer_a, weights[k], row(simplex, 4 + k))
            closer_b = add_scaled(closer_b, weights[k], row(simplex, 8 + k))
        if dot(closer, closer) >= vv:
            # No progress: w was (to rounding) in v's plane and the nearly flat simplex it
            # made lost the closest point. v and its points stand.
            break
        v, point_a, point_b = closer, closer_a, closer_b
    if dot(v, v) < GJK_OVERLAP_DISTANCE * GJK_OVERLAP_DISTANCE:
        return OVERLAPPING, n, point_a, point_b
    return SEPARATED, n, point_a, point_b


# --- EPA --------------------------------------------------------------------------------------

@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def set_face(faces, planes, f, i, j, k, w):
    """Face f = (i, j, k) of the polytope whose points are w's rows, with its plane. False when
    it is degenerate."""
    a = row(w, i)
    normal = cross(sub(row(w, j), a), sub(row(w, k), a))
    length = np.sqrt(dot(normal, normal))
    if length < 1e-14:
        return False
    faces[f, 0], faces[f, 1], faces[f, 2] = i, j, k
    for e in range(3):
        planes[f, e] = normal[e] / length
    planes[f, 3] = dot(normal, a) / length
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def tetrahedron_from(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, simplex, n,
                     store):
    """Copies GJK's simplex (n points) to EPA's store and grows it to a tetrahedron with new
    support points. False when A - B is flat (a point or segment core against a triangle)."""
    for k in range(n):
        for block in range(3):
            for e in range(3):
                store[block * EPA_MAX_VERTICES + k, e] = simplex[4 * block + k, e]
    axes = ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0),
            (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
    if n == 1:
        for d in axes:
            gap = sub(put_support(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, d,
                                  store, np.int64(EPA_MAX_VERTICES), np.int64(1)), row(store, 0))
            if dot(gap, gap) > 1e-18:
                n = 2
                break
    if n == 2:
        line = sub(row(store, 1), row(store, 0))
        for d in axes:
            side = cross(line, d)
            if dot(side, side) < 1e-6 * dot(line, line):
                continue  # d along the line
            x = put_support(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, side,
                            store, np.int64(EPA_MAX_VERTICES), np.int64(2))
            off = cross(line, sub(x, row(store, 0)))
            if dot(off, off) > 1e-18 * dot(line, line):
                n = 3
                break
    if n == 3:
        normal = cross(sub(row(store, 1), row(store, 0)), sub(row(store, 2), row(store, 0)))
        for sign in (1.0, -1.0):
            x = put_support(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b,
                            scaled(sign, normal), store, np.int64(EPA_MAX_VERTICES), np.int64(3))
            volume = dot(normal, sub(x, row(store, 0)))
            if abs(volume) > 1e-12 * dot(normal, normal) ** 0.75:
                n = 4
                break
    return n == 4


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def epa(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, simplex, n, sc):
    """Penetration of the overlapping cores of A and B (expanding polytope): returns (found,
    normal A -> B, depth, deepest point of A's core, deepest point of B's core); depth is how
    far B must move along the normal to separate them."""
    nothing = (0.0, 0.0, 0.0)
    w, faces, planes, edges = sc.polytope, sc.epa_face, sc.epa_plane, sc.epa_edge
    if not tetrahedron_from(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, simplex,
                            n, w):
        return False, nothing, 0.0, nothing, nothing
    centre = (0.0, 0.0, 0.0)
    for k in range(4):
        centre = add_scaled(centre, 0.25, row(w, k))
    face_count = 0
    for i, j, k in ((0, 1, 2), (0, 3, 1), (0, 2, 3), (1, 3, 2)):
        if dot(cross(sub(row(w, j), row(w, i)), sub(row(w, k), row(w, i))),
               sub(row(w, i), centre)) < 0.0:
            j, k = k, j  # wound outwards
        if set_face(faces, planes, face_count, i, j, k, w):
            face_count += 1
    vertex_count = 4
    found, normal, best_i, best_j, best_k = False, nothing, 0, 0, 0
    while face_count > 0:
        best = 0
        for f in range(1, face_count):
            if planes[f, 3] < planes[best, 3]:
                best = f
        normal = (planes[best, 0], planes[best, 1], planes[best, 2])
        best_i, best_j, best_k = faces[best, 0], faces[best, 1], faces[best, 2]
        found = True
        if vertex_count == EPA_MAX_VERTICES:
            break
        x = put_support(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, normal, w,
                        np.int64(EPA_MAX_VERTICES), vertex_count)
        if dot(x, normal) - planes[best, 3] <= EPA_TOLERANCE:
            break  # the closest face is on A - B's boundary
        # Remove the faces x sees; their boundary (edges not shared by two of them) is the
        # horizon, which x joins with new faces.
        edge_count, kept = 0, 0
        for f in range(face_count):
            i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
            if planes[f, 0] * (x[0] - w[i, 0]) + planes[f, 1] * (x[1] - w[i, 1]) \
                    + planes[f, 2] * (x[2] - w[i, 2]) > 1e-12:
                for p, q in ((i, j), (j, k), (k, i)):
                    twin = -1
                    for e in range(edge_count):
                        if edges[e, 0] == q and edges[e, 1] == p:
                            twin = e
                            break
                    if twin >= 0:
                        edge_count -= 1
                        edges[twin, 0], edges[twin, 1] = edges[edge_count, 0], edges[edge_count, 1]
                    else:
                        edges[edge_count, 0], edges[edge_count, 1] = p, q
                        edge_count += 1
            else:
                if kept != f:
                    for e in range(3):
                        faces[kept, e] = faces[f, e]
                    for e in range(4):
                        planes[kept, e] = planes[f, e]
                kept += 1
        face_count = kept
        if face_count + edge_count > EPA_MAX_FACES:
            break
        for e in range(edge_count):
            if set_face(faces, planes, face_count, edges[e, 0], edges[e, 1], vertex_count, w):
                face_count += 1
        vertex_count += 1
    if not found:
        return False, nothing, 0.0, nothing, nothing
    u, v, t = triangle_weights(row(w, best_i), row(w, best_j), row(w, best_k))
    a, b = EPA_MAX_VERTICES, 2 * EPA_MAX_VERTICES
    point_a = add_scaled(add_scaled(scaled(u, row(w, a + best_i)), v, row(w, a + best_j)), t,
                         row(w, a + best_k))
    point_b = add_scaled(add_scaled(scaled(u, row(w, b + best_i)), v, row(w, b + best_j)), t,
                         row(w, b + best_k))
    return True, normal, dot(sub(point_a, point_b), normal), point_a, point_b


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def shrink_of(kind, dims):
    """How far the shallow-overlap test shrinks a shape without a radius (see SHRINK); a convex
    hull is not shrunk (0)."""
    if kind == BOX:
        return min(SHRINK, 0.25 * min(dims[0], dims[1], dims[2]))
    if kind == CYLINDER:
        return min(SHRINK, 0.25 * min(dims[0], dims[1]))
    return 0.0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def shrunk(kind, dims, by):
    """The dimensions of the shape shrunk by `by` all round (a box's or cylinder's)."""
    if kind == BOX:
        return (dims[0] - by, dims[1] - by, dims[2] - by)
    if kind == CYLINDER:
        return (dims[0] - by, dims[1] - by, dims[2])
    return (dims[0], dims[1], dims[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def shallow_contact(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, sc):
    """The contact of overlapping A and B from the distance of their shrunk versions (see
    SHRINK): (found, normal A -> B, point on A, point on B, depth), found when the shrunk
    shapes are apart. The depth is the true shapes' overlap along the normal, the points are
    on their supporting planes, beside the shrunk shapes' closest points."""
    shrink_a, shrink_b = shrink_of(kind_a, da), shrink_of(kind_b, db)
    nothing = (0.0, 0.0, 0.0)
    if shrink_a + shrink_b == 0.0:
        return False, nothing, nothing, nothing, 0.0
    outcome, n, core_a, core_b = gjk(hulls, kind_a, pa, ra, shrunk(kind_a, da, shrink_a), slot_a,
                                     kind_b, pb, rb, shrunk(kind_b, db, shrink_b), slot_b, np.inf,
                                     sc.simplex)
    if outcome != SEPARATED:
        return False, nothing, nothing, nothing, 0.0
    gap = sub(core_b, core_a)
    normal = scaled(1.0 / np.sqrt(dot(gap, gap)), gap)
    reach_a = dot(surface_point(hulls, kind_a, pa, ra, da, slot_a, normal), normal)
    reach_b = dot(surface_point(hulls, kind_b, pb, rb, db, slot_b,
                                (-normal[0], -normal[1], -normal[2])), normal)
    middle = scaled(0.5, add_scaled(core_a, 1.0, core_b))
    along = dot(middle, normal)
    return (True, normal, add_scaled(middle, reach_a - along, normal),
            add_scaled(middle, reach_b - along, normal), reach_a - reach_b)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def shape_contact(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, margin, sc):
    """The deepest contact of A and B: (found, normal A -> B, point on A's surface, point on
    B's surface, depth: positive overlapping, negative apart); not found when they are more
    than `margin` apart. Apart, GJK's closest points give it exactly; overlapping a little, the
    shrunk shapes' (shallow_contact); deeper, EPA's."""
    radius_a, radius_b = radius_of(kind_a, da), radius_of(kind_b, db)
    outcome, n, core_a, core_b = gjk(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b,
                                     radius_a + radius_b + margin, sc.simplex)
    nothing = (0.0, 0.0, 0.0)
    if outcome == BEYOND:
        return False, nothing, nothing, nothing, 0.0
    if outcome == SEPARATED:
        gap = sub(core_b, core_a)
        distance = np.sqrt(dot(gap, gap))
        normal = scaled(1.0 / distance, gap)
        depth = radius_a + radius_b - distance
    else:
        shallow = shallow_contact(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, sc)
        if shallow[0]:
            return shallow
        found, normal, depth, core_a, core_b = epa(
            hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, sc.simplex, n, sc)
        if not found:
            # A - B is flat: take the centres' direction and the overlap along it.
            normal = sub(pb, pa)
            length = np.sqrt(dot(normal, normal))
            normal = scaled(1.0 / length, normal) if length > 1e-12 else (0.0, 0.0, 1.0)
            core_a = core_point(hulls, kind_a, pa, ra, da, slot_a, normal)
            core_b = core_point(hulls, kind_b, pb, rb, db, slot_b,
                                (-normal[0], -normal[1], -normal[2]))
            depth = dot(sub(core_a, core_b), normal)
        depth += radius_a + radius_b
    if depth < -margin:
        return False, nothing, nothing, nothing, 0.0
    return (True, normal, add_scaled(core_a, radius_a, normal),
            add_scaled(core_b, -radius_b, normal), depth)


# --- Manifold ---------------------------------------------------------------------------------

@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def clip_polygon(src, n_src, dst, plane, offset):
    """Sutherland-Hodgman: the part of polygon src (world points) with plane . p <= offset,
    written to dst. Returns its point count."""
    n = 0
    if n_src == 0:
        return 0
    prev = n_src - 1
    prev_d = src[prev, 0] * plane[0] + src[prev, 1] * plane[1] + src[prev, 2] * plane[2] - offset
    for k in range(n_src):
        d = src[k, 0] * plane[0] + src[k, 1] * plane[1] + src[k, 2] * plane[2] - offset
        if (prev_d <= 0.0) != (d <= 0.0):
            f = prev_d / (prev_d - d)
            for e in range(3):
                dst[n, e] = src[prev, e] + f * (src[k, e] - src[prev, e])
            n += 1
        if d <= 0.0:
            for e in range(3):
                dst[n, e] = src[k, e]
            n += 1
        prev, prev_d = k, d
    return n


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def clip_segment(poly, plane, offset):
    """Keeps the part of segment poly[0]-poly[1] with plane . p <= offset. False when none."""
    d0 = dot(row(poly, 0), plane) - offset
    d1 = dot(row(poly, 1), plane) - offset
    if d0 > 0.0 and d1 > 0.0:
        return False
    if d0 > 0.0 or d1 > 0.0:
        f = d0 / (d0 - d1)
        cut = add_scaled(row(poly, 0), f, sub(row(poly, 1), row(poly, 0)))
        set_row(poly, 0 if d0 > 0.0 else 1, cut)
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def to_world_face(hulls, kind, p, r, dims, slot, d, out):
    """The shape's supporting face along world d (shapes.supporting_face), in world points."""
    count = supporting_face(kind, dims, hulls, slot, to_local(r, d), out)
    for k in range(count):
        set_row(out, k, to_world(p, r, row(out, k)))
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def clip_faces(face_a, count_a, face_b, count_b, normal, margin, sc, out_point, out_depth):
    """Contact points of A's supporting face and B's (each a polygon or a segment), normal
    A -> B: the incident feature clipped to the reference feature's side planes (planes through
    its edges along the normal; a polygon is the reference when there is one), each point
    measured along the normal to the reference's plane, those within `margin` kept, halfway.
    Returns their count (0 for crossing segments: one point, the deepest, says it all)."""
    if count_b >= 3 or count_a < 3:
        reference, count_ref, incident, count_inc, sign = face_b, count_b, face_a, count_a, -1.0
    else:
        reference, count_ref, incident, count_inc, sign = face_a, count_a, face_b, count_b, 1.0
    poly, spare = sc.poly_a, sc.poly_b
    for k in range(count_inc):
        set_row(poly, k, row(incident, k))
    origin = row(reference, 0)
    if count_ref >= 3:
        centre, plane_normal = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        for k in range(count_ref):
            here, there = row(reference, k), row(reference, (k + 1) % count_ref)
            centre = add_scaled(centre, 1.0 / count_ref, here)
            plane_normal = add_scaled(plane_normal, 1.0, cross(here, there))  # Newell
        for k in range(count_ref):
            here = row(reference, k)
            side = cross(sub(row(reference, (k + 1) % count_ref), here), normal)
            if dot(side, sub(centre, here)) > 0.0:
                side = scaled(-1.0, side)  # outwards, whichever way the polygon winds
            offset = dot(side, here)
            if count_inc >= 3:
                count_inc = clip_polygon(poly, count_inc, spare, side, offset)
                poly, spare = spare, poly
            elif not clip_segment(poly, side, offset):
                return 0
    else:
        # Segment on segment: only (nearly) parallel ones, seen along the normal, touch along
        # a stretch; it is the incident segment's part beside the reference one.
        line_ref = sub(row(reference, 1), origin)
        line_inc = sub(row(incident, 1), row(incident, 0))
        flat_ref = add_scaled(line_ref, -dot(line_ref, normal), normal)
        flat_inc = add_scaled(line_inc, -dot(line_inc, normal), normal)
        across = cross(flat_ref, flat_inc)
        lengths_sq = dot(flat_ref, flat_ref) * dot(flat_inc, flat_inc)
        if lengths_sq < 1e-24 or dot(across, across) > PARALLEL_SINE * PARALLEL_SINE * lengths_sq:
            return 0
        if not clip_segment(poly, flat_ref, dot(flat_ref, row(reference, 1))):
            return 0
        if not clip_segment(poly, scaled(-1.0, flat_ref), -dot(flat_ref, origin)):
            return 0
        plane_normal = cross(cross(line_ref, normal), line_ref)
    along = dot(plane_normal, normal)
    if along * along <= 1e-12 * dot(plane_normal, plane_normal):
        return 0  # the reference is edge-on to the normal
    kept = 0
    for k in range(count_inc):
        q = row(poly, k)
        t = dot(sub(origin, q), plane_normal) / along  # q + t normal is on the reference plane
        depth = sign * t
        if depth < -margin:
            continue
        set_row(out_point, kept, add_scaled(q, 0.5 * t, normal))
        out_depth[kept] = depth
        kept += 1
    return kept


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def add_deepest(count, point_a, point_b, depth, out_point, out_depth):
    """Adds the exact deepest contact (points on A and B) unless a clipped point is about as
    deep already. Returns the new count."""
    for k in range(count):
        if out_depth[k] >= depth - DEEPEST_POINT_TOLERANCE:
            return count
    set_row(out_point, count, scaled(0.5, add_scaled(point_a, 1.0, point_b)))
    out_depth[count] = depth
    return count + 1


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def convex_pair(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, margin, sc,
                out_point, out_depth):
    """Manifold of any two shapes: (point count, normal A -> B)."""
    found, normal, point_a, point_b, depth = shape_contact(
        hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, margin, sc)
    if not found:
        return 0, normal
    count_a = to_world_face(hulls, kind_a, pa, ra, da, slot_a, normal, sc.face_a)
    count_b = to_world_face(hulls, kind_b, pb, rb, db, slot_b, (-normal[0], -normal[1], -normal[2]),
                            sc.face_b)
    count = 0
    if count_a >= 2 and count_b >= 2:
        count = clip_faces(sc.face_a, count_a, sc.face_b, count_b, normal, margin, sc,
                           out_point, out_depth)
    return add_deepest(count, point_a, point_b, depth, out_point, out_depth), normal


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def convex_ground(hulls, kind, p, r, dims, slot, height, margin, sc, out_point, out_depth):
    """Manifold of a shape and the ground z = height (normal (0, 0, -1)): the corners of its
    supporting face along -z within `margin` of the plane, and its lowest point when they miss
    it. Points halfway to the plane."""
    down = (0.0, 0.0, -1.0)
    count = 0
    for k in range(to_world_face(hulls, kind, p, r, dims, slot, down, sc.face_a)):
        gap = sc.face_a[k, 2] - height
        if gap <= margin:
            out_point[count, 0], out_point[count, 1] = sc.face_a[k, 0], sc.face_a[k, 1]
            out_point[count, 2] = sc.face_a[k, 2] - 0.5 * gap
            out_depth[count] = -gap
            count += 1
    lowest = surface_point(hulls, kind, p, r, dims, slot, down)
    if lowest[2] - height > margin:
        return count
    return add_deepest(count, lowest, (lowest[0], lowest[1], height), height - lowest[2],
                       out_point, out_depth)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def triangle_face(tri, tri_normal, d, out):
    """The triangle's feature facing d: itself when d is within 45 degrees of its plane's
    normal (either side), an edge nearly square to d, else its vertex farthest along d."""
    length = np.sqrt(dot(d, d))
    if abs(dot(d, tri_normal)) >= 0.7071 * length:
        for k in range(3):
            set_row(out, k, tri[k])
        return 3
    best = 0
    for k in range(1, 3):
        if dot(tri[k], d) > dot(tri[best], d):
            best = k
    for other in ((best + 1) % 3, (best + 2) % 3):
        edge = sub(tri[other], tri[best])
        if abs(dot(edge, d)) <= PARALLEL_SINE * length * np.sqrt(dot(edge, edge)):
            set_row(out, 0, tri[best])
            set_row(out, 1, tri[other])
            return 2
    set_row(out, 0, tri[best])
    return 1


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def convex_triangle(hulls, kind, p, r, dims, slot, tri, tri_normal, margin, sc, out_point,
                    out_depth):
    """Manifold of a shape and a one-sided playground triangle: (point count, normal shape ->
    triangle). None when the shape's centre is behind the triangle's plane. While the shape is
    sunk at most SEAM_TOLERANCE below the plane the triangle's face normal is the normal (as
    in box_triangle: bodies slide over seams between coplanar triangles instead of catching on
    an edge), its supporting face clipped to the triangle; deeper (beside a step's riser, say)
    the deepest contact's normal decides, as for two shapes."""
    n = (tri_normal[0], tri_normal[1], tri_normal[2])
    front = dot(sub(p, tri[0]), n)
    nothing = (0.0, 0.0, 0.0)
    if front <= 0.0:
        return 0, nothing
    origin, frame = triangle_frame(tri, n)
    # The triangle's kind and slot as run-time integers: as constants they made a second
    # specialisation of shape_contact and everything it calls (about 9 s of the cold compile).
    found, normal, point_a, point_b, depth = shape_contact(
        hulls, kind, p, r, dims, slot, np.int64(TRIANGLE), origin, frame, nothing,
        np.int64(NO_HULL), margin, sc)
    if not found:
        return 0, nothing
    into = (-n[0], -n[1], -n[2])
    lowest = surface_point(hulls, kind, p, r, dims, slot, into)
    face_gap = dot(sub(lowest, tri[0]), n)
    if face_gap < -SEAM_TOLERANCE:
        count_a = to_world_face(hulls, kind, p, r, dims, slot, normal, sc.face_a)
        count_b = triangle_face(tri, n, (-normal[0], -normal[1], -normal[2]), sc.face_b)
        count = 0
        if count_a >= 2 and count_b >= 2:
            count = clip_faces(sc.face_a, count_a, sc.face_b, count_b, normal, margin, sc,
                               out_point, out_depth)
        return add_deepest(count, point_a, point_b, depth, out_point, out_depth), normal
    for k in range(3):
        set_row(sc.face_b, k, tri[k])
    count_a = to_world_face(hulls, kind, p, r, dims, slot, into, sc.face_a)
    count = 0
    if count_a >= 2:
        count = clip_faces(sc.face_a, count_a, sc.face_b, 3, into, margin, sc, out_point,
                           out_depth)
    # The shape's lowest point when it is over the triangle and the clipped face missed it.
    # Beside the triangle with nothing clipped, the shape reaches over an edge: the nearest
    # approach gives the depth, measured along the face normal, and the lowest point is where
    # it acts, since it stands still while the shape rolls (the surface near the edge moves down
    # onto the next triangle, which the solver would take for an approach and bump the shape).
    inside = True
    for k in range(3):
        edge = sub(tri[(k + 1) % 3], tri[k])
        if dot(cross(edge, n), sub(lowest, tri[k])) > 0.0:
            inside = False
    if inside:
        depth = -face_gap
    elif count > 0:
        return count, into
    else:
        depth = dot(sub(point_b, point_a), n)
    if depth < -margin:
        return count, into
    return add_deepest(count, lowest, add_scaled(lowest, depth, n), depth, out_point,
                       out_depth), into
