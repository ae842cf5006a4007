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
together, exactly: their effective mass matrix K = J M^-1 J^T (6 rows a joint) is factored
(Cholesky) once a step, and each sweep applies K^-1 times what the rows lack. Row by row, a thin arm's
hinge drifted into a growing wobble within 2 s, a 10-link chain came apart at 10 sweeps, and a
10 kg weight on a 1 kg arm wandered off its plane: sequential impulses converge slowly across
mass ratios, and correcting the drift in full each step feeds what they leave back. Islands of
more than MAX_DIRECT_JOINTS solve each joint's block alone (6x6), one after the other.
Rows 6-8 are bounded, solved one by one after the block, each with its effective mass
through the island's equalities (what moving the axis moves: a motor turning a light link that
carries a heavy one feels the heavy one) and its change carried through them by a response
computed once a step, so one such row is exact in one sweep (the motor first, the limits after:
a limit has the last word); in the contact pass, an island no contact touches has them solved
together, as a bounded problem by active sets (solve_island_alone, bounded_solve). A row with
no effective mass (both sides static, or a limit or motor the joint does not have) is skipped.
Position errors are corrected through the real velocities in full each step (target -C/dt, a
velocity-level SHAKE): the split-impulse correction the contacts use forgets
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
# The bounded rows (counted from LOWER_ROW) in the order a sweep solves them: the motor, then the
# limits, which so have the last word (solved after it, a 300 N m motor drove a light link a
# radian past its limit).
MOTOR_FIRST = (MOTOR_ROW - LOWER_ROW, 0, UPPER_ROW - LOWER_ROW)

# A position motor closes this fraction of its error each step (at most max_speed): all of it
# would fight the other rows' sweeps and ring; a fifth settles in ~25 steps (0.2 s at 128/s).
POSITION_MOTOR_RATE = 0.2

# Islands of up to this many joints have their equality rows solved as one (a K of up to 384 x
# 384; factored within each row's envelope, a chain's costs as its neighbours' blocks); larger
# ones joint by joint, which holds chains of up to 16 joints only (a 17-link chain hanging
# still came apart: sequential blocks and full drift correction).
MAX_DIRECT_JOINTS = 64

# A pivot of K's factor this small against its diagonal is a redundant row's.
REDUNDANT_PIVOT = 1.0e-9
# The projected Gauss-Seidel sweeps over the bounded rows of an island no contact touches
# (solve_island_alone, each a few hundred multiply-adds for an arm's 7 motors; at most the
# pass's sweeps: where a motor fights a limit no answer exists, and more sweeps only push
# both harder) stop when none changed more than this (N s, N m s: another changes nothing).
SETTLED_IMPULSE = 1.0e-12
# bounded_solve changes which rows a bound holds, one at a time, at most this many times the
# rows' count in all (a chain of limited joints takes a few; 1,500 random problems of up to 12
# rows never more than 22) before the sweeps above finish what it left.
PIVOTS_PER_ROW = 3
# An island of m joints keeps (6m)^2 floats of K's factor, 3m x 6m of its bounded rows'
# responses and 3m x 2m x 6 of their velocity changes: ISLAND_FLOATS m^2 (island_floats).
ISLAND_FLOATS = 36 + 18 + 36

# A limit row is solved only while its joint is this close to it (rad or m), or closer than two
# steps at its speed: far from its limit it cannot act, and each solved row costs the island.
LIMIT_MARGIN = 0.05

# Position errors are corrected at most this fast (m/s, rad/s): a joint made between bodies far
# apart, or a body teleported by an edit, pulls them together over a few steps, not in one.
MAX_JOINT_CORRECTION_SPEED = 5.0

# The world's side of a joint to the world.
WORLD_SIDE = -1

# Columns of JointArrays.links (int64): what a joint is and holds.
KIND, BODY_A, BODY_B, MOTOR_MODE, COLLIDE_CONNECTED, VELOCITY_A, VELOCITY_B = range(7)
# Columns of JointArrays.values (float): its settings, its state, and the solver's masses.
(LOWER, UPPER, MOTOR_TARGET, FEED_FORWARD, MAX_EFFORT, MAX_SPEED, POSITION, WRAPPED_ANGLE,
 SPEED, EFFORT, INV_MASS_A, INV_MASS_B) = range(12)
# Columns of JointArrays.row_values: per row of a joint.
(ROW_MASS, COLLISION_TARGET, CONTACT_TARGET, IMPULSE_LOW, IMPULSE_HIGH, COLLISION_IMPULSE,
 IMPULSE, PASS_CHANGE) = range(8)
# JointArrays.frames[j, side]: the anchor (x, y, z) then the joint frame's quaternion.
ANCHOR, FRAME = 0, 3
# Rows of JointArrays.islands.
ISLAND_JOINTS, ISLAND_START, ISLAND_OFFSET, ISLAND_BODY_START, ISLAND_BODIES = range(5)

# A few arrays with named columns rather than one array a field: handing a tuple of arrays to
# compiled code costs ~0.25 us an array, on every World.step call, and 40 arrays of joints made
# the call of a world without any 10 us slower.
JointArrays = namedtuple("JointArrays", [
    "count",       # (2,) joints in use (rows 0..count-1, kept packed by the World), islands
    "links",       # (J, 7) int64 KIND ... VELOCITY_B: the kind (FIXED ... PRISMATIC), the body
                   # slots (parent, child; WORLD_SIDE for the world), MOTOR_*, whether the two
                   # collide, and (prepare_joints) their rows of the velocity arrays
    "frames",      # (J, 2, 7) per side (parent, child): the anchor in the body's frame from its
                   # centre of mass, then the joint's frame in the body's frame (x: the axis)
    "values",      # (J, 12) LOWER ... INV_MASS_B: limits (rad or m; -inf / inf for none), the
                   # motor's target (rad/s, m/s; rad, m), a position motor's feed-forward
                   # velocity (rad/s, m/s), max_effort (N m, N; inf: unbounded),
                   # max_speed, the coordinate (angle with turns counted, or slide), the last
                   # measured angle in (-pi, pi], its rate, the effort the motor and limits
                   # applied last step, each side's inverse mass in the solver
    # The solver's view, rebuilt each step (prepare_joints):
    "rows",        # (J, JOINT_ROWS, ROW_SIZE)
    "row_values",  # (J, JOINT_ROWS, 8) ROW_MASS (0: not solved) ... PASS_CHANGE: relative
                   # velocity goals of the two passes, the accumulated impulse's bounds, the
                   # impulses of the collision pass and of the contact pass (warm-started), and
                   # what a bounded row of an island solved whole added in this pass
    "block_inverse",  # (J, EQUALITY_ROWS, EQUALITY_ROWS) inverse effective mass of rows 0-5
    "islands",     # (5, 2 J + 1) the joints island by island (each in the order they were made),
                   # each island's first place there, where its factor starts (-1: joint by
                   # joint), its moving bodies' first place in the next row, those bodies'
                   # velocity rows
    "island_solver",    # (island_floats(...),) each island's Cholesky factor of K (n x n,
                        # row-major), its bounded rows' equality responses (3 x joints x n),
                        # and their velocity changes (3 x joints x 2 joints x 6)
    "island_residual",  # (J * EQUALITY_ROWS,) scratch of the sweeps
    "excluded_pairs",   # (E,) sorted pair_key of the jointed pairs that do not collide
])


def allocate_joints(capacity):
    frames = np.zeros((capacity, 2, 7))
    frames[:, :, FRAME + 3] = 1.0
    return JointArrays(
        count=np.zeros(2, np.int64), links=np.zeros((capacity, 7), np.int64), frames=frames,
        values=np.zeros((capacity, 12)), rows=np.zeros((capacity, JOINT_ROWS, ROW_SIZE)),
        row_values=np.zeros((capacity, JOINT_ROWS, 8)),
        block_inverse=np.zeros((capacity, EQUALITY_ROWS, EQUALITY_ROWS)),
        islands=np.zeros((5, 2 * capacity + 1), np.int64),
        island_solver=np.zeros(capacity * ISLAND_FLOATS),
        island_residual=np.zeros(capacity * EQUALITY_ROWS), excluded_pairs=np.zeros(0, np.int64))


def island_floats(group_sizes):
    """island_solver's length for joints that hold their bodies in groups of `group_sizes`
    joints (the groups of bodies joints connect, the world apart): enough for whatever islands
    a step makes of them (frozen and immovable bodies split a group; islands of m <=
    MAX_DIRECT_JOINTS joints take ISLAND_FLOATS m^2 each), ISLAND_FLOATS m min(m, MAX) a group."""
    return ISLAND_FLOATS * sum(m * min(m, MAX_DIRECT_JOINTS) for m in group_sizes)


# The arrays whose rows are joints, kept from step to step (the rest prepare_joints rebuilds).
PER_JOINT = ("links", "frames", "values", "row_values")


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
    x_a, q_a = side_pose(bodies, joints.links[j, BODY_A])
    x_b, q_b = side_pose(bodies, joints.links[j, BODY_B])
    r_a = rotate(q_a, joints.frames[j, 0, ANCHOR:ANCHOR + 3])
    r_b = rotate(q_b, joints.frames[j, 1, ANCHOR:ANCHOR + 3])
    p_a = (x_a[0] + r_a[0], x_a[1] + r_a[1], x_a[2] + r_a[2])
    p_b = (x_b[0] + r_b[0], x_b[1] + r_b[1], x_b[2] + r_b[2])
    f_a = quat_multiply(q_a, joints.frames[j, 0, FRAME:FRAME + 4])
    f_b = quat_multiply(q_b, joints.frames[j, 1, FRAME:FRAME + 4])
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
    half a revolution between two, ~400 rad/s at 128 steps/s) and its rate."""
    velocity = bodies.velocity
    static_row = len(bodies.active)
    for j in range(joints.count[0]):
        kind = joints.links[j, KIND]
        if kind == FIXED:
            joints.values[j, POSITION] = joints.values[j, SPEED] = 0.0
            continue
        a, b = joints.links[j, BODY_A], joints.links[j, BODY_B]
        row_a = a if a >= 0 else static_row
        row_b = b if b >= 0 else static_row
        p_a, p_b, arm_a, r_b, f_a, f_b, rel = joint_geometry(bodies, joints, j)
        axis = rotate(f_a, (1.0, 0.0, 0.0))
        if kind == PRISMATIC:
            joints.values[j, POSITION] = ((p_b[0] - p_a[0]) * axis[0] + (p_b[1] - p_a[1]) * axis[1]
                                  + (p_b[2] - p_a[2]) * axis[2])
            lever_a, lever_b = cross(arm_a, axis), cross(r_b, axis)
            speed = 0.0
            for e in range(3):
                speed += (axis[e] * (velocity[row_b, e] - velocity[row_a, e])
                          - lever_a[e] * velocity[row_a, 3 + e] + lever_b[e] * velocity[row_b, 3 + e])
            joints.values[j, SPEED] = speed
        else:
            angle = 2.0 * np.arctan2(rel[0], rel[3])
            joints.values[j, POSITION] += wrap_angle(angle - joints.values[j, WRAPPED_ANGLE])
            joints.values[j, WRAPPED_ANGLE] = angle
            joints.values[j, SPEED] = (axis[0] * (velocity[row_b, 3] - velocity[row_a, 3])
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
    joints.row_values[j, row, ROW_MASS] = 1.0 / k if k > 1.0e-12 else 0.0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def equality_row(joints, j, row, error, inv_dt):
    """An equality row: nothing to hold in the collision pass; the whole error in the contact
    pass (bounded)."""
    correction = min(max(-error * inv_dt, -MAX_JOINT_CORRECTION_SPEED), MAX_JOINT_CORRECTION_SPEED)
    joints.row_values[j, row, COLLISION_TARGET] = 0.0
    joints.row_values[j, row, CONTACT_TARGET] = correction
    joints.row_values[j, row, IMPULSE_LOW] = -np.inf
    joints.row_values[j, row, IMPULSE_HIGH] = np.inf


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def limit_row(joints, j, row, gap, inv_dt):
    """A one-sided row, `gap` from its limit (negative: past it): it may close the gap this step,
    no more; the contact pass also takes back what is past (bounded)."""
    joints.row_values[j, row, COLLISION_TARGET] = min(-gap * inv_dt, 0.0)
    joints.row_values[j, row, CONTACT_TARGET] = min(-gap * inv_dt, MAX_JOINT_CORRECTION_SPEED)
    joints.row_values[j, row, IMPULSE_LOW] = 0.0
    joints.row_values[j, row, IMPULSE_HIGH] = np.inf


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
        a, b, kind = joints.links[j, BODY_A], joints.links[j, BODY_B], joints.links[j, KIND]
        joints.links[j, VELOCITY_A] = a if a >= 0 else static_row
        joints.links[j, VELOCITY_B] = b if b >= 0 else static_row
        m_a = inv_mass[a] if a >= 0 else 0.0
        m_b = inv_mass[b] if b >= 0 else 0.0
        joints.values[j, INV_MASS_A], joints.values[j, INV_MASS_B] = m_a, m_b
        ia, ib = max(a, 0), max(b, 0)
        p_a, p_b, arm_a, r_b, f_a, f_b, rel = joint_geometry(bodies, joints, j)
        axis = rotate(f_a, (1.0, 0.0, 0.0))
        across = (rotate(f_a, (0.0, 1.0, 0.0)), rotate(f_a, (0.0, 0.0, 1.0)))
        separation = (p_b[0] - p_a[0], p_b[1] - p_a[1], p_b[2] - p_a[2])
        for row in range(JOINT_ROWS):
            joints.row_values[j, row, ROW_MASS] = 0.0
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
            position = joints.values[j, POSITION]
            near = LIMIT_MARGIN + 2.0 * abs(joints.values[j, SPEED]) * dt
            if kind != CONTINUOUS and position - joints.values[j, LOWER] < near:
                set_row(joints, j, LOWER_ROW, direction, lever_a, lever_b, m_a, m_b, inertia,
                        inertia, ia, ib)
                limit_row(joints, j, LOWER_ROW, position - joints.values[j, LOWER], inv_dt)
            if kind != CONTINUOUS and joints.values[j, UPPER] - position < near:
                set_row(joints, j, UPPER_ROW, flipped[0], flipped[1], flipped[2], m_a, m_b,
                        inertia, inertia, ia, ib)
                limit_row(joints, j, UPPER_ROW, joints.values[j, UPPER] - position, inv_dt)
            mode = joints.links[j, MOTOR_MODE]
            if mode != MOTOR_NONE:
                set_row(joints, j, MOTOR_ROW, direction, lever_a, lever_b, m_a, m_b, inertia,
                        inertia, ia, ib)
                if mode == MOTOR_VELOCITY:
                    goal = joints.values[j, MOTOR_TARGET]
                else:
                    # The velocity the target moves at, and a share of the way to it.
                    goal = (joints.values[j, FEED_FORWARD]
                            + POSITION_MOTOR_RATE * (joints.values[j, MOTOR_TARGET] - position) * inv_dt)
                    # The target moves on at its velocity: a trajectory's feed-forward carries
                    # it between the commands (a batch of steps between two publishes).
                    joints.values[j, MOTOR_TARGET] += joints.values[j, FEED_FORWARD] * dt
                goal = min(max(goal, -joints.values[j, MAX_SPEED]), joints.values[j, MAX_SPEED])
                joints.row_values[j, MOTOR_ROW, COLLISION_TARGET] = goal
                joints.row_values[j, MOTOR_ROW, CONTACT_TARGET] = goal
                bound = joints.values[j, MAX_EFFORT] * dt
                joints.row_values[j, MOTOR_ROW, IMPULSE_LOW] = -bound
                joints.row_values[j, MOTOR_ROW, IMPULSE_HIGH] = bound
        # A frozen joint (both sides at rest, one of them frozen) keeps its impulses: what held
        # it when it froze is its effort (a frozen arm reported 0 once anything else moved) and
        # its warm start on waking.
        frozen = m_a == 0.0 and m_b == 0.0 and ((a >= 0 and bodies.frozen[a]) or (b >= 0 and bodies.frozen[b]))
        for row in range(JOINT_ROWS):
            joints.row_values[j, row, COLLISION_IMPULSE] = 0.0
            if joints.row_values[j, row, ROW_MASS] == 0.0:
                if not frozen:
                    joints.row_values[j, row, IMPULSE] = 0.0
                joints.rows[j, row, :] = 0.0
                joints.row_values[j, row, COLLISION_TARGET] = joints.row_values[j, row, CONTACT_TARGET] = 0.0
    group_islands(joints, static_row)
    for island in range(joints.count[1]):
        if joints.islands[ISLAND_OFFSET, island] >= 0:
            factor_island(joints, island)
            bounded_responses(joints, island, static_row + 1)
        else:
            for place in range(joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]):
                invert_block(joints, joints.islands[ISLAND_JOINTS, place], work)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def invert_block(joints, j, work):
    """joints.block_inverse[j] = the inverse of joint j's equality rows' K (an island too large
    to solve whole solves each joint's block alone). A row not used gets a unit diagonal, so
    its impulse stays 0; a joint between two static sides gets all zeros."""
    for r in range(EQUALITY_ROWS):
        for c in range(EQUALITY_ROWS):
            if joints.row_values[j, r, ROW_MASS] == 0.0 or joints.row_values[j, c, ROW_MASS] == 0.0:
                work[r, c] = 1.0 if r == c else 0.0
            else:
                work[r, c] = shared_response(joints, j, r, j, c)
    if joints.values[j, INV_MASS_A] == 0.0 and joints.values[j, INV_MASS_B] == 0.0:
        joints.block_inverse[j] = 0.0
        return
    invert_in_place(work, EQUALITY_ROWS)
    for r in range(EQUALITY_ROWS):
        for c in range(EQUALITY_ROWS):
            joints.block_inverse[j, r, c] = work[r, EQUALITY_ROWS + c]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def group_islands(joints, bodies):
    """Groups the joints by the moving bodies they share (a static side, the world or a frozen
    or immovable body, joins nothing; a joint holding nothing that moves is in no island), and
    gives each island of up to MAX_DIRECT_JOINTS a place for its factor and responses."""
    count = joints.count[0]
    # Union-find over joint indices, through the moving bodies they hold.
    parent = np.arange(count)
    first_joint = np.full(bodies + 1, -1, np.int64)  # a joint holding each velocity row
    for j in range(count):
        for side in range(2):
            body = joints.links[j, VELOCITY_A] if side == 0 else joints.links[j, VELOCITY_B]
            if joints.values[j, INV_MASS_A + side] == 0.0:
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
        if joints.values[j, INV_MASS_A] == 0.0 and joints.values[j, INV_MASS_B] == 0.0:
            continue  # nothing it holds moves (frozen, immovable): no island
        root = find_root(parent, j)
        if island_of_root[root] < 0:
            island_of_root[root] = islands
            islands += 1
        sizes[island_of_root[root]] += 1
    start = joints.islands[ISLAND_START]
    start[0] = 0
    offset = 0
    for island in range(islands):
        start[island + 1] = start[island] + sizes[island]
        floats = ISLAND_FLOATS * sizes[island] ** 2
        # (The registry sizes island_solver for any islands its joints can make; were it short,
        # an island would be solved joint by joint rather than written past its end.)
        if sizes[island] <= MAX_DIRECT_JOINTS and offset + floats <= len(joints.island_solver):
            joints.islands[ISLAND_OFFSET, island] = offset
            offset += floats
        else:
            joints.islands[ISLAND_OFFSET, island] = -1
    filled = sizes  # reused: joints placed so far per island
    filled[:islands] = 0
    for j in range(count):
        island = island_of_root[find_root(parent, j)]
        if island < 0:
            continue
        joints.islands[ISLAND_JOINTS, start[island] + filled[island]] = j
        filled[island] += 1
    # Each island's moving bodies (its joints' sides that move), once each.
    body_start, island_bodies = joints.islands[ISLAND_BODY_START], joints.islands[ISLAND_BODIES]
    listed = np.full(bodies + 1, -1, np.int64)  # the island that listed each velocity row
    count_bodies = 0
    for island in range(islands):
        body_start[island] = count_bodies
        for place in range(start[island], start[island + 1]):
            j = joints.islands[ISLAND_JOINTS, place]
            for side in range(2):
                row = joints.links[j, VELOCITY_A + side]
                if joints.values[j, INV_MASS_A + side] != 0.0 and listed[row] != island:
                    listed[row] = island
                    island_bodies[count_bodies] = row
                    count_bodies += 1
    body_start[islands] = count_bodies
    joints.count[1] = islands


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def find_root(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def share_a_body(joints, j, k):
    """Whether joints j and k hold a moving body in common."""
    for side_j in range(2):
        if joints.values[j, INV_MASS_A + side_j] == 0.0:
            continue
        body = joints.links[j, VELOCITY_A + side_j]
        for side_k in range(2):
            if joints.values[k, INV_MASS_A + side_k] != 0.0 and joints.links[k, VELOCITY_A + side_k] == body:
                return True
    return False


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def shared_response(joints, j, row, k, col):
    """J_row M^-1 J_col^T between row `row` of joint j and row `col` of joint k: the velocity
    change along the one per unit impulse along the other, through the moving bodies they
    share (a side A's row enters with a minus sign: see contact.py's row layout)."""
    rows = joints.rows
    total = 0.0
    for side_j in range(2):
        mass = joints.values[j, INV_MASS_A + side_j]
        if mass == 0.0:
            continue
        body = joints.links[j, VELOCITY_A] if side_j == 0 else joints.links[j, VELOCITY_B]
        for side_k in range(2):
            other = joints.links[k, VELOCITY_A] if side_k == 0 else joints.links[k, VELOCITY_B]
            if other != body or joints.values[k, INV_MASS_A + side_k] == 0.0:
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
def factor_island(joints, island):
    """The island's K (a row a joint does not use gets a unit diagonal, so its impulse stays 0)
    factored as L L^T (Cholesky: K is symmetric positive definite) into island_solver.
    Joints that share no body have a zero block in K: row by row, L is only made from the first
    joint that shares one (the row's envelope, which Cholesky fills no further), so a chain's
    factor and solves cost as its neighbours' blocks, not the whole island's. Each row's
    envelope start is kept in the factor's unused upper triangle, row 0's (envelope_start)."""
    first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
    n = EQUALITY_ROWS * (last - first)
    factor = joints.island_solver[joints.islands[ISLAND_OFFSET, island]:]
    for p in range(last - first):
        j = joints.islands[ISLAND_JOINTS, first + p]
        start = p
        for q in range(p + 1):
            k = joints.islands[ISLAND_JOINTS, first + q]
            linked = p == q or share_a_body(joints, j, k)  # else their block of K is zero
            if linked and q < start:
                start = q
            for r in range(EQUALITY_ROWS):
                for c in range(EQUALITY_ROWS if q < p else r + 1):  # the lower triangle is what is read
                    if not linked or joints.row_values[j, r, ROW_MASS] == 0.0 or joints.row_values[k, c, ROW_MASS] == 0.0:
                        value = 1.0 if (p == q and r == c) else 0.0
                    else:
                        value = shared_response(joints, j, r, k, c)
                    factor[(EQUALITY_ROWS * p + r) * n + EQUALITY_ROWS * q + c] = value
        for r in range(EQUALITY_ROWS):
            if EQUALITY_ROWS * p + r > 0:
                factor[EQUALITY_ROWS * p + r] = EQUALITY_ROWS * start  # row 0's upper triangle
    cholesky_factor(factor, n)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def cholesky_factor(factor, n):
    """factor (n x n, row-major: a symmetric positive definite K's lower triangle, each row's
    envelope start in row 0's upper triangle, envelope_start) becomes L, K = L L^T, in place."""
    for col in range(n):
        begin_col = envelope_start(factor, col)
        original = factor[col * n + col]
        diagonal = original
        for k in range(begin_col, col):
            diagonal -= factor[col * n + k] * factor[col * n + k]
        if diagonal <= REDUNDANT_PIVOT * original:
            # A redundant row (two hinges of one door on one axis, two fixed joints between the
            # same bodies; in S, a motor and a limit of one axis): the others already hold what
            # it would. An infinite pivot makes the
            # solve give it no impulse; the rest factor as without it.
            factor[col * n + col] = np.inf
            for row in range(col + 1, n):
                if envelope_start(factor, row) <= col:
                    factor[row * n + col] = 0.0
            continue
        diagonal = np.sqrt(diagonal)
        factor[col * n + col] = diagonal
        for row in range(col + 1, n):
            begin_row = envelope_start(factor, row)
            if begin_row > col:
                continue  # outside the row's envelope: zero, and it stays so
            value = factor[row * n + col]
            for k in range(max(begin_row, begin_col), col):
                value -= factor[row * n + k] * factor[col * n + k]
            factor[row * n + col] = value / diagonal


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def envelope_start(factor, row):
    """The first column of the factor's row that is not zero (factor_island keeps it)."""
    return 0 if row == 0 else int(factor[row])


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def cholesky_solve(factor, n, x):
    """x = K^-1 x in place, K = L L^T with L in factor's lower triangle (n x n, row-major),
    each row from its envelope start: L y = x row by row, then L^T x = y column by column."""
    for row in range(n):
        value = x[row]
        for k in range(envelope_start(factor, row), row):
            value -= factor[row * n + k] * x[k]
        x[row] = value / factor[row * n + row]
    for row in range(n - 1, -1, -1):
        x[row] /= factor[row * n + row]
        value = x[row]
        for k in range(envelope_start(factor, row), row):
            x[k] -= factor[row * n + k] * value


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


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def body_changes(joints, island, p, which):
    """The velocity changes (2 m x 6, m the island's joints) of the island's moving bodies per
    unit impulse of bounded row `which` (0 lower, 1 upper, 2 motor) of its p-th joint."""
    first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
    size = last - first
    n = EQUALITY_ROWS * size
    at = joints.islands[ISLAND_OFFSET, island] + n * n + 3 * size * n + (3 * p + which) * 2 * size * 6
    return joints.island_solver[at:at + 2 * size * 6].reshape((2 * size, 6))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def add_row_change(joints, j, row, scale, change, slot_of):
    """Adds to `change` (per island body: linear, angular) what an impulse `scale` along row
    `row` of joint j does to its moving sides."""
    rows = joints.rows
    for side in range(2):
        mass = joints.values[j, INV_MASS_A + side]
        if mass == 0.0:
            continue
        body = slot_of[joints.links[j, VELOCITY_A + side]]
        sign = -scale if side == 0 else scale
        turn = TURN_A if side == 0 else TURN_B
        for e in range(3):
            change[body, e] += sign * mass * rows[j, row, DIRECTION + e]
            change[body, 3 + e] += sign * rows[j, row, turn + e]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def bounded_responses(joints, island, rows):
    """For each motor and limit row j of the island: the equality impulses w = -K^-1 u, u =
    J_eq M^-1 j^T, that keep the equalities when j's impulse changes by 1 (stored after the
    factor), the velocity change of each of the island's moving bodies that this makes with
    j's own (body_changes), and j's effective mass through them, 1 / (j M^-1 j^T + u . w).
    `rows`: the velocity arrays' length."""
    first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
    size = last - first
    n = EQUALITY_ROWS * size
    offset = joints.islands[ISLAND_OFFSET, island]
    factor = joints.island_solver[offset:]
    # Each moving body's place among the island's (for body_changes).
    slot_of = np.full(rows, -1, np.int64)
    bodies_first = joints.islands[ISLAND_BODY_START, island]
    for place in range(bodies_first, joints.islands[ISLAND_BODY_START, island + 1]):
        slot_of[joints.islands[ISLAND_BODIES, place]] = place - bodies_first
    u = np.empty(n)
    for p in range(size):
        j = joints.islands[ISLAND_JOINTS, first + p]
        for which in range(3):
            row = LOWER_ROW + which
            if joints.row_values[j, row, ROW_MASS] == 0.0:
                continue
            w = joints.island_solver[offset + n * n + (3 * p + which) * n:]
            for q in range(size):
                k = joints.islands[ISLAND_JOINTS, first + q]
                linked = k == j or share_a_body(joints, j, k)
                for c in range(EQUALITY_ROWS):
                    w[EQUALITY_ROWS * q + c] = (shared_response(joints, k, c, j, row)
                                                if linked and joints.row_values[k, c, ROW_MASS] != 0.0 else 0.0)
            response = 1.0 / joints.row_values[j, row, ROW_MASS]
            for r in range(n):
                u[r] = w[r]
            cholesky_solve(factor, n, w)
            for r in range(n):
                w[r] = -w[r]
                response += u[r] * w[r]
            if not response > 1.0e-12:  # the equalities leave it no motion: not solved
                joints.row_values[j, row, ROW_MASS] = joints.row_values[j, row, IMPULSE] = 0.0
                continue
            joints.row_values[j, row, ROW_MASS] = 1.0 / response
            # What a unit impulse of the row, with its equality responses, does to each moving
            # body of the island (its row's own sides and every equality row's).
            change = body_changes(joints, island, p, which)
            change[:] = 0.0
            add_row_change(joints, j, row, 1.0, change, slot_of)
            for q in range(size):
                k = joints.islands[ISLAND_JOINTS, first + q]
                for c in range(EQUALITY_ROWS):
                    if w[EQUALITY_ROWS * q + c] != 0.0:
                        add_row_change(joints, k, c, w[EQUALITY_ROWS * q + c], change, slot_of)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def warm_start_joints(joints, velocity):
    """Applies last step's contact-pass impulses of the rows still in use (prepare_joints)."""
    for j in range(joints.count[0]):
        a, b = joints.links[j, VELOCITY_A], joints.links[j, VELOCITY_B]
        m_a, m_b = joints.values[j, INV_MASS_A], joints.values[j, INV_MASS_B]
        for row in range(JOINT_ROWS):
            if joints.row_values[j, row, IMPULSE] != 0.0:
                apply_row_impulse(velocity, joints.rows, j, row, a, b, m_a, m_b, joints.row_values[j, row, IMPULSE])


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
def bounded_row_change(velocity, joints, target, impulse, j, row):
    """One motor or limit row: its accumulated impulse driven to the target within bounds.
    Returns the impulse it added (not yet applied to the bodies)."""
    mass = joints.row_values[j, row, ROW_MASS]
    if mass == 0.0:
        return 0.0
    a, b = joints.links[j, VELOCITY_A], joints.links[j, VELOCITY_B]
    old = impulse[j, row]
    new = old + mass * (target[j, row] - row_speed(velocity, joints.rows, j, row, a, b))
    new = min(max(new, joints.row_values[j, row, IMPULSE_LOW]), joints.row_values[j, row, IMPULSE_HIGH])
    impulse[j, row] = new
    return new - old


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_bounded_row(velocity, joints, target, impulse, j, row):
    """bounded_row_change, applied to the joint's two bodies (a joint solved alone)."""
    change = bounded_row_change(velocity, joints, target, impulse, j, row)
    if change != 0.0:
        apply_row_impulse(velocity, joints.rows, j, row, joints.links[j, VELOCITY_A],
                          joints.links[j, VELOCITY_B], joints.values[j, INV_MASS_A],
                          joints.values[j, INV_MASS_B], change)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_joint_block(velocity, joints, target, impulse, j):
    """Joint j's equality rows together: K_j^-1 times what they lack (an island too large to
    solve whole)."""
    inverse = joints.block_inverse
    if inverse[j, 0, 0] == 0.0 and inverse[j, 1, 1] == 0.0:
        return  # both sides static
    rows, a, b = joints.rows, joints.links[j, VELOCITY_A], joints.links[j, VELOCITY_B]
    m_a, m_b = joints.values[j, INV_MASS_A], joints.values[j, INV_MASS_B]
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


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def apply_island_impulses(velocity, joints, impulse, first, size, change, scale):
    """Adds scale x change[6p + r] to equality row r of the island's p-th joint."""
    for p in range(size):
        j = joints.islands[ISLAND_JOINTS, first + p]
        a, b = joints.links[j, VELOCITY_A], joints.links[j, VELOCITY_B]
        m_a, m_b = joints.values[j, INV_MASS_A], joints.values[j, INV_MASS_B]
        for row in range(EQUALITY_ROWS):
            d = scale * change[EQUALITY_ROWS * p + row]
            if d != 0.0:
                impulse[j, row] += d
                apply_row_impulse(velocity, joints.rows, j, row, a, b, m_a, m_b, d)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_island(velocity, joints, target, impulse, island, with_motors):
    """One sweep over an island solved whole: the equalities, K^-1 times what they lack (what
    the contacts changed since); then each motor and limit row, its change carried through the
    equalities by its precomputed velocity changes (so they hold as before it; the equality
    impulses that takes are booked at the pass's end, settle_island_impulses). In that order
    each bounded row's effective mass through the equalities is its true one: solved before
    them, a limit measured a speed the equalities were about to change, with a mass several
    times its own, and a 1 kg link pinned at its limit under a 1,200 kg car took energy
    from every sweep (1,359 m/s within 0.7 s)."""
    first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
    size = last - first
    solve_island_equalities(velocity, joints, target, impulse, island)
    for p in range(size):
        j = joints.islands[ISLAND_JOINTS, first + p]
        for which in MOTOR_FIRST:
            row = LOWER_ROW + which
            if row == MOTOR_ROW and not with_motors:
                continue
            change = bounded_row_change(velocity, joints, target, impulse, j, row)
            if change != 0.0:
                joints.row_values[j, row, PASS_CHANGE] += change
                moved = body_changes(joints, island, p, which)
                bodies_first = joints.islands[ISLAND_BODY_START, island]
                for place in range(bodies_first, joints.islands[ISLAND_BODY_START, island + 1]):
                    body = joints.islands[ISLAND_BODIES, place]
                    for e in range(6):
                        velocity[body, e] += change * moved[place - bodies_first, e]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_island_equalities(velocity, joints, target, impulse, island):
    """The equality rows of an island solved whole: K^-1 times what they lack."""
    first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
    size = last - first
    residual, rows = joints.island_residual, joints.rows
    for p in range(size):
        j = joints.islands[ISLAND_JOINTS, first + p]
        a, b = joints.links[j, VELOCITY_A], joints.links[j, VELOCITY_B]
        for row in range(EQUALITY_ROWS):
            residual[EQUALITY_ROWS * p + row] = target[j, row] - row_speed(velocity, rows, j, row, a, b)
    cholesky_solve(joints.island_solver[joints.islands[ISLAND_OFFSET, island]:], EQUALITY_ROWS * size, residual)
    apply_island_impulses(velocity, joints, impulse, first, size, residual, 1.0)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def solve_island_alone(velocity, joints, target, impulse, island, sweeps):
    """An island solved whole that no contact point touches, in the contact pass: what sweeps
    of solve_island reach in the limit. Its equalities are solved; then its motor and limit
    rows as a bounded problem in their own coupling through the equalities, S[i, k] = row i's
    speed change per unit impulse of row k (with the equality impulses that keep the
    equalities: body_changes), by bounded_solve, then up to `sweeps` projected Gauss-Seidel
    sweeps on S alone for what it left (motors first: a limit has the last word; a few hundred
    multiply-adds each instead of every island body's velocity a row, as solve_island's sweeps
    are); their changes are applied once through body_changes, and the equalities solved again
    for what rounding left. Sweeping the bodies, 10 sweeps of a KUKA arm took ~25 us of its
    ~80 us step and stopped short of the answer."""
    first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
    size = last - first
    bodies_first = joints.islands[ISLAND_BODY_START, island]
    bodies_end = joints.islands[ISLAND_BODY_START, island + 1]
    solve_island_equalities(velocity, joints, target, impulse, island)
    # The bounded rows in use (p, which), and each joint's sides' places among the island's
    # moving bodies (-1: static), for the rows' speeds in body_changes.
    bounded = np.empty((3 * size, 2), np.int64)
    count = 0
    place = np.full((size, 2), -1, np.int64)
    for p in range(size):
        j = joints.islands[ISLAND_JOINTS, first + p]
        for side in range(2):
            if joints.values[j, INV_MASS_A + side] != 0.0:
                for k in range(bodies_first, bodies_end):
                    if joints.islands[ISLAND_BODIES, k] == joints.links[j, VELOCITY_A + side]:
                        place[p, side] = k - bodies_first
        for which in range(3):
            if joints.row_values[j, LOWER_ROW + which, ROW_MASS] != 0.0:
                bounded[count, 0], bounded[count, 1] = p, which
                count += 1
    if count == 0:
        return
    rows = joints.rows
    coupling = np.empty((count, count))
    lacking = np.empty(count)
    for i in range(count):
        p, row = bounded[i, 0], LOWER_ROW + bounded[i, 1]
        j = joints.islands[ISLAND_JOINTS, first + p]
        lacking[i] = target[j, row] - row_speed(velocity, rows, j, row, joints.links[j, VELOCITY_A],
                                                joints.links[j, VELOCITY_B])
    for k in range(count):
        moved = body_changes(joints, island, bounded[k, 0], bounded[k, 1])
        for i in range(count):
            p, row = bounded[i, 0], LOWER_ROW + bounded[i, 1]
            j = joints.islands[ISLAND_JOINTS, first + p]
            speed = 0.0
            for side in range(2):
                at = place[p, side]
                if at < 0:
                    continue
                sign = -1.0 if side == 0 else 1.0
                arm = ARM_A if side == 0 else ARM_B
                for e in range(3):
                    speed += sign * rows[j, row, DIRECTION + e] * moved[at, e] + (
                        sign * rows[j, row, arm + e] * moved[at, 3 + e])
            coupling[i, k] = speed
    # Start from the bounded answer (bounded_solve): sweeping from zero, an arm's rows, coupled
    # across a 13:1 mass ratio, had not settled in 100 sweeps, and from the answer without
    # bounds projected onto them, a chain of limited joints had been left with the pushes that
    # balanced the pulls clipped away, and gained 90 times its energy.
    old, low, high = np.empty(count), np.empty(count), np.empty(count)
    for i in range(count):
        j, row = joints.islands[ISLAND_JOINTS, first + bounded[i, 0]], LOWER_ROW + bounded[i, 1]
        old[i] = impulse[j, row]
        low[i], high[i] = joints.row_values[j, row, IMPULSE_LOW], joints.row_values[j, row, IMPULSE_HIGH]
    change = bounded_solve(coupling, lacking, old, low, high)
    for i in range(count):
        j, row = joints.islands[ISLAND_JOINTS, first + bounded[i, 0]], LOWER_ROW + bounded[i, 1]
        impulse[j, row] = min(max(old[i] + change[i], low[i]), high[i])
        change[i] = impulse[j, row] - old[i]
    for _ in range(sweeps):
        largest = 0.0
        for turn in range(2 * count):  # MOTOR_FIRST: every motor row, then every limit row
            i = turn % count
            if (bounded[i, 1] == MOTOR_FIRST[0]) != (turn < count):
                continue
            p, row = bounded[i, 0], LOWER_ROW + bounded[i, 1]
            j = joints.islands[ISLAND_JOINTS, first + p]
            speed_change = 0.0
            for k in range(count):
                speed_change += coupling[i, k] * change[k]
            before = impulse[j, row]
            new = before + joints.row_values[j, row, ROW_MASS] * (lacking[i] - speed_change)
            new = min(max(new, low[i]), high[i])
            impulse[j, row] = new
            change[i] += new - before
            largest = max(largest, abs(new - before))
        if largest <= SETTLED_IMPULSE:
            break
    for i in range(count):
        if change[i] == 0.0:
            continue
        p, which = bounded[i, 0], bounded[i, 1]
        j = joints.islands[ISLAND_JOINTS, first + p]
        joints.row_values[j, LOWER_ROW + which, PASS_CHANGE] += change[i]
        moved = body_changes(joints, island, p, which)
        for k in range(bodies_first, bodies_end):
            body = joints.islands[ISLAND_BODIES, k]
            for e in range(6):
                velocity[body, e] += change[i] * moved[k - bodies_first, e]
    solve_island_equalities(velocity, joints, target, impulse, island)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def bounded_solve(coupling, lacking, old, low, high):
    """The changes of bounded rows' impulses (each row's accumulated impulse `old`, kept within
    [low, high]; `coupling` S: row i's speed change per unit impulse of row k) that give every
    row what it `lacking` where no bound holds it, and hold a row at a bound only where it would
    pass it: at its low bound a row has what it lacks or more, at its high bound less (the
    box-bounded complementarity problem). By active sets: the rows no bound holds are solved
    exactly (S's factor over them; a row that depends on earlier ones gets nothing, as in
    factor_island), then the worst row on the wrong side of its bound, or held by a bound it
    pulls away from, changes set, one at a time, at most PIVOTS_PER_ROW times the rows' count
    in all (the sweeps that follow finish what that leaves: an unbounded motor and a limit of
    one axis that disagree have no answer)."""
    n = len(lacking)
    state = np.zeros(n, np.int64)  # -1: held at low, 1: held at high, 0: free
    change = np.zeros(n)
    free = np.empty(n, np.int64)
    factor = np.empty(n * n)
    for _ in range(PIVOTS_PER_ROW * n + 1):
        m = 0
        for i in range(n):
            if state[i] < 0:
                change[i] = low[i] - old[i]
            elif state[i] > 0:
                change[i] = high[i] - old[i]
            else:
                free[m] = i
                m += 1
        rhs = np.empty(m)
        for k in range(m * m):  # every row's envelope from column 0 (row 0's upper triangle)
            factor[k] = 0.0
        for a in range(m):
            i = free[a]
            value = lacking[i]
            for k in range(n):
                if state[k] != 0:
                    value -= coupling[i, k] * change[k]
            rhs[a] = value
            for b in range(a + 1):
                factor[a * m + b] = coupling[i, free[b]]
        if m > 0:
            cholesky_factor(factor, m)
            cholesky_solve(factor, m, rhs)
        for a in range(m):
            change[free[a]] = rhs[a]
        worst, worst_row, worst_state = SETTLED_IMPULSE, -1, 0
        for i in range(n):
            if coupling[i, i] <= 0.0:
                continue
            lacks = lacking[i]
            for k in range(n):
                lacks -= coupling[i, k] * change[k]
            wants = lacks / coupling[i, i]  # the impulse the row still lacks
            if state[i] == 0:
                below, above = low[i] - (old[i] + change[i]), old[i] + change[i] - high[i]
                if below > worst:
                    worst, worst_row, worst_state = below, i, -1
                if above > worst:
                    worst, worst_row, worst_state = above, i, 1
                # Solved, a row lacks nothing but rounding, unless it depends on the rows before
                # it and wants otherwise (a motor pushing a joint against its limit): then it
                # pushes as hard as it may, and the others answer that.
                if abs(wants) > 1e-9 * abs(old[i] + change[i]) + worst:
                    bound = high[i] if wants > 0.0 else low[i]
                    if np.isfinite(bound):
                        worst, worst_row, worst_state = abs(wants), i, (1 if wants > 0.0 else -1)
            elif -state[i] * wants > worst:  # what it lacks takes it off its bound
                worst, worst_row, worst_state = -state[i] * wants, i, 0
        if worst_row < 0:
            break
        state[worst_row] = worst_state
    return change


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def settle_island_impulses(joints, impulse):
    """Books the equality impulses the bounded rows of islands solved whole took this pass
    (their changes times their responses), for the warm start and the efforts."""
    for island in range(joints.count[1]):
        offset = joints.islands[ISLAND_OFFSET, island]
        if offset < 0:
            continue
        first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
        size = last - first
        n = EQUALITY_ROWS * size
        for p in range(size):
            j = joints.islands[ISLAND_JOINTS, first + p]
            for which in range(3):
                change = joints.row_values[j, LOWER_ROW + which, PASS_CHANGE]
                if change == 0.0:
                    continue
                joints.row_values[j, LOWER_ROW + which, PASS_CHANGE] = 0.0
                response = joints.island_solver[offset + n * n + (3 * p + which) * n:]
                for q in range(size):
                    k = joints.islands[ISLAND_JOINTS, first + q]
                    for c in range(EQUALITY_ROWS):
                        impulse[k, c] += change * response[EQUALITY_ROWS * q + c]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def islands_touched(joints, velocity_a, velocity_b, points, count, rows):
    """Which islands a contact point of points[:count] touches (a moving body of one of its
    joints is a side of the point); `rows` is the velocity arrays' length."""
    touched_row = np.zeros(rows, np.bool_)
    for k in range(count):
        touched_row[velocity_a[points[k]]] = True
        touched_row[velocity_b[points[k]]] = True
    touched = np.zeros(joints.count[1], np.bool_)
    for island in range(joints.count[1]):
        for place in range(joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]):
            j = joints.islands[ISLAND_JOINTS, place]
            if ((joints.values[j, INV_MASS_A] != 0.0 and touched_row[joints.links[j, VELOCITY_A]])
                    or (joints.values[j, INV_MASS_B] != 0.0 and touched_row[joints.links[j, VELOCITY_B]])):
                touched[island] = True
    return touched


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, inline="always")
def solve_joint_sweep(velocity, joints, target, impulse, backwards, with_motors, selected):
    """One sweep over the joints' rows of the `selected` islands, island by island (backwards:
    the last first); the motors only `with_motors` (the contact pass: in the collision pass too,
    a motor would apply its effort twice a step). An island solved whole: solve_island. A larger
    one: joint by joint, the motor and limits, then the joint's equality block (what matters
    most last)."""
    islands = joints.count[1]
    for step in range(islands):
        island = islands - 1 - step if backwards else step
        if not selected[island]:
            continue
        first, last = joints.islands[ISLAND_START, island], joints.islands[ISLAND_START, island + 1]
        if joints.islands[ISLAND_OFFSET, island] >= 0:
            solve_island(velocity, joints, target, impulse, island, with_motors)
        else:
            for p in range(first, last):
                j = joints.islands[ISLAND_JOINTS, last - 1 - (p - first) if backwards else p]
                for which in MOTOR_FIRST:
                    if LOWER_ROW + which != MOTOR_ROW or with_motors:
                        solve_bounded_row(velocity, joints, target, impulse, j, LOWER_ROW + which)
                solve_joint_block(velocity, joints, target, impulse, j)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def solve_islands_alone(velocity, joints, target, impulse, touched, sweeps):
    """The contact pass's islands no point touched: those solved whole at once
    (solve_island_alone). Returns which are left to sweep joint by joint."""
    left = np.zeros(joints.count[1], np.bool_)
    for island in range(joints.count[1]):
        if touched[island]:
            continue
        if joints.islands[ISLAND_OFFSET, island] >= 0:
            solve_island_alone(velocity, joints, target, impulse, island, sweeps)
        else:
            left[island] = True
    return left


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def record_effort(joints, dt):
    """What the motor and limits applied along each joint's axis this step (N m or N)."""
    for j in range(joints.count[0]):
        impulse = joints.row_values[j, :, IMPULSE]
        joints.values[j, EFFORT] = (impulse[MOTOR_ROW] + impulse[LOWER_ROW] - impulse[UPPER_ROW]) / dt


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
