"""Narrow phase: the contact manifold of every pair of shapes, of a shape and a playground
triangle, of a shape and the ground, each chosen in one place (collide_pair, collide_triangle,
collide_ground): the box/box separating-axis test and its triangle and ground versions below,
the closed forms of spheres and capsules (analytic.py), and the general convex path
(convex_contact.py) for the rest. Adding a shape means a row in each dispatcher.

A job in which a compound body takes part is one piece per pair of parts (its parts against the
other body's parts or whole shape, the triangle or the ground): collide_pieces, each piece a
manifold with a warm-start key of its own.

Box/box tests the 15 axes (3 face normals of each box, 9 edge crosses) and leaves at the first
one that separates by more than the speculative margin. On a face axis the incident face of the
other box is clipped against the reference face's side planes (up to 8 points), and the points
are reduced to the 4 that keep the manifold's area; on an edge axis the two closest edge points
give one contact. Points come out in `scratch_point`/`scratch_depth` with the A -> B normal.
"""
import numpy as np
from numba import njit, prange

from .atomics import atomic_add
from .analytic import capsule_triangle, round_ground, round_pair, sphere_box, sphere_triangle
from .constants import CONTACT_MARGIN, EDGE_AXIS_TOLERANCE, SEAM_TOLERANCE
from .convex_contact import (MAX_CLIP_POINTS, allocate_scratch, clip_polygon, convex_ground,
                     convex_pair, convex_triangle)
from .ids import GROUND, PLAYGROUND, triangle_key
from .playground import crease_rows, past_crease
from .shapes import BOX, CAPSULE, COMPOUND, SPHERE
from .shapes.compound import MAX_PARTS, part_pose

# Two threads share the narrow phase from this many pairs (bodies and triangles): a box pair
# takes ~0.3 us, and a parallel region ends only once its second thread has woken (some tens of
# microseconds, whether or not work is left for it): from 128 pairs the loose pile's median
# step (~200) was 7 % slower on two threads than on one.
PARALLEL_MIN_PAIRS = 384

FACE_AXIS_TOLERANCE = 1e-3  # B's face must beat A's by this to become the reference (no flip-flop)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def vector3(v, i):
    """Row i of an (N, 3) array as a tuple (the narrow phase works on tuples: see collide)."""
    return (v[i, 0], v[i, 1], v[i, 2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def matrix3(m, i):
    """m[i] of an (N, 3, 3) array as a tuple of its rows."""
    return ((m[i, 0, 0], m[i, 0, 1], m[i, 0, 2]), (m[i, 1, 0], m[i, 1, 1], m[i, 1, 2]),
            (m[i, 2, 0], m[i, 2, 1], m[i, 2, 2]))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def axis_dots(ra, rb, i):
    """(a_i . b_0, a_i . b_1, a_i . b_2) for the axes (columns) of rotations ra and rb."""
    return (ra[0][i] * rb[0][0] + ra[1][i] * rb[1][0] + ra[2][i] * rb[2][0],
            ra[0][i] * rb[0][1] + ra[1][i] * rb[1][1] + ra[2][i] * rb[2][1],
            ra[0][i] * rb[0][2] + ra[1][i] * rb[1][2] + ra[2][i] * rb[2][2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def box_box_axis(pa, ra, ha, pb, rb, hb, margin):
    """Best separating axis: (kind 0 face of A / 1 face of B / 2 edges / -1 separated,
    index (face axis, or 3*i + j for edge a_i x b_j), separation, normal A -> B)."""
    d0, d1, d2 = pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]
    # c[i][j] = a_i . b_j (tuples: no heap allocation per pair); t = d in A's frame
    c = (axis_dots(ra, rb, 0), axis_dots(ra, rb, 1), axis_dots(ra, rb, 2))
    # Parallel edges give near-zero crosses: the epsilon keeps them from 0/0.
    abs_c = ((abs(c[0][0]) + 1e-9, abs(c[0][1]) + 1e-9, abs(c[0][2]) + 1e-9),
             (abs(c[1][0]) + 1e-9, abs(c[1][1]) + 1e-9, abs(c[1][2]) + 1e-9),
             (abs(c[2][0]) + 1e-9, abs(c[2][1]) + 1e-9, abs(c[2][2]) + 1e-9))
    t = (d0 * ra[0][0] + d1 * ra[1][0] + d2 * ra[2][0],
         d0 * ra[0][1] + d1 * ra[1][1] + d2 * ra[2][1],
         d0 * ra[0][2] + d1 * ra[1][2] + d2 * ra[2][2])

    best_a, best_a_axis = -np.inf, -1
    for i in range(3):
        s = abs(t[i]) - (ha[i] + hb[0] * abs_c[i][0] + hb[1] * abs_c[i][1] + hb[2] * abs_c[i][2])
        if s > margin:
            return -1, 0, s, (0.0, 0.0, 0.0)
        if s > best_a:
            best_a, best_a_axis = s, i
    best_b, best_b_axis = -np.inf, -1
    for j in range(3):
        tb = d0 * rb[0][j] + d1 * rb[1][j] + d2 * rb[2][j]
        s = abs(tb) - (hb[j] + ha[0] * abs_c[0][j] + ha[1] * abs_c[1][j] + ha[2] * abs_c[2][j])
        if s > margin:
            return -1, 0, s, (0.0, 0.0, 0.0)
        if s > best_b:
            best_b, best_b_axis = s, j
    best_e, best_e_axis = -np.inf, -1
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            length = np.sqrt(max(1.0 - c[i][j] * c[i][j], 0.0))
            if length < 1e-5:
                continue  # parallel edges: the face axes already cover this direction
            radius_a = ha[i1] * abs_c[i2][j] + ha[i2] * abs_c[i1][j]
            radius_b = hb[j1] * abs_c[i][j2] + hb[j2] * abs_c[i][j1]
            s = (abs(t[i2] * c[i1][j] - t[i1] * c[i2][j]) - radius_a - radius_b) / length
            if s > margin:
                return -1, 0, s, (0.0, 0.0, 0.0)
            if s > best_e:
                best_e, best_e_axis = s, 3 * i + j

    if best_e > max(best_a, best_b) + EDGE_AXIS_TOLERANCE:
        i, j = best_e_axis // 3, best_e_axis % 3
        n0 = ra[1][i] * rb[2][j] - ra[2][i] * rb[1][j]
        n1 = ra[2][i] * rb[0][j] - ra[0][i] * rb[2][j]
        n2 = ra[0][i] * rb[1][j] - ra[1][i] * rb[0][j]
        inv = 1.0 / np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if n0 * d0 + n1 * d1 + n2 * d2 < 0.0:
            inv = -inv
        return 2, best_e_axis, best_e, (n0 * inv, n1 * inv, n2 * inv)
    if best_b > best_a + FACE_AXIS_TOLERANCE:
        j = best_b_axis
        sign = 1.0 if d0 * rb[0][j] + d1 * rb[1][j] + d2 * rb[2][j] >= 0.0 else -1.0
        return 1, j, best_b, (rb[0][j] * sign, rb[1][j] * sign, rb[2][j] * sign)
    i = best_a_axis
    sign = 1.0 if t[i] >= 0.0 else -1.0
    return 0, i, best_a, (ra[0][i] * sign, ra[1][i] * sign, ra[2][i] * sign)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def incident_box_face(p, r, h, normal, out):
    """Writes to out the 4 corners (in order around it) of the face of box (p, r, h) most
    anti-parallel to `normal`, the reference normal pointing at this box."""
    best, axis, sign = -1.0, 0, 1.0
    for k in range(3):
        d = r[0][k] * normal[0] + r[1][k] * normal[1] + r[2][k] * normal[2]
        if abs(d) > best:
            best, axis = abs(d), k
            sign = -1.0 if d > 0.0 else 1.0
    k1, k2 = (axis + 1) % 3, (axis + 2) % 3
    for corner in range(4):
        su = 1.0 if corner == 0 or corner == 3 else -1.0
        sv = 1.0 if corner < 2 else -1.0
        for e in range(3):
            out[corner, e] = p[e] + sign * r[e][axis] * h[axis] + su * r[e][k1] * h[k1] + sv * r[e][k2] * h[k2]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def keep_below(poly, n, origin, normal, margin, out_point, out_depth):
    """Points of poly at most `margin` above the reference plane (origin, normal), moved halfway
    to it; depth is how far below the plane they were. Returns their count."""
    kept = 0
    for k in range(n):
        z = ((poly[k, 0] - origin[0]) * normal[0] + (poly[k, 1] - origin[1]) * normal[1]
             + (poly[k, 2] - origin[2]) * normal[2])
        if z > margin:
            continue
        for e in range(3):
            out_point[kept, e] = poly[k, e] - 0.5 * z * normal[e]
        out_depth[kept] = -z
        kept += 1
    return kept


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def clip_to_box_face(pr, rr, hr, face_axis, normal, poly_a, n, poly_b, margin, out_point,
                     out_depth):
    """Clips the incident polygon in poly_a (n world points) to the side planes of the reference
    box's face whose outward normal is `normal`, and keeps what lies within `margin` of it."""
    for k in range(2):
        axis = (face_axis + 1 + k) % 3
        for sign in (1.0, -1.0):
            plane = (sign * rr[0][axis], sign * rr[1][axis], sign * rr[2][axis])
            offset = plane[0] * pr[0] + plane[1] * pr[1] + plane[2] * pr[2] + hr[axis]
            n = clip_polygon(poly_a, n, poly_b, plane, offset)
            poly_a, poly_b = poly_b, poly_a
    origin = (pr[0] + normal[0] * hr[face_axis], pr[1] + normal[1] * hr[face_axis],
              pr[2] + normal[2] * hr[face_axis])
    return keep_below(poly_a, n, origin, normal, margin, out_point, out_depth)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def box_edge(p, r, h, axis, direction):
    """The edge of box (p, r, h) parallel to its `axis` that lies farthest along `direction`:
    (centre, unit direction, half length)."""
    c0, c1, c2 = p[0], p[1], p[2]
    for k in range(3):
        if k != axis:
            s = h[k] if r[0][k] * direction[0] + r[1][k] * direction[1] + r[2][k] * direction[2] > 0.0 else -h[k]
            c0, c1, c2 = c0 + r[0][k] * s, c1 + r[1][k] * s, c2 + r[2][k] * s
    return (c0, c1, c2), (r[0][axis], r[1][axis], r[2][axis]), h[axis]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def segments_midpoint(ca, da, half_a, cb, db, half_b):
    """Midpoint of the closest points of two segments (centre, unit direction, half length)."""
    r0, r1, r2 = ca[0] - cb[0], ca[1] - cb[1], ca[2] - cb[2]
    b = da[0] * db[0] + da[1] * db[1] + da[2] * db[2]
    d = da[0] * r0 + da[1] * r1 + da[2] * r2
    f = db[0] * r0 + db[1] * r1 + db[2] * r2
    denom = 1.0 - b * b
    s = (b * f - d) / denom if denom > 1e-12 else 0.0
    s = min(max(s, -half_a), half_a)
    t = min(max(b * s + f, -half_b), half_b)
    s = min(max(b * t - d, -half_a), half_a)  # re-project once t was clamped
    return (0.5 * (ca[0] + s * da[0] + cb[0] + t * db[0]), 0.5 * (ca[1] + s * da[1] + cb[1] + t * db[1]),
            0.5 * (ca[2] + s * da[2] + cb[2] + t * db[2]))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def reduce_manifold(points, depths, n, normal, keep):
    """Indices of at most 4 points: the deepest, the farthest from it, then the two spanning the
    largest triangles on either side, so the kept quad supports the body like the full set."""
    if n <= 4:
        for k in range(n):
            keep[k] = k
        return n
    first = 0
    for k in range(1, n):
        if depths[k] > depths[first]:
            first = k
    second, best = first, -1.0
    for k in range(n):
        d = ((points[k, 0] - points[first, 0]) ** 2 + (points[k, 1] - points[first, 1]) ** 2
             + (points[k, 2] - points[first, 2]) ** 2)
        if d > best:
            second, best = k, d
    ex, ey, ez = (points[second, 0] - points[first, 0], points[second, 1] - points[first, 1],
                  points[second, 2] - points[first, 2])
    third, fourth, most, least = -1, -1, 0.0, 0.0
    for k in range(n):
        if k == first or k == second:
            continue
        px, py, pz = points[k, 0] - points[first, 0], points[k, 1] - points[first, 1], points[k, 2] - points[first, 2]
        area = (ey * pz - ez * py) * normal[0] + (ez * px - ex * pz) * normal[1] + (ex * py - ey * px) * normal[2]
        if third < 0 or area > most:
            third, most = k, area
        if fourth < 0 or area < least:
            fourth, least = k, area
    keep[0], keep[1] = first, second
    count = 2
    if third >= 0:
        keep[count] = third
        count += 1
    if fourth >= 0 and fourth != third:
        keep[count] = fourth
        count += 1
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def box_box(pa, ra, ha, pb, rb, hb, margin, poly_a, poly_b, out_point, out_depth):
    """Manifold of boxes A and B: returns (point count, normal A -> B). (Inlined into its
    callers, with the face clipping it calls: as calls handing over the scratch arrays they took
    ~15 % of a pile's narrow phase.)"""
    kind, index, separation, normal = box_box_axis(pa, ra, ha, pb, rb, hb, margin)
    if kind < 0:
        return 0, normal
    if kind == 2:
        ca, da, half_a = box_edge(pa, ra, ha, index // 3, normal)
        cb, db, half_b = box_edge(pb, rb, hb, index % 3, (-normal[0], -normal[1], -normal[2]))
        point = segments_midpoint(ca, da, half_a, cb, db, half_b)
        for e in range(3):
            out_point[0, e] = point[e]
        out_depth[0] = -separation
        return 1, normal
    if kind == 0:
        incident_box_face(pb, rb, hb, normal, poly_a)
        n = clip_to_box_face(pa, ra, ha, index, normal, poly_a, 4, poly_b, margin, out_point,
                             out_depth)
        return n, normal
    # B's face is the reference: clip with the normal pointing from B to A; report A -> B.
    flipped = (-normal[0], -normal[1], -normal[2])
    incident_box_face(pa, ra, ha, flipped, poly_a)
    n = clip_to_box_face(pb, rb, hb, index, flipped, poly_a, 4, poly_b, margin, out_point,
                         out_depth)
    return n, normal


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def interval_separation(box_center, box_radius, t0, t1, t2):
    """Gap between the box's [c - r, c + r] and the triangle's projections on an axis, and
    +1 when the triangle lies on the axis' positive side (else -1)."""
    low, high = min(t0, t1, t2), max(t0, t1, t2)
    above, below = low - (box_center + box_radius), (box_center - box_radius) - high
    return (above, 1.0) if above > below else (below, -1.0)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def box_triangle(p, r, h, tri, tri_normal, edges, creases, margin, poly_a, poly_b, out_point,
                 out_depth):
    """Manifold of a box and a one-sided triangle (`edges`, `creases`: its Playground.edges and
    crease_rows): (point count, normal box -> triangle).

    13 axes: the triangle's normal, the box's 3 face axes, 9 crosses of box axes and triangle
    edges. The triangle's face is the reference whenever the box is in front of it and sunk at
    most SEAM_TOLERANCE below its plane: a box sliding over the seam between two coplanar
    triangles then gets the face normal from the next triangle too, instead of an edge or side
    axis that would point into the neighbour and catch it. A box deeper below the plane is
    beside the triangle (at a step's riser, say), and the best axis decides: a box face clips
    the triangle, or two edges give one point; only an axis along which the triangle would push
    the box out of its front (or along it) may decide, since nothing is behind a one-sided
    triangle: a box sliding up the ramp, its rear below the platform's plane, had its front face
    taken for the separating axis, and the platform stopped it like a wall at the ridge. Past a
    concave edge, for a box in front of the triangle across it (playground.past_crease), the
    box's side is clipped to the strip beyond the edge instead (between the lines across it at its ends): the plane goes on there, so a
    box coming down a ramp onto a floor meets the floor's plane before it crosses it."""
    v0, v1, v2 = tri[0], tri[1], tri[2]
    n = (tri_normal[0], tri_normal[1], tri_normal[2])
    front = (p[0] - v0[0]) * n[0] + (p[1] - v0[1]) * n[1] + (p[2] - v0[2]) * n[2]
    if front <= 0.0:
        return 0, (0.0, 0.0, 0.0)  # one-sided: behind the face is the inside of the solid
    face_gap = front - (h[0] * abs(r[0][0] * n[0] + r[1][0] * n[1] + r[2][0] * n[2])
                        + h[1] * abs(r[0][1] * n[0] + r[1][1] * n[1] + r[2][1] * n[2])
                        + h[2] * abs(r[0][2] * n[0] + r[1][2] * n[1] + r[2][2] * n[2]))
    if face_gap > margin:
        return 0, (0.0, 0.0, 0.0)
    best, best_kind, best_axis, best_sign = face_gap, 0, 0, 1.0
    best_dir = (0.0, 0.0, 0.0)
    for k in range(3):
        a = (r[0][k], r[1][k], r[2][k])
        gap, sign = interval_separation(
            p[0] * a[0] + p[1] * a[1] + p[2] * a[2], h[k],
            v0[0] * a[0] + v0[1] * a[1] + v0[2] * a[2], v1[0] * a[0] + v1[1] * a[1] + v1[2] * a[2],
            v2[0] * a[0] + v2[1] * a[1] + v2[2] * a[2])
        if gap > margin:
            return 0, (0.0, 0.0, 0.0)
        if gap > best and sign * (a[0] * n[0] + a[1] * n[1] + a[2] * n[2]) <= 0.0:
            best, best_kind, best_axis, best_sign = gap, 1, k, sign
    for j in range(3):
        e0 = tri[(j + 1) % 3][0] - tri[j][0]
        e1 = tri[(j + 1) % 3][1] - tri[j][1]
        e2 = tri[(j + 1) % 3][2] - tri[j][2]
        for k in range(3):
            l0 = r[1][k] * e2 - r[2][k] * e1
            l1 = r[2][k] * e0 - r[0][k] * e2
            l2 = r[0][k] * e1 - r[1][k] * e0
            length = np.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
            if length < 1e-9:
                continue  # edge parallel to a box axis: the face axes cover it
            l0, l1, l2 = l0 / length, l1 / length, l2 / length
            radius = (h[0] * abs(r[0][0] * l0 + r[1][0] * l1 + r[2][0] * l2)
                      + h[1] * abs(r[0][1] * l0 + r[1][1] * l1 + r[2][1] * l2)
                      + h[2] * abs(r[0][2] * l0 + r[1][2] * l1 + r[2][2] * l2))
            gap, sign = interval_separation(
                p[0] * l0 + p[1] * l1 + p[2] * l2, radius,
                v0[0] * l0 + v0[1] * l1 + v0[2] * l2, v1[0] * l0 + v1[1] * l1 + v1[2] * l2,
                v2[0] * l0 + v2[1] * l1 + v2[2] * l2)
            if gap > margin:
                return 0, (0.0, 0.0, 0.0)
            if gap > best + EDGE_AXIS_TOLERANCE and sign * (l0 * n[0] + l1 * n[1] + l2 * n[2]) <= 0.0:
                best, best_kind, best_axis, best_sign = gap, 2, 3 * k + j, sign
                best_dir = (l0 * sign, l1 * sign, l2 * sign)
    if best_kind == 0 or face_gap >= -SEAM_TOLERANCE:
        # The triangle's face is the reference: clip the box's facing side to its edges.
        incident_box_face(p, r, h, n, poly_a)
        count = 4
        for j in range(3):
            a, b = tri[j], tri[(j + 1) % 3]
            along = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
            if past_crease(edges, creases, j, p):
                # The strip past the edge: along . x from along . a to along . b.
                count = clip_polygon(poly_a, count, poly_b, (-along[0], -along[1], -along[2]),
                                     -(along[0] * a[0] + along[1] * a[1] + along[2] * a[2]))
                poly_a, poly_b = poly_b, poly_a
                count = clip_polygon(poly_a, count, poly_b, along,
                                     along[0] * b[0] + along[1] * b[1] + along[2] * b[2])
                poly_a, poly_b = poly_b, poly_a
                continue
            plane = (along[1] * n[2] - along[2] * n[1], along[2] * n[0] - along[0] * n[2],
                     along[0] * n[1] - along[1] * n[0])  # edge x normal: outwards
            offset = plane[0] * a[0] + plane[1] * a[1] + plane[2] * a[2]
            count = clip_polygon(poly_a, count, poly_b, plane, offset)
            poly_a, poly_b = poly_b, poly_a
        count = keep_below(poly_a, count, v0, n, margin, out_point, out_depth)
        return count, (-n[0], -n[1], -n[2])
    if best_kind == 1:
        k = best_axis
        normal = (r[0][k] * best_sign, r[1][k] * best_sign, r[2][k] * best_sign)
        for corner in range(3):
            for e in range(3):
                poly_a[corner, e] = tri[corner][e]
        count = clip_to_box_face(p, r, h, k, normal, poly_a, 3, poly_b, margin, out_point, out_depth)
        return count, normal
    k, j = best_axis // 3, best_axis % 3
    ca, da, half_a = box_edge(p, r, h, k, best_dir)
    a, b = tri[j], tri[(j + 1) % 3]
    length = np.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
    cb = (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2]))
    db = ((b[0] - a[0]) / length, (b[1] - a[1]) / length, (b[2] - a[2]) / length)
    point = segments_midpoint(ca, da, half_a, cb, db, 0.5 * length)
    for e in range(3):
        out_point[0, e] = point[e]
    out_depth[0] = -best
    return 1, best_dir


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def box_ground(p, r, h, height, margin, out_point, out_depth):
    """Corners of the box's lower half within `margin` of the plane z = height; points halfway
    to the plane. (The upper ones meet the plane after them: a box smaller than the margin gave
    all eight, the manifold kept the deepest and the corner farthest from it, a top one, and a
    1 cm cube stood on three corners, sunk to 0.45 of its half-height and tilted 11 degrees.)"""
    n = 0
    for corner in range(8):
        sx = 1.0 if corner & 1 else -1.0
        sy = 1.0 if corner & 2 else -1.0
        sz = 1.0 if corner & 4 else -1.0
        above_centre = sx * r[2][0] * h[0] + sy * r[2][1] * h[1] + sz * r[2][2] * h[2]
        if above_centre > 0.0:
            continue
        z = p[2] + above_centre
        gap = z - height
        if gap > margin:
            continue
        out_point[n, 0] = p[0] + sx * r[0][0] * h[0] + sy * r[0][1] * h[1] + sz * r[0][2] * h[2]
        out_point[n, 1] = p[1] + sx * r[1][0] * h[0] + sy * r[1][1] * h[1] + sz * r[1][2] * h[2]
        out_point[n, 2] = z - 0.5 * gap
        out_depth[n] = -gap
        n += 1
    return n


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def is_round(kind):
    return kind == SPHERE or kind == CAPSULE


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def flipped(pair):
    count, normal = pair
    return count, (-normal[0], -normal[1], -normal[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def collide_pair(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, margin, scratch,
                 out_point, out_depth):
    """Manifold of two bodies (shape code, position, rotation rows, dimensions, slot each; the
    slot finds a convex body's hull in `hulls`): (point count, normal A -> B), the points in
    out_point/out_depth. Boxes first: most pairs are."""
    if kind_a == BOX and kind_b == BOX:
        return box_box(pa, ra, da, pb, rb, db, margin, scratch.poly_a, scratch.poly_b,
                       out_point, out_depth)
    if is_round(kind_a) and is_round(kind_b):
        return round_pair(pa, ra, da, pb, rb, db, margin, out_point, out_depth)
    if kind_a == SPHERE and kind_b == BOX:
        return sphere_box(pa, da[0], pb, rb, db, margin, out_point, out_depth)
    if kind_a == BOX and kind_b == SPHERE:
        return flipped(sphere_box(pb, db[0], pa, ra, da, margin, out_point, out_depth))
    return convex_pair(hulls, kind_a, pa, ra, da, slot_a, kind_b, pb, rb, db, slot_b, margin,
                       scratch, out_point, out_depth)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def collide_triangle(hulls, kind, p, r, dims, slot, tri, tri_normal, edges, creases, margin,
                     scratch, out_point, out_depth):
    """Manifold of a body and a one-sided playground triangle (`edges`, `creases`: its
    Playground.edges and crease_rows): (point count, normal body -> triangle)."""
    if kind == BOX:
        return box_triangle(p, r, dims, tri, tri_normal, edges, creases, margin, scratch.poly_a,
                            scratch.poly_b, out_point, out_depth)
    if kind == SPHERE:
        return sphere_triangle(p, dims[0], tri, tri_normal, edges, creases, margin, out_point,
                               out_depth)
    if kind == CAPSULE:
        count = capsule_triangle(p, r, dims, tri, tri_normal, edges, creases, margin, out_point,
                                 out_depth)
        if count > 0:
            return count, (-tri_normal[0], -tri_normal[1], -tri_normal[2])
    return convex_triangle(hulls, kind, p, r, dims, slot, tri, tri_normal, margin, scratch,
                           out_point, out_depth)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def collide_ground(hulls, kind, p, r, dims, slot, height, margin, scratch, out_point, out_depth):
    """Points of a body within `margin` of the ground z = height (normal (0, 0, -1)): count."""
    if kind == BOX:
        return box_ground(p, r, dims, height, margin, out_point, out_depth)
    if is_round(kind):
        return round_ground(p, r, dims, height, margin, out_point, out_depth)
    return convex_ground(hulls, kind, p, r, dims, slot, height, margin, scratch, out_point,
                         out_depth)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def piece(parts, shape, position, rotation, dimensions, half_extents, body, k):
    """Body `body` as the narrow phase takes a shape, or its part k when it is a compound:
    (shape code, position, rotation rows, dimensions, hull row, radius of a sphere about the
    position holding it)."""
    p, r = vector3(position, body), matrix3(rotation, body)
    if shape[body] == COMPOUND:
        row = parts.start[body] + k
        kind, pp, pr, pd, hull = part_pose(parts, row, p, r)
        return kind, pp, pr, pd, hull, parts.radius[row]
    h = half_extents[body]
    return shape[body], p, r, vector3(dimensions, body), body, np.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def near_pieces(parts, shape, position, rotation, dimensions, half_extents, a, b, triangle, margin,
                ground_height, triangles, triangle_normals, spheres, out):
    """The pieces of a job in which a compound takes part that may touch, in `out`; returns
    their count. Piece i * pieces_b + j is part i of body a (or a whole) against part j of body
    b (or b whole), or against playground triangle `triangle` (b PLAYGROUND) or the ground (b
    GROUND), j 0. A piece is kept when the parts' bounding spheres come within the margin of
    each other, of the triangle's plane or of the ground: a table's legs meet the ground, not
    the box on its top, and the rest cost no call of their own. `spheres` (MAX_PARTS, 4) holds
    B's parts' centres and radii meanwhile."""
    pieces_a = parts.count[a] if shape[a] == COMPOUND else 1
    pieces_b = parts.count[b] if b >= 0 and shape[b] == COMPOUND else 1
    if b >= 0:
        for j in range(pieces_b):
            _, pb, _, _, _, radius_b = piece(parts, shape, position, rotation, dimensions, half_extents, b, j)
            spheres[j, 0], spheres[j, 1], spheres[j, 2], spheres[j, 3] = pb[0], pb[1], pb[2], radius_b
    count = 0
    for i in range(pieces_a):
        _, pa, _, _, _, radius_a = piece(parts, shape, position, rotation, dimensions, half_extents, a, i)
        if b >= 0:
            for j in range(pieces_b):
                gap = (spheres[j, 0] - pa[0], spheres[j, 1] - pa[1], spheres[j, 2] - pa[2])
                reach = radius_a + spheres[j, 3] + margin
                if gap[0] * gap[0] + gap[1] * gap[1] + gap[2] * gap[2] <= reach * reach:
                    out[count] = i * pieces_b + j
                    count += 1
            continue
        if b == PLAYGROUND:
            v, n = triangles[triangle, 0], triangle_normals[triangle]
            above = (pa[0] - v[0]) * n[0] + (pa[1] - v[1]) * n[1] + (pa[2] - v[2]) * n[2]
            near = -radius_a <= above <= radius_a + margin  # not off its plane, nor wholly behind it
        else:
            near = pa[2] - radius_a <= ground_height + margin
        if near:
            out[count] = i
            count += 1
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def collide_pieces(hulls, parts, shape, position, rotation, dimensions, half_extents, a, b, triangle,
                   job_piece, pieces_b, margin, ground_height, triangles, triangle_normals,
                   triangle_edges, triangle_creases, scratch, out_point, out_depth):
    """Manifold of piece `job_piece` (see near_pieces) of a job in which a compound takes part.
    Returns (point count, normal A -> B, and the manifold's warm-start keys).

    The keys tell the parts apart, so no two manifolds of one pair of bodies share impulses:
    key A is -2 - (a * MAX_PARTS + i), below every body slot (and the hash table's empty -1),
    so compound keys never meet the other manifolds'; key B is b * MAX_PARTS + j for a body,
    the ground's or the triangle's key otherwise."""
    i, j = job_piece // pieces_b, job_piece % pieces_b
    kind_a, pa, ra, da, hull_a, _ = piece(parts, shape, position, rotation, dimensions, half_extents, a, i)
    key_a = -2 - (a * MAX_PARTS + i)
    if b >= 0:
        kind_b, pb, rb, db, hull_b, _ = piece(parts, shape, position, rotation, dimensions, half_extents, b, j)
        n, normal = collide_pair(hulls, kind_a, pa, ra, da, hull_a, kind_b, pb, rb, db, hull_b, margin,
                                 scratch, out_point, out_depth)
        return n, normal, key_a, b * MAX_PARTS + j
    if b == PLAYGROUND:
        n, normal = collide_triangle(hulls, kind_a, pa, ra, da, hull_a, matrix3(triangles, triangle),
                                     vector3(triangle_normals, triangle), triangle_edges[triangle],
                                     crease_rows(triangle_creases, triangle), margin, scratch,
                                     out_point, out_depth)
        return n, normal, key_a, triangle_key(triangle)
    n = collide_ground(hulls, kind_a, pa, ra, da, hull_a, ground_height, margin, scratch, out_point, out_depth)
    return n, (0.0, 0.0, -1.0), key_a, GROUND


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def reaches_ground(awake, aabb_min, body, ground_height):
    """Whether a body has a ground job to do: awake, its bounds within half the contact margin
    of the ground (the bounds are grown by the other half)."""
    return awake[body] and aabb_min[body, 2] <= ground_height + 0.5 * CONTACT_MARGIN


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def collide(contacts, bodies, hulls, parts, broad, playground, ground_enabled, ground_height, live,
            threads):
    """Manifolds of every candidate pair, of every (body, playground triangle) candidate and of
    every awake body among `live` (slots, ascending) with the ground, each reduced to at most 4
    points and appended to `contacts` in that order. With `threads` > 1 and enough pairs, two
    threads share the jobs, with the same result. Returns False when the contact buffers are
    full (nothing of the step has been applied yet)."""
    jobs = broad.pair_count[0] + broad.playground_count[0] + (len(live) if ground_enabled else 0)
    # A part that outgrows its half of the buffers runs again on one thread, not as a full
    # buffer: a step that grows them runs its detection again, and after bodies woke that is not
    # the step the serial run takes (the woken are counted once, the static index may rebuild).
    if (threads > 1 and broad.pair_count[0] + broad.playground_count[0] >= PARALLEL_MIN_PAIRS
            and collide_shared(contacts, bodies, hulls, parts, broad, playground, ground_enabled,
                               ground_height, live, jobs)):
        return True
    # Typed zeros: literal ones made Numba compile collide_jobs once more than the shared path's.
    count, manifolds = collide_jobs(contacts, bodies, hulls, parts, broad.pair_a, broad.pair_b,
                                    broad.pair_count[0], broad.playground_body,
                                    broad.playground_triangle, broad.playground_count[0],
                                    playground.triangles, playground.normals, playground.edges,
                                    playground.creases, ground_enabled, ground_height, live, np.int64(0),
                                    jobs, np.int64(0), np.int64(0),
                                    len(contacts.body_a),
                                    len(contacts.manifold_start))
    contacts.count[0], contacts.manifold_count[0] = max(count, 0), max(manifolds, 0)
    return count >= 0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def collide_shared(contacts, bodies, hulls, parts, broad, playground, ground_enabled, ground_height,
                   live, jobs):
    """collide on two threads: the jobs in two parts of about equal work, the first part's
    manifolds written from the buffers' start, the second's from their middle, then moved down
    behind the first's: the order, and so every later stage, is the serial one. Either thread
    may run either part (whichever is free first: a late second thread finds both taken).
    False, with no contacts, when a part outgrew its half."""
    pairs = broad.pair_count[0] + broad.playground_count[0]
    # A pair's job is about the work of a box on the ground; a ground job of a body well above
    # the ground is a skipped test.
    near = 0
    if ground_enabled:
        for k in range(len(live)):
            if reaches_ground(bodies.awake, bodies.aabb_min, live[k], ground_height):
                near += 1
    half = (pairs + near) // 2
    middle = half
    if half > pairs:  # the first part takes ground jobs too, up to its share of the near ones
        middle, seen = pairs, pairs
        while middle < jobs and seen < half:
            if reaches_ground(bodies.awake, bodies.aabb_min, live[middle - pairs], ground_height):
                seen += 1
            middle += 1
    point_half, manifold_half = len(contacts.body_a) // 2, len(contacts.manifold_start) // 2
    bounds = np.array([[0, middle, 0, 0, point_half, manifold_half],
                       [middle, jobs, point_half, manifold_half, len(contacts.body_a),
                        len(contacts.manifold_start)]], np.int64)
    ends = np.empty((2, 2), np.int64)
    sync = np.zeros(1, np.int64)
    run_collide_workers(contacts, bodies, hulls, parts, broad.pair_a, broad.pair_b,
                        broad.pair_count[0], broad.playground_body, broad.playground_triangle,
                        broad.playground_count[0], playground.triangles, playground.normals,
                        playground.edges, playground.creases, ground_enabled, ground_height, live,
                        bounds, ends, sync)
    if ends[0, 0] < 0 or ends[1, 0] < 0:
        contacts.count[0] = contacts.manifold_count[0] = 0
        return False
    count, manifolds = ends[0, 0], ends[0, 1]
    moved, shift = ends[1, 0] - point_half, count - point_half
    for k in range(point_half, ends[1, 0]):
        contacts.body_a[k + shift], contacts.body_b[k + shift] = contacts.body_a[k], contacts.body_b[k]
        contacts.depth[k + shift] = contacts.depth[k]
        for e in range(3):
            contacts.point[k + shift, e] = contacts.point[k, e]
            contacts.normal[k + shift, e] = contacts.normal[k, e]
            contacts.local_a[k + shift, e] = contacts.local_a[k, e]
    for m in range(manifold_half, ends[1, 1]):
        to = manifolds + m - manifold_half
        contacts.manifold_start[to] = contacts.manifold_start[m] + shift
        contacts.manifold_size[to] = contacts.manifold_size[m]
        contacts.manifold_a[to], contacts.manifold_b[to] = contacts.manifold_a[m], contacts.manifold_b[m]
    contacts.count[0] = count + moved
    contacts.manifold_count[0] = manifolds + ends[1, 1] - manifold_half
    return True


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True, parallel=True)
def run_collide_workers(contacts, bodies, hulls, parts, pair_a, pair_b, body_pairs, mesh_body,
                        mesh_triangle, mesh_pairs, triangles, triangle_normals, triangle_edges,
                        triangle_creases, ground_enabled, ground_height, live, bounds, ends, sync):
    """One parallel region: each thread takes a part (bounds[part]: first and last job, first
    point and manifold, their ends) until none is left, and leaves its counts in ends[part]."""
    for _ in prange(2):
        while True:
            part = atomic_add(sync, 0, 1)
            if part >= 2:
                break
            first, last, count, manifolds, point_end, manifold_end = (
                bounds[part, 0], bounds[part, 1], bounds[part, 2], bounds[part, 3], bounds[part, 4],
                bounds[part, 5])
            ends[part, 0], ends[part, 1] = collide_jobs(
                contacts, bodies, hulls, parts, pair_a, pair_b, body_pairs, mesh_body, mesh_triangle,
                mesh_pairs, triangles, triangle_normals, triangle_edges, triangle_creases,
                ground_enabled, ground_height, live, first, last, count, manifolds, point_end,
                manifold_end)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def collide_jobs(contacts, bodies, hulls, parts, pair_a, pair_b, body_pairs, mesh_body, mesh_triangle,
                 mesh_pairs, triangles, triangle_normals, triangle_edges, triangle_creases,
                 ground_enabled, ground_height, live, first, last, count, manifolds, point_end,
                 manifold_end):
    """collide's jobs first to last - 1 (the body_pairs pairs, then the mesh_pairs (body,
    playground triangle) pairs, then the live bodies against the ground), their manifolds
    written from point `count` and manifold `manifolds` on, short of point_end and
    manifold_end. Returns the point and manifold counts after them, or (-1, -1) when the space
    ran out. (The broad phase's and the playground's arrays one by one: a parallel region takes
    no tuple holding tuples.)

    One flat loop over the three kinds of job with one emitting block, and the geometry on
    tuples: Numba counts references to every array (and view) handed to a call, and that cost
    more than the geometry when a helper took `contacts` and `bodies` per manifold. For the same
    reason boxes go straight to the first rows of collide_pair, collide_triangle and
    collide_ground: through the dispatchers (whose arguments include the convex path's scratch
    arrays) a falling pile of boxes spent 40 % longer here. A job with a compound body is one
    piece per pair of its parts that may touch (near_pieces, collide_pieces), the others one
    piece."""
    scratch = allocate_scratch()
    poly_a, poly_b = scratch.poly_a, scratch.poly_b
    scratch_point = np.empty((MAX_CLIP_POINTS, 3))
    scratch_depth = np.empty(MAX_CLIP_POINTS)
    keep = np.empty(4, np.int64)
    spheres, near = np.empty((MAX_PARTS, 4)), np.empty(MAX_PARTS * MAX_PARTS, np.int64)
    reach, awake = bodies.speculative_reach, bodies.awake
    position, rotation, dimensions, shape = (bodies.position, bodies.rotation, bodies.dimensions,
                                             bodies.shape)
    body_a, body_b, point, normal_out = contacts.body_a, contacts.body_b, contacts.point, contacts.normal
    depth, local_a = contacts.depth, contacts.local_a
    manifold_start, manifold_size = contacts.manifold_start, contacts.manifold_size
    manifold_a, manifold_b = contacts.manifold_a, contacts.manifold_b
    part_count = parts.count
    down = (0.0, 0.0, -1.0)
    for job in range(first, last):
        t = -1
        if job < body_pairs:
            a, b = pair_a[job], pair_b[job]
            if not awake[a]:
                a, b = b, a  # the moving body first: the ground-contact code and solver expect it
            key_b = b
            margin = CONTACT_MARGIN + reach[a] + reach[b]
        elif job < body_pairs + mesh_pairs:
            a, t = mesh_body[job - body_pairs], mesh_triangle[job - body_pairs]
            # Each triangle is its own manifold (its own warm-start key); all are the PLAYGROUND.
            b, key_b = PLAYGROUND, triangle_key(t)
            margin = CONTACT_MARGIN + reach[a]
        else:
            a = live[job - body_pairs - mesh_pairs]
            if not reaches_ground(awake, bodies.aabb_min, a, ground_height):
                continue
            b, key_b = GROUND, GROUND
            margin = CONTACT_MARGIN + reach[a]
        pieces_b = part_count[b] if b >= 0 and shape[b] == COMPOUND else 1
        compound = shape[a] == COMPOUND or (b >= 0 and shape[b] == COMPOUND)
        pieces = 1
        if compound:
            pieces = near_pieces(parts, shape, position, rotation, dimensions, bodies.half_extents, a, b, t,
                                 margin, ground_height, triangles, triangle_normals, spheres, near)
        for job_piece in range(pieces):
            key_a = a
            if compound:
                n, normal, key_a, key_b = collide_pieces(
                    hulls, parts, shape, position, rotation, dimensions, bodies.half_extents, a, b, t,
                    near[job_piece], pieces_b, margin, ground_height, triangles,
                    triangle_normals, triangle_edges, triangle_creases, scratch, scratch_point,
                    scratch_depth)
            elif job < body_pairs:
                if shape[a] == BOX and shape[b] == BOX:
                    n, normal = box_box(vector3(position, a), matrix3(rotation, a),
                                        vector3(dimensions, a), vector3(position, b),
                                        matrix3(rotation, b), vector3(dimensions, b), margin, poly_a,
                                        poly_b, scratch_point, scratch_depth)
                else:
                    n, normal = collide_pair(hulls, shape[a], vector3(position, a),
                                             matrix3(rotation, a), vector3(dimensions, a), a,
                                             shape[b], vector3(position, b), matrix3(rotation, b),
                                             vector3(dimensions, b), b, margin, scratch,
                                             scratch_point, scratch_depth)
            elif job < body_pairs + mesh_pairs:
                if shape[a] == BOX:
                    n, normal = box_triangle(vector3(position, a), matrix3(rotation, a),
                                             vector3(dimensions, a), matrix3(triangles, t),
                                             vector3(triangle_normals, t), triangle_edges[t],
                                             crease_rows(triangle_creases, t), margin, poly_a,
                                             poly_b, scratch_point, scratch_depth)
                else:
                    n, normal = collide_triangle(hulls, shape[a], vector3(position, a),
                                                 matrix3(rotation, a), vector3(dimensions, a), a,
                                                 matrix3(triangles, t),
                                                 vector3(triangle_normals, t), triangle_edges[t],
                                                 crease_rows(triangle_creases, t), margin,
                                                 scratch, scratch_point, scratch_depth)
            else:
                normal = down
                if shape[a] == BOX:
                    n = box_ground(vector3(position, a), matrix3(rotation, a), vector3(dimensions, a),
                                   ground_height, margin, scratch_point, scratch_depth)
                else:
                    n = collide_ground(hulls, shape[a], vector3(position, a), matrix3(rotation, a),
                                       vector3(dimensions, a), a, ground_height,
                                       margin, scratch, scratch_point,
                                       scratch_depth)
            if n == 0:
                continue
            kept = reduce_manifold(scratch_point, scratch_depth, n, normal, keep)
            if count + kept > point_end or manifolds >= manifold_end:
                return -1, -1
            for k in range(kept):
                c = count + k
                src = keep[k]
                body_a[c], body_b[c] = a, b
                for e in range(3):
                    point[c, e] = scratch_point[src, e]
                    normal_out[c, e] = normal[e]
                depth[c] = scratch_depth[src]
                dx = scratch_point[src, 0] - position[a, 0]
                dy = scratch_point[src, 1] - position[a, 1]
                dz = scratch_point[src, 2] - position[a, 2]
                for e in range(3):  # the point in A's frame: its identity for the warm start
                    local_a[c, e] = rotation[a, 0, e] * dx + rotation[a, 1, e] * dy + rotation[a, 2, e] * dz
            manifold_start[manifolds], manifold_size[manifolds] = count, kept
            manifold_a[manifolds], manifold_b[manifolds] = key_a, key_b
            count += kept
            manifolds += 1
    return count, manifolds
