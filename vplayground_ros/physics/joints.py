"""Joints: constraints holding two bodies (or a body and the world) together, as rows the
solver's passes run beside the contact points (contact_solver), the way Box2D v3 solves its
contact and joint blocks in one set of stages.

A joint has a frame in each body (an anchor and an orientation, fixed to the body; they coincide
in the world when the joint is made) whose x axis is the joint's axis. Its rows, each in the
contacts' row layout (contact.DIRECTION ... TURN_B):

- rows 0-2, the anchors: the three world axes (fixed, revolute, continuous), or the two axes
  across the joint's axis (prismatic: it slides along the axis);
- rows 3-5, the relative rotation: the three world axes (fixed, prismatic), or the two axes
  across the joint's axis (revolute, continuous: they turn about it);
- rows 6 and 7, the lower and upper limits along the axis (one-sided, like a contact's normal:
  speculative, so a joint approaching its limit stops at it instead of passing it);
- row 8, the motor along the axis: a velocity, or a position reached at a bounded speed, with
  its impulse bounded by max_effort x dt.

Rows 0-5 are equalities. The joints an island of bodies shares (a robot) have theirs solved
together, exactly: their effective mass matrix K = J M^-1 J^T (6 rows a joint) is inverted
once a step, and each sweep applies K^-1 times what the rows lack. Row by row, a thin arm's
hinge drifted into a growing wobble within 2 s, a 10-link chain came apart at 10 sweeps, and a
10 kg weight on a 1 kg arm wandered off its plane: sequential impulses converge slowly across
mass ratios, and correcting the drift in full each step feeds what they leave back. Islands of
more than MAX_DIRECT_JOINTS solve each joint's block alone (6x6), one after the other.
Rows 6-8 are bounded, solved one by one before the block, each with its effective mass
through the island's equalities (what moving the axis moves: a motor turning a light link that
carries a heavy one feels the heavy one), then the island's equalities are solved again, so
one such row is exact in one sweep. A row with no effective mass
(both sides static, or a limit or motor the joint does not have) is skipped. Position errors are corrected through the real velocities in full each step
(target -C/dt, a velocity-level SHAKE): the split-impulse correction the contacts use forgets
the centripetal share of a swing, and a pendulum corrected so lost ~1 % of its energy a
minute; corrected in full, a 1 m pendulum at 128 steps/s keeps it to 0.01 %.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .contact import ARM_A, ARM_B, DIRECTION, ROW_SIZE, TURN_A, TURN_B
from .math3d import cross, quat_conjugate, quat_multiply, rotate

FIXED, REVOLUTE, CONTINUOUS, PRISMATIC = 0, 1, 2, 3
KINDS = {"fixed": FIXED, "revolute": REVOLUTE, "continuous": CONTINUOUS, "prismatic": PRISMATIC}
MOTOR_NONE, MOTOR_VELOCITY, MOTOR_POSITION = 0, 1, 2
MOTORS = {"none": MOTOR_NONE, "velocity": MOTOR_VELOCITY, "position": MOTOR_POSITION}

# Row slots of a joint (see the module's docstring).
ANCHOR_ROW, TURN_ROW, LOWER_ROW, UPPER_ROW, MOTOR_ROW = 0, 3, 6, 7, 8
EQUALITY_ROWS, JOINT_ROWS = 6, 9

# A position motor closes this fraction of its error each step (at most max_speed): all of it
# would fight the other rows' sweeps and ring; a fifth settles in ~25 steps (0.2 s at 128/s).
POSITION_MOTOR_RATE = 0.2

# Islands of up to this many joints have their equality rows solved as one (a K of up to 96 x 96,
# ~0.3 ms to invert); larger ones joint by joint.
MAX_DIRECT_JOINTS = 16

# Position errors are corrected at most this fast (m/s, rad/s): a joint made between bodies far
# apart, or a body teleported by an edit, pulls them together over a few steps, not in one.
MAX_JOINT_CORRECTION_SPEED = 5.0

# The world's side of a joint to the world.
WORLD_SIDE = -1

JointArrays = namedtuple("JointArrays", [
    "count",            # (1,) joints in use, rows 0..count-1 (the World keeps them packed)
    "kind",             # (J,) int64 FIXED ... PRISMATIC
    "body_a", "body_b",  # (J,) int64 slots (the parent, the child); WORLD_SIDE for the world
    "anchor_a", "anchor_b",  # (J, 3) the anchor in each body's frame, from its centre of mass
    "frame_a", "frame_b",    # (J, 4) the joint's frame in each body's frame (x: the axis)
    "lower", "upper",   # (J,) limits along the axis (rad or m); -inf / inf for none
    "motor_mode",       # (J,) int64 MOTOR_*
    "motor_target",     # (J,) rad/s or m/s (velocity), rad or m (position)
    "max_effort",       # (J,) N m or N the motor may apply (inf: as much as it takes)
    "max_speed",        # (J,) rad/s or m/s a position motor may move at (inf: no bound)
    "collide_connected",  # (J,) the two bodies collide with each other
    "position",         # (J,) the joint's coordinate: angle (turns counted) or slide
    "wrapped_angle",    # (J,) last measured angle in (-pi, pi], for counting turns
    "speed",            # (J,) the coordinate's rate, rad/s or m/s
    "effort",           # (J,) N m or N the motor and limits applied along the axis last step
    # The solver's view, rebuilt each step (prepare_joints):
    "velocity_a", "velocity_b",  # (J,) rows of the velocity arrays (the static world's last row)
    "row_inv_mass",     # (J, 2)
    "rows",             # (J, JOINT_ROWS, ROW_SIZE)
    "row_mass",         # (J, JOINT_ROWS) 0 for a row not solved
    "block_inverse",    # (J, EQUALITY_ROWS, EQUALITY_ROWS) inverse effective mass of rows 0-5
    # Islands (prepare_joints): the joints grouped by the bodies they share.
    "island_count",     # (1,)
    "island_joints",    # (J,) joints, island by island, each in the order they were made
    "island_start",     # (J + 1,) each island's first place in island_joints
    "island_offset",    # (J,) where each island's K^-1 starts in island_inverse; -1: joint by joint
    "island_inverse",   # (J * EQUALITY_ROWS * EQUALITY_ROWS * MAX_DIRECT_JOINTS,) K^-1s, row-major
    "island_residual",  # (J * EQUALITY_ROWS,) scratch of the sweeps
    "collision_target", "contact_target",  # (J, JOINT_ROWS) relative velocity goals
    "impulse_low", "impulse_high",  # (J, JOINT_ROWS) bounds of each row's accumulated impulse
    "collision_impulse",  # (J, JOINT_ROWS) accumulated in the collision pass
    "impulse",          # (J, JOINT_ROWS) accumulated in the contact pass (warm-started)
    "excluded_pairs",   # (E,) sorted pair_key of the jointed pairs that do not collide
])


def allocate_joints(capacity):
    f = lambda *shape: np.zeros((capacity,) + shape)  # noqa: E731
    i = lambda: np.zeros(capacity, np.int64)  # noqa: E731
    identity = f(4)
    identity[:, 3] = 1.0
    return JointArrays(
        count=np.zeros(1, np.int64), kind=i(), body_a=i(), body_b=i(), anchor_a=f(3),
        anchor_b=f(3), frame_a=identity.copy(), frame_b=identity.copy(), lower=f(), upper=f(),
        motor_mode=i(), motor_target=f(), max_effort=f(), max_speed=f(),
        collide_connected=np.zeros(capacity, np.bool_), position=f(), wrapped_angle=f(),
        speed=f(), effort=f(), velocity_a=i(), velocity_b=i(), row_inv_mass=f(2),
        rows=f(JOINT_ROWS, ROW_SIZE), row_mass=f(JOINT_ROWS),
        block_inverse=f(EQUALITY_ROWS, EQUALITY_ROWS), island_count=np.zeros(1, np.int64),
        island_joints=i(), island_start=np.zeros(capacity + 1, np.int64), island_offset=i(),
        island_inverse=np.zeros(capacity * EQUALITY_ROWS * EQUALITY_ROWS * MAX_DIRECT_JOINTS),
        island_residual=np.zeros(capacity * EQUALITY_ROWS), collision_target=f(JOINT_ROWS),
        contact_target=f(JOINT_ROWS), impulse_low=f(JOINT_ROWS), impulse_high=f(JOINT_ROWS),
        collision_impulse=f(JOINT_ROWS), impulse=f(JOINT_ROWS),
        excluded_pairs=np.zeros(0, np.int64))


# The fields that hold each joint from step to step (the rest prepare_joints rebuilds).
PERSISTENT = ("kind", "body_a", "body_b", "anchor_a", "anchor_b", "frame_a", "frame_b", "lower",
              "upper", "motor_mode", "motor_target", "max_effort", "max_speed",
              "collide_connected", "position", "wrapped_angle", "speed", "effort", "impulse")


def pair_key(a, b):
    """The key of an unordered pair of body slots (the same in Python and compiled code)."""
    return (min(a, b) << 32) | max(a, b)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def side_pose(bodies, body):
    """Centre of mass and orientation of one side of a joint (the world: the origin, unturned)."""
    if body < 0:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)
    p, q = bodies.position[body], bodies.orientation[body]
    return (p[0], p[1], p[2]), (q[0], q[1], q[2], q[3])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def joint_geometry(bodies, joints, j):
    """The joint's world anchors, arms, frames and coordinate: (anchor A, anchor B, arm A (from
    A's centre to B's anchor), arm B, frame A, frame B, relative rotation of B's frame in A's,
    w >= 0), all tuples."""
    x_a, q_a = side_pose(bodies, joints.body_a[j])
    x_b, q_b = side_pose(bodies, joints.body_b[j])
    r_a = rotate(q_a, joints.anchor_a[j])
    r_b = rotate(q_b, joints.anchor_b[j])
    p_a = (x_a[0] + r_a[0], x_a[1] + r_a[1], x_a[2] + r_a[2])
    p_b = (x_b[0] + r_b[0], x_b[1] + r_b[1], x_b[2] + r_b[2])
    f_a = quat_multiply(q_a, joints.frame_a[j])
    f_b = quat_multiply(q_b, joints.frame_b[j])
    rel = quat_multiply(quat_conjugate(f_a), f_b)
    if rel[3] < 0.0:
        rel = (-rel[0], -rel[1], -rel[2], -rel[3])
    # The prismatic's rows act at B's anchor on both bodies: A's arm reaches it.
    arm_a = (p_b[0] - x_a[0], p_b[1] - x_a[1], p_b[2] - x_a[2])
    return p_a, p_b, arm_a, r_b, f_a, f_b, rel


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def wrap_angle(angle):
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)
def measure_joints(bodies, joints):
    """Each joint's coordinate (turns counted from the last measurement: a joint must not turn
    half a revolution between two, ~100 rad/s at 128 steps/s) and its rate."""
    velocity = bodies.velocity
    static_row = len(bodies.active)
    for j in range(joints.count[0]):
        kind = joints.kind[j]
        if kind == FIXED:
            joints.position[j] = joints.speed[j] = 0.0
            continue
        a, b = joints.body_a[j], joints.body_b[j]
        row_a = a if a >= 0 else static_row
        row_b = b if b >= 0 else static_row
        p_a, p_b, arm_a, r_b, f_a, f_b, rel = joint_geometry(bodies, joints, j)
        axis = rotate(f_a, (1.0, 0.0, 0.0))
        if kind == PRISMATIC:
            joints.position[j] = ((p_b[0] - p_a[0]) * axis[0] + (p_b[1] - p_a[1]) * axis[1]
                                  + (p_b[2] - p_a[2]) * axis[2])
            lever_a, lever_b = cross(arm_a, axis), cross(r_b, axis)
            speed = 0.0
            for e in range(3):
                speed += (axis[e] * (velocity[row_b, e] - velocity[row_a, e])
                          - lever_a[e] * velocity[row_a, 3 + e] + lever_b[e] * velocity[row_b, 3 + e])
            joints.speed[j] = speed
        else:
            angle = 2.0 * np.arctan2(rel[0], rel[3])
            joints.position[j] += wrap_angle(angle - joints.wrapped_angle[j])
            joints.wrapped_angle[j] = angle
            joints.speed[j] = (axis[0] * (velocity[row_b, 3] - velocity[row_a, 3])
                               + axis[1] * (velocity[row_b, 4] - velocity[row_a, 4])
                               + axis[2] * (velocity[row_b, 5] - velocity[row_a, 5]))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def set_row(joints, j, row, direction, arm_a, arm_b, m_a, m_b, inertia_a, inertia_b, a, b):
    """Row `row` of joint j along `direction` (linear part) with lever arms arm_a, arm_b (the
    angular parts), and its effective mass."""
    rows = joints.rows
    k = (m_a + m_b) * (direction[0] * direction[0] + direction[1] * direction[1]
                       + direction[2] * direction[2])
    for e in range(3):
        turn_a = (inertia_a[a, e, 0] * arm_a[0] + inertia_a[a, e, 1] * arm_a[1]
                  + inertia_a[a, e, 2] * arm_a[2]) if m_a != 0.0 else 0.0
        turn_b = (inertia_b[b, e, 0] * arm_b[0] + inertia_b[b, e, 1] * arm_b[1]
                  + inertia_b[b, e, 2] * arm_b[2]) if m_b != 0.0 else 0.0
        rows[j, row, DIRECTION + e] = direction[e]
        rows[j, row, ARM_A + e], rows[j, row, ARM_B + e] = arm_a[e], arm_b[e]
        rows[j, row, TURN_A + e], rows[j, row, TURN_B + e] = turn_a, turn_b
        k += arm_a[e] * turn_a + arm_b[e] * turn_b
    joints.row_mass[j, row] = 1.0 / k if k > 1.0e-12 else 0.0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def equality_row(joints, j, row, error, inv_dt):
    """An equality row: nothing to hold in the collision pass; the whole error in the contact
    pass (bounded)."""
    correction = min(max(-error * inv_dt, -MAX_JOINT_CORRECTION_SPEED), MAX_JOINT_CORRECTION_SPEED)
    joints.collision_target[j, row] = 0.0
    joints.contact_target[j, row] = correction
    joints.impulse_low[j, row] = -np.inf
    joints.impulse_high[j, row] = np.inf


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def limit_row(joints, j, row, gap, inv_dt):
    """A one-sided row, `gap` from its limit (negative: past it): it may close the gap this step,
    no more; the contact pass also takes back what is past (bounded)."""
    joints.collision_target[j, row] = min(-gap * inv_dt, 0.0)
    joints.contact_target[j, row] = min(-gap * inv_dt, MAX_JOINT_CORRECTION_SPEED)
    joints.impulse_low[j, row] = 0.0
    joints.impulse_high[j, row] = np.inf


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def prepare_joints(joints, bodies, dt):
    """Rows, effective masses, targets and bounds of every joint for this step, from the
    bodies' current poses (update_bodies' solver masses: a frozen or immovable side is static).
    Rows a joint does not have get no mass; impulses of rows that come and go are dropped."""
    measure_joints(bodies, joints)
    static_row = len(bodies.active)
    inv_dt = 1.0 / dt
    inv_mass, inertia = bodies.solver_inv_mass, bodies.inv_inertia_world
    zero = (0.0, 0.0, 0.0)
    work = np.empty((EQUALITY_ROWS, 2 * EQUALITY_ROWS))
    for j in range(joints.count[0]):
        a, b, kind = joints.body_a[j], joints.body_b[j], joints.kind[j]
        joints.velocity_a[j] = a if a >= 0 else static_row
        joints.velocity_b[j] = b if b >= 0 else static_row
        m_a = inv_mass[a] if a >= 0 else 0.0
        m_b = inv_mass[b] if b >= 0 else 0.0
        joints.row_inv_mass[j, 0], joints.row_inv_mass[j, 1] = m_a, m_b
        ia, ib = max(a, 0), max(b, 0)
        p_a, p_b, arm_a, r_b, f_a, f_b, rel = joint_geometry(bodies, joints, j)
        axis = rotate(f_a, (1.0, 0.0, 0.0))
        across = (rotate(f_a, (0.0, 1.0, 0.0)), rotate(f_a, (0.0, 0.0, 1.0)))
        separation = (p_b[0] - p_a[0], p_b[1] - p_a[1], p_b[2] - p_a[2])
        for row in range(JOINT_ROWS):
            joints.row_mass[j, row] = 0.0
        # Rows 0-2: the anchors.
        if kind == PRISMATIC:
            for k in range(2):
                n = across[k]
                set_row(joints, j, ANCHOR_ROW + k, n, cross(arm_a, n), cross(r_b, n), m_a, m_b,
                        inertia, inertia, ia, ib)
                equality_row(joints, j, ANCHOR_ROW + k,
                             separation[0] * n[0] + separation[1] * n[1] + separation[2] * n[2],
                             inv_dt)
        else:
            x_a, _ = side_pose(bodies, a)
            r_a = (p_a[0] - x_a[0], p_a[1] - x_a[1], p_a[2] - x_a[2])
            for k in range(3):
                n = (1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0)
                set_row(joints, j, ANCHOR_ROW + k, n, cross(r_a, n), cross(r_b, n), m_a, m_b,
                        inertia, inertia, ia, ib)
                equality_row(joints, j, ANCHOR_ROW + k, separation[k], inv_dt)
        # Rows 3-5: the relative rotation.
        if kind == FIXED or kind == PRISMATIC:
            # B's frame turned from A's by the rotation vector of rel (in A's frame), in the world.
            sine = np.sqrt(rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2])
            scale = 2.0 * np.arctan2(sine, rel[3]) / sine if sine > 1.0e-12 else 2.0
            turn = rotate(f_a, (rel[0] * scale, rel[1] * scale, rel[2] * scale))
            for k in range(3):
                u = (1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0)
                set_row(joints, j, TURN_ROW + k, zero, u, u, m_a, m_b, inertia, inertia, ia, ib)
                equality_row(joints, j, TURN_ROW + k, turn[k], inv_dt)
        else:
            tilt = cross(axis, rotate(f_b, (1.0, 0.0, 0.0)))
            for k in range(2):
                u = across[k]
                set_row(joints, j, TURN_ROW + k, zero, u, u, m_a, m_b, inertia, inertia, ia, ib)
                equality_row(joints, j, TURN_ROW + k, tilt[0] * u[0] + tilt[1] * u[1] + tilt[2] * u[2],
                             inv_dt)
        # Rows 6-8 along the axis: limits and motor.
        if kind != FIXED:
            if kind == PRISMATIC:
                direction, lever_a, lever_b = axis, cross(arm_a, axis), cross(r_b, axis)
            else:
                direction, lever_a, lever_b = zero, axis, axis
            flipped = ((-direction[0], -direction[1], -direction[2]),
                       (-lever_a[0], -lever_a[1], -lever_a[2]), (-lever_b[0], -lever_b[1], -lever_b[2]))
            position = joints.position[j]
            if kind != CONTINUOUS and joints.lower[j] > -np.inf:
                set_row(joints, j, LOWER_ROW, direction, lever_a, lever_b, m_a, m_b, inertia,
                        inertia, ia, ib)
                limit_row(joints, j, LOWER_ROW, position - joints.lower[j], inv_dt)
            if kind != CONTINUOUS and joints.upper[j] < np.inf:
                set_row(joints, j, UPPER_ROW, flipped[0], flipped[1], flipped[2], m_a, m_b,
                        inertia, inertia, ia, ib)
                limit_row(joints, j, UPPER_ROW, joints.upper[j] - position, inv_dt)
            mode = joints.motor_mode[j]
            if mode != MOTOR_NONE:
                set_row(joints, j, MOTOR_ROW, direction, lever_a, lever_b, m_a, m_b, inertia,
                        inertia, ia, ib)
                if mode == MOTOR_VELOCITY:
                    goal = joints.motor_target[j]
                else:
                    goal = POSITION_MOTOR_RATE * (joints.motor_target[j] - position) * inv_dt
                goal = min(max(goal, -joints.max_speed[j]), joints.max_speed[j])
                joints.collision_target[j, MOTOR_ROW] = goal
                joints.contact_target[j, MOTOR_ROW] = goal
                bound = joints.max_effort[j] * dt
                joints.impulse_low[j, MOTOR_ROW] = -bound
                joints.impulse_high[j, MOTOR_ROW] = bound
        for row in range(JOINT_ROWS):
            joints.collision_impulse[j, row] = 0.0
            if joints.row_mass[j, row] == 0.0:
                joints.impulse[j, row] = 0.0
                joints.rows[j, row, :] = 0.0
                joints.collision_target[j, row] = joints.contact_target[j, row] = 0.0
        invert_block(joints, j, work)
    group_islands(joints, static_row)
    for island in range(joints.island_count[0]):
        if joints.island_offset[island] >= 0:
            invert_island(joints, island)
            constrain_bounded_rows(joints, island)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def invert_block(joints, j, work):
    """joints.block_inverse[j] = the inverse of joint j's equality rows' K (an island too large
    to solve whole solves each joint's block alone). A row not used gets a unit diagonal, so
    its impulse stays 0; a joint between two static sides gets all zeros."""
    for r in range(EQUALITY_ROWS):
        for c in range(EQUALITY_ROWS):
            if joints.row_mass[j, r] == 0.0 or joints.row_mass[j, c] == 0.0:
                work[r, c] = 1.0 if r == c else 0.0
            else:
                work[r, c] = shared_response(joints, j, r, j, c)
    if joints.row_inv_mass[j, 0] == 0.0 and joints.row_inv_mass[j, 1] == 0.0:
        joints.block_inverse[j] = 0.0
        return
    invert_in_place(work, EQUALITY_ROWS)
    for r in range(EQUALITY_ROWS):
        for c in range(EQUALITY_ROWS):
            joints.block_inverse[j, r, c] = work[r, EQUALITY_ROWS + c]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def group_islands(joints, bodies):
    """Groups the joints by the moving bodies they share (a static side, the world or a frozen
    or immovable body, joins nothing), and gives each island of up to MAX_DIRECT_JOINTS a
    place for its K^-1."""
    count = joints.count[0]
    # Union-find over joint indices, through the moving bodies they hold.
    parent = np.arange(count)
    first_joint = np.full(bodies + 1, -1, np.int64)  # a joint holding each velocity row
    for j in range(count):
        for side in range(2):
            body = joints.velocity_a[j] if side == 0 else joints.velocity_b[j]
            if joints.row_inv_mass[j, side] == 0.0:
                continue
            if first_joint[body] >= 0:
                root_a, root_b = find_root(parent, j), find_root(parent, first_joint[body])
                parent[max(root_a, root_b)] = min(root_a, root_b)
            else:
                first_joint[body] = j
    # Islands numbered by their first joint; joints in order within each.
    island_of_root = np.full(count, -1, np.int64)
    sizes = np.zeros(count, np.int64)
    islands = 0
    for j in range(count):
        root = find_root(parent, j)
        if island_of_root[root] < 0:
            island_of_root[root] = islands
            islands += 1
        sizes[island_of_root[root]] += 1
    start = joints.island_start
    start[0] = 0
    offset = 0
    for island in range(islands):
        start[island + 1] = start[island] + sizes[island]
        if sizes[island] <= MAX_DIRECT_JOINTS:
            joints.island_offset[island] = offset
            offset += (EQUALITY_ROWS * sizes[island]) ** 2
        else:
            joints.island_offset[island] = -1
    filled = sizes  # reused: joints placed so far per island
    filled[:islands] = 0
    for j in range(count):
        island = island_of_root[find_root(parent, j)]
        joints.island_joints[start[island] + filled[island]] = j
        filled[island] += 1
    joints.island_count[0] = islands


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def find_root(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def shared_response(joints, j, row, k, col):
    """J_row M^-1 J_col^T between row `row` of joint j and row `col` of joint k: the velocity
    change along the one per unit impulse along the other, through the moving bodies they
    share (a side A's row enters with a minus sign: see contact.py's row layout)."""
    rows = joints.rows
    total = 0.0
    for side_j in range(2):
        mass = joints.row_inv_mass[j, side_j]
        if mass == 0.0:
            continue
        body = joints.velocity_a[j] if side_j == 0 else joints.velocity_b[j]
        for side_k in range(2):
            other = joints.velocity_a[k] if side_k == 0 else joints.velocity_b[k]
            if other != body or joints.row_inv_mass[k, side_k] == 0.0:
                continue
            arm = ARM_A if side_j == 0 else ARM_B
            turn = TURN_A if side_k == 0 else TURN_B
            value = 0.0
            for e in range(3):
                value += (mass * rows[j, row, DIRECTION + e] * rows[k, col, DIRECTION + e]
                          + rows[j, row, arm + e] * rows[k, col, turn + e])
            total += value if side_j == side_k else -value
    return total


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def invert_island(joints, island):
    """The island's K^-1 into island_inverse (Gauss-Jordan with partial pivoting). A row a
    joint does not use gets a unit diagonal, so its impulse stays 0."""
    first, last = joints.island_start[island], joints.island_start[island + 1]
    n = EQUALITY_ROWS * (last - first)
    work = np.empty((n, 2 * n))
    for p in range(last - first):
        j = joints.island_joints[first + p]
        for r in range(EQUALITY_ROWS):
            for q in range(last - first):
                k = joints.island_joints[first + q]
                for c in range(EQUALITY_ROWS):
                    if joints.row_mass[j, r] == 0.0 or joints.row_mass[k, c] == 0.0:
                        value = 1.0 if (p == q and r == c) else 0.0
                    else:
                        value = shared_response(joints, j, r, k, c)
                    work[EQUALITY_ROWS * p + r, EQUALITY_ROWS * q + c] = value
    invert_in_place(work, n)
    offset = joints.island_offset[island]
    for r in range(n):
        for c in range(n):
            joints.island_inverse[offset + r * n + c] = work[r, n + c]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def invert_in_place(work, n):
    """work = [A | .] (n x 2n): its right half becomes A^-1 (Gauss-Jordan, partial pivoting;
    all zeros for a singular A)."""
    for r in range(n):
        for c in range(n):
            work[r, n + c] = 1.0 if r == c else 0.0
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(work[r, col]) > abs(work[pivot, col]):
                pivot = r
        if abs(work[pivot, col]) < 1.0e-14:
            work[:, n:] = 0.0
            return
        if pivot != col:
            for c in range(2 * n):
                work[col, c], work[pivot, c] = work[pivot, c], work[col, c]
        scale = 1.0 / work[col, col]
        for c in range(2 * n):
            work[col, c] *= scale
        for r in range(n):
            if r != col and work[r, col] != 0.0:
                factor = work[r, col]
                for c in range(2 * n):
                    work[r, c] -= factor * work[col, c]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def constrain_bounded_rows(joints, island):
    """The effective mass of each motor and limit row of the island through its equalities:
    1 / (j M^-1 j^T - u^T K^-1 u), u = J_eq M^-1 j^T."""
    first, last = joints.island_start[island], joints.island_start[island + 1]
    n = EQUALITY_ROWS * (last - first)
    offset = joints.island_offset[island]
    u = np.empty(n)
    for p in range(last - first):
        j = joints.island_joints[first + p]
        for row in (LOWER_ROW, UPPER_ROW, MOTOR_ROW):
            if joints.row_mass[j, row] == 0.0:
                continue
            for q in range(last - first):
                k = joints.island_joints[first + q]
                for c in range(EQUALITY_ROWS):
                    u[EQUALITY_ROWS * q + c] = (shared_response(joints, k, c, j, row)
                                                if joints.row_mass[k, c] != 0.0 else 0.0)
            response = 1.0 / joints.row_mass[j, row]
            for r in range(n):
                if u[r] == 0.0:
                    continue
                for c in range(n):
                    response -= u[r] * joints.island_inverse[offset + r * n + c] * u[c]
            joints.row_mass[j, row] = 1.0 / response if response > 1.0e-12 else 0.0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def warm_start_joints(joints, velocity):
    """Applies last step's contact-pass impulses of the rows still in use (prepare_joints)."""
    for j in range(joints.count[0]):
        a, b = joints.velocity_a[j], joints.velocity_b[j]
        m_a, m_b = joints.row_inv_mass[j, 0], joints.row_inv_mass[j, 1]
        for row in range(JOINT_ROWS):
            if joints.impulse[j, row] != 0.0:
                apply_row_impulse(velocity, joints.rows, j, row, a, b, m_a, m_b, joints.impulse[j, row])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def apply_row_impulse(velocity, rows, j, row, a, b, m_a, m_b, d):
    """Impulse d along row `row` of joint j: -d on side A, +d on side B (static sides untouched)."""
    for e in range(3):
        if m_a != 0.0:
            velocity[a, e] -= m_a * d * rows[j, row, DIRECTION + e]
            velocity[a, 3 + e] -= d * rows[j, row, TURN_A + e]
        if m_b != 0.0:
            velocity[b, e] += m_b * d * rows[j, row, DIRECTION + e]
            velocity[b, 3 + e] += d * rows[j, row, TURN_B + e]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def row_speed(velocity, rows, j, row, a, b):
    """The relative velocity along row `row` of joint j (contact.py's row layout)."""
    v = 0.0
    for e in range(3):
        v += (rows[j, row, DIRECTION + e] * (velocity[b, e] - velocity[a, e])
              - rows[j, row, ARM_A + e] * velocity[a, 3 + e] + rows[j, row, ARM_B + e] * velocity[b, 3 + e])
    return v


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_bounded_row(velocity, joints, target, impulse, j, row):
    """One motor or limit row: its accumulated impulse driven to the target within bounds.
    Returns the impulse it added."""
    mass = joints.row_mass[j, row]
    if mass == 0.0:
        return 0.0
    a, b = joints.velocity_a[j], joints.velocity_b[j]
    old = impulse[j, row]
    new = old + mass * (target[j, row] - row_speed(velocity, joints.rows, j, row, a, b))
    new = min(max(new, joints.impulse_low[j, row]), joints.impulse_high[j, row])
    impulse[j, row] = new
    apply_row_impulse(velocity, joints.rows, j, row, a, b, joints.row_inv_mass[j, 0],
                      joints.row_inv_mass[j, 1], new - old)
    return new - old


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_joint_block(velocity, joints, target, impulse, j):
    """Joint j's equality rows together: K_j^-1 times what they lack (an island too large to
    solve whole)."""
    inverse = joints.block_inverse
    if inverse[j, 0, 0] == 0.0 and inverse[j, 1, 1] == 0.0:
        return  # both sides static
    rows, a, b = joints.rows, joints.velocity_a[j], joints.velocity_b[j]
    m_a, m_b = joints.row_inv_mass[j, 0], joints.row_inv_mass[j, 1]
    e0 = target[j, 0] - row_speed(velocity, rows, j, 0, a, b)
    e1 = target[j, 1] - row_speed(velocity, rows, j, 1, a, b)
    e2 = target[j, 2] - row_speed(velocity, rows, j, 2, a, b)
    e3 = target[j, 3] - row_speed(velocity, rows, j, 3, a, b)
    e4 = target[j, 4] - row_speed(velocity, rows, j, 4, a, b)
    e5 = target[j, 5] - row_speed(velocity, rows, j, 5, a, b)
    for row in range(EQUALITY_ROWS):
        m = inverse[j, row]
        d = m[0] * e0 + m[1] * e1 + m[2] * e2 + m[3] * e3 + m[4] * e4 + m[5] * e5
        impulse[j, row] += d
        apply_row_impulse(velocity, rows, j, row, a, b, m_a, m_b, d)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def solve_island_equalities(velocity, joints, target, impulse, island):
    """Every equality row of the island at once: K^-1 times what they lack (exact)."""
    first, last = joints.island_start[island], joints.island_start[island + 1]
    n = EQUALITY_ROWS * (last - first)
    offset, residual, rows = joints.island_offset[island], joints.island_residual, joints.rows
    for p in range(last - first):
        j = joints.island_joints[first + p]
        a, b = joints.velocity_a[j], joints.velocity_b[j]
        for row in range(EQUALITY_ROWS):
            residual[EQUALITY_ROWS * p + row] = target[j, row] - row_speed(velocity, rows, j, row, a, b)
    for p in range(last - first):
        j = joints.island_joints[first + p]
        a, b = joints.velocity_a[j], joints.velocity_b[j]
        m_a, m_b = joints.row_inv_mass[j, 0], joints.row_inv_mass[j, 1]
        for row in range(EQUALITY_ROWS):
            at = offset + (EQUALITY_ROWS * p + row) * n
            d = 0.0
            for c in range(n):
                d += joints.island_inverse[at + c] * residual[c]
            impulse[j, row] += d
            apply_row_impulse(velocity, rows, j, row, a, b, m_a, m_b, d)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_joint_sweep(velocity, joints, target, impulse, backwards, with_motors):
    """One sweep over the joints' rows, island by island (backwards: the last first); the motors
    only `with_motors` (the contact pass: in the collision pass too, a motor would apply its
    effort twice a step). An island
    solved whole: each motor and limit row that changes, then its equalities again; then its
    equalities (what the contacts since the last sweep changed). A larger one: joint by joint,
    the motor and limits, then the joint's equality block (what matters most last)."""
    islands = joints.island_count[0]
    for step in range(islands):
        island = islands - 1 - step if backwards else step
        first, last = joints.island_start[island], joints.island_start[island + 1]
        if joints.island_offset[island] >= 0:
            for p in range(first, last):
                j = joints.island_joints[p]
                for row in (MOTOR_ROW, LOWER_ROW, UPPER_ROW):
                    if row == MOTOR_ROW and not with_motors:
                        continue
                    if solve_bounded_row(velocity, joints, target, impulse, j, row) != 0.0:
                        solve_island_equalities(velocity, joints, target, impulse, island)
            solve_island_equalities(velocity, joints, target, impulse, island)
        else:
            for p in range(first, last):
                j = joints.island_joints[last - 1 - (p - first) if backwards else p]
                for row in (MOTOR_ROW, LOWER_ROW, UPPER_ROW):
                    if row != MOTOR_ROW or with_motors:
                        solve_bounded_row(velocity, joints, target, impulse, j, row)
                solve_joint_block(velocity, joints, target, impulse, j)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def record_effort(joints, dt):
    """What the motor and limits applied along each joint's axis this step (N m or N)."""
    for j in range(joints.count[0]):
        impulse = joints.impulse[j]
        joints.effort[j] = (impulse[MOTOR_ROW] + impulse[LOWER_ROW] - impulse[UPPER_ROW]) / dt


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def drop_jointed_pairs(pair_a, pair_b, count, excluded):
    """Removes the broad phase's pairs of bodies a joint holds together (and does not let
    collide) from pair_a/pair_b[:count]; returns how many pairs remain."""
    kept = 0
    for k in range(count):
        a, b = pair_a[k], pair_b[k]
        key = (min(a, b) << 32) | max(a, b)
        at = np.searchsorted(excluded, key)
        if at < len(excluded) and excluded[at] == key:
            continue
        pair_a[kept], pair_b[kept] = a, b
        kept += 1
    return kept
