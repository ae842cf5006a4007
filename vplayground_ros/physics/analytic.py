"""Closed-form contacts of the round shapes. A sphere is a point grown by its radius and a
capsule a segment grown by its radius, so their contacts with each other, with a box (a
sphere's), with the ground and with a triangle (a sphere's) follow from the closest points of
the cores: exact, and cheaper than the convex path's iterations. Same conventions as
narrow_phase: points halfway between the surfaces, depth positive when overlapping, normal
from the first shape to the second."""
import numpy as np
from numba import njit

from .constants import SEAM_TOLERANCE
from .convex_contact import (PARALLEL_SINE, add_scaled, dot, scaled, set_row, sub, to_local,
                     to_world, triangle_weights)
from .math3d import cross
from .playground import past_crease


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def core_axis(r):
    """A capsule's axis (its body z) in the world."""
    return (r[0][2], r[1][2], r[2][2])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def segments_closest(ca, ua, ha, cb, ub, hb):
    """Parameters (s, t) in [-ha, ha] x [-hb, hb] of the closest points ca + s ua, cb + t ub of
    two segments given by centre, unit direction and half length (0 for a point)."""
    r = sub(ca, cb)
    b, d, f = dot(ua, ub), dot(ua, r), dot(ub, r)
    denom = 1.0 - b * b
    s = (b * f - d) / denom if denom > 1e-12 else 0.0
    s = min(max(s, -ha), ha)
    t = min(max(b * s + f, -hb), hb)
    s = min(max(b * t - d, -ha), ha)  # re-project once t was clamped
    return s, t


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def put_contact(out_point, out_depth, k, surface_a, surface_b, depth):
    set_row(out_point, k, scaled(0.5, add_scaled(surface_a, 1.0, surface_b)))
    out_depth[k] = depth


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def meeting_normal(pa, ua, ha, pb, ub, hb):
    """A normal for cores that meet (no closest-point direction): square to both segments (or
    to the one segment), pointing from A's centre towards B's."""
    if ha > 0.0 and hb > 0.0:
        normal = cross(ua, ub)
    else:
        normal = (0.0, 0.0, 0.0)
    axis = ua if ha > 0.0 else ub
    if dot(normal, normal) < 1e-12 and (ha > 0.0 or hb > 0.0):
        normal = cross(axis, (1.0, 0.0, 0.0))
        if dot(normal, normal) < 1e-12:
            normal = cross(axis, (0.0, 1.0, 0.0))
    if dot(normal, normal) < 1e-12:
        normal = (0.0, 0.0, 1.0)  # two coincident points
    normal = scaled(1.0 / np.sqrt(dot(normal, normal)), normal)
    return scaled(-1.0, normal) if dot(normal, sub(pb, pa)) < 0.0 else normal


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def round_pair(pa, ra, da, pb, rb, db, margin, out_point, out_depth):
    """Spheres and capsules (dims: radius, half length of the core; 0 for a sphere): (point
    count, normal A -> B). Two capsules lying (nearly) parallel touch along a stretch: its two
    ends are the points."""
    ua, ub = core_axis(ra), core_axis(rb)
    ha, hb = da[1], db[1]
    radii = da[0] + db[0]
    s, t = segments_closest(pa, ua, ha, pb, ub, hb)
    qa, qb = add_scaled(pa, s, ua), add_scaled(pb, t, ub)
    gap = sub(qb, qa)
    distance = np.sqrt(dot(gap, gap))
    if distance > radii + margin:
        return 0, (0.0, 0.0, 0.0)
    if distance > 1e-12:
        normal = scaled(1.0 / distance, gap)
    else:
        normal = meeting_normal(pa, ua, ha, pb, ub, hb)
    count = 0
    across = cross(ua, ub)
    if ha > 0.0 and hb > 0.0 and dot(across, across) < PARALLEL_SINE * PARALLEL_SINE:
        ends = (dot(sub(add_scaled(pb, -hb, ub), pa), ua), dot(sub(add_scaled(pb, hb, ub), pa), ua))
        low, high = max(-ha, min(ends[0], ends[1])), min(ha, max(ends[0], ends[1]))
        if high - low > 1e-9:
            for s_end in (low, high):
                qa = add_scaled(pa, s_end, ua)
                t_end = min(max(dot(sub(qa, pb), ub), -hb), hb)
                qb = add_scaled(pb, t_end, ub)
                depth = radii - dot(sub(qb, qa), normal)
                if depth >= -margin:
                    put_contact(out_point, out_depth, count, add_scaled(qa, da[0], normal),
                                add_scaled(qb, -db[0], normal), depth)
                    count += 1
            if count > 0:
                return count, normal
    put_contact(out_point, out_depth, 0, add_scaled(qa, da[0], normal),
                add_scaled(qb, -db[0], normal), radii - distance)
    return 1, normal


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def sphere_box(c, radius, pb, rb, hb, margin, out_point, out_depth):
    """Sphere (centre, radius) and box (p, r, half extents): (point count, normal sphere ->
    box). The box's closest point to the centre gives the normal; a centre inside the box
    leaves through the face it is nearest."""
    local = to_local(rb, sub(c, pb))
    closest = (min(max(local[0], -hb[0]), hb[0]), min(max(local[1], -hb[1]), hb[1]),
               min(max(local[2], -hb[2]), hb[2]))
    gap = sub(closest, local)
    distance_sq = dot(gap, gap)
    if distance_sq > 0.0:
        distance = np.sqrt(distance_sq)
        if distance > radius + margin:
            return 0, (0.0, 0.0, 0.0)
        normal_local = scaled(1.0 / distance, gap)
        depth = radius - distance
    else:
        axis, least = 0, np.inf
        for k in range(3):
            if hb[k] - abs(local[k]) < least:
                axis, least = k, hb[k] - abs(local[k])
        sign = 1.0 if local[axis] >= 0.0 else -1.0
        normal_local = (-sign if axis == 0 else 0.0, -sign if axis == 1 else 0.0,
                        -sign if axis == 2 else 0.0)
        closest = (sign * hb[0] if axis == 0 else local[0], sign * hb[1] if axis == 1 else local[1],
                   sign * hb[2] if axis == 2 else local[2])
        depth = radius + least
    normal = to_world((0.0, 0.0, 0.0), rb, normal_local)
    put_contact(out_point, out_depth, 0, add_scaled(c, radius, normal), to_world(pb, rb, closest),
                depth)
    return 1, normal


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def round_ground(p, r, dims, height, margin, out_point, out_depth):
    """A sphere's lowest point, or a capsule's two ends' lowest points, within `margin` of the
    ground z = height. Returns the count (normal (0, 0, -1))."""
    axis = core_axis(r)
    count = 0
    for k in range(1 if dims[1] == 0.0 else 2):
        end = add_scaled(p, dims[1] if k == 0 else -dims[1], axis)
        gap = end[2] - dims[0] - height
        if gap <= margin:
            set_row(out_point, count, (end[0], end[1], end[2] - dims[0] - 0.5 * gap))
            out_depth[count] = -gap
            count += 1
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def capsule_triangle(p, r, dims, tri, tri_normal, edges, creases, margin, out_point, out_depth):
    """A capsule's two end spheres against a one-sided triangle (sphere_triangle each), when
    both meet its face: those two points (normal the face's), so a capsule rocking on a mesh
    floor has its free end's speculative contact as on the ground (round_ground). -1 otherwise
    (an end at an edge, or beyond the margin): the convex path decides. (It gave a tilted
    capsule one point, its lower end; the free end landed unseen, and capsules of 5-10 mm
    dropped onto a mesh floor sank through it.)"""
    axis = core_axis(r)
    count = 0
    for k in range(2):
        end = add_scaled(p, dims[1] if k == 0 else -dims[1], axis)
        found, normal = sphere_triangle(end, dims[0], tri, tri_normal, edges, creases, margin,
                                        out_point[count:], out_depth[count:])
        face = normal[0] == -tri_normal[0] and normal[1] == -tri_normal[1] and normal[2] == -tri_normal[2]
        if found == 0 or not face:
            return -1
        count += 1
    return count


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def sphere_triangle(c, radius, tri, tri_normal, edges, creases, margin, out_point, out_depth):
    """Sphere and one-sided triangle (`edges`, `creases`: its Playground.edges and crease_rows):
    (point count, normal sphere -> triangle). None when the centre is behind the plane. The
    triangle's closest point gives the contact. While the sphere is sunk at most SEAM_TOLERANCE
    below the plane the normal is the face's even when that point is on an edge, so a ball
    rolling over the seam of two coplanar triangles is not pushed back by the edge it crosses;
    the depth is then the sphere's surface straight above the edge point, and the point is the
    sphere's lowest, which stands still while it rolls (at the edge point, a rolling ball's
    surface moves down onto the next triangle, and the solver would take that for an approach
    and bump the ball up). Past a concave edge (playground.past_crease) the plane goes on: the depth is the sphere's lowest point's, however far beside, so a ball
    coming down a ramp onto a floor meets the floor's plane before it crosses it."""
    n = (tri_normal[0], tri_normal[1], tri_normal[2])
    front = dot(sub(c, tri[0]), n)
    if front <= 0.0:
        return 0, (0.0, 0.0, 0.0)
    u, v, w = triangle_weights(sub(tri[0], c), sub(tri[1], c), sub(tri[2], c))
    closest = add_scaled(add_scaled(scaled(u, tri[0]), v, tri[1]), w, tri[2])
    gap = sub(closest, c)
    distance_sq = dot(gap, gap)
    if distance_sq > (radius + margin) ** 2:
        return 0, (0.0, 0.0, 0.0)
    on = (1 if w == 0.0 else 0) | (2 if u == 0.0 else 0) | (4 if v == 0.0 else 0)  # edge j's bit
    crease = (on == 1 or on == 2 or on == 4) and past_crease(edges, creases, on >> 1, c)
    inside = u > 0.0 and v > 0.0 and w > 0.0
    if inside or crease or front - radius >= -SEAM_TOLERANCE:
        if crease:
            depth = radius - front
        else:
            beside_sq = max(distance_sq - front * front, 0.0)  # the centre's offset along the plane
            if beside_sq >= radius * radius:
                return 0, (0.0, 0.0, 0.0)
            depth = np.sqrt(radius * radius - beside_sq) - front
        if depth < -margin:
            return 0, (0.0, 0.0, 0.0)
        set_row(out_point, 0, add_scaled(c, 0.5 * depth - radius, n))
        out_depth[0] = depth
        return 1, (-n[0], -n[1], -n[2])
    distance = np.sqrt(distance_sq)
    normal = scaled(1.0 / distance, gap) if distance > 1e-12 else (-n[0], -n[1], -n[2])
    put_contact(out_point, out_depth, 0, add_scaled(c, radius, normal), closest,
                radius - distance)
    return 1, normal
