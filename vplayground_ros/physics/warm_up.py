"""The engine's first compile: a small world that does everything a world does (`warm_up`), and
the shares of it that helper processes compile beside it (`SHARES`, jit_cache.compile_shares).

Numba compiles the step's whole call tree at its first call, one kernel after another on one
core (~2.5 minutes on this machine). A kernel already in the cache is not compiled again: its caller
loads it and links it in. So the shares compile the largest stages the step calls, with the
argument types the step hands them, each in a process of its own, and the warm-up then compiles
the step itself around them. A share whose argument types differ from the step's only compiles
in vain: the step then compiles that stage itself, as it would without shares.
"""
import numpy as np
from numba import typeof

from .contact_solver import (collision_pass, collision_pass_with_joints, contact_pass,
                             contact_pass_with_joints, prepare_contacts)
from .joints import prepare_joints
from .pipeline import detect
from .vehicle import drive_vehicles

# The shares, the first for the process filling the cache, each other for a helper of its own;
# balanced by their compile times (~55 s each on one of this machine's 2 cores).
SHARES = (f"{__name__}:compile_solver_and_wheels", f"{__name__}:compile_detection_and_queries")


def warm_up_world():
    """A world of every shape on the ground and on a playground, a car and each kind of joint
    with limits and both motors (the joint rows compile with the step)."""
    from .world import World  # (world.py fills the cache with this module's warm_up)
    world = World(capacity=8)
    world.set_playground(np.array([[-4.0, -4.0, 0.0], [4.0, -4.0, 0.0], [4.0, 4.0, 0.5],
                                   [-4.0, 4.0, 0.5]]), np.array([[0, 1, 2], [0, 2, 3]]))
    cube = [[x, y, z] for x in (-0.2, 0.2) for y in (-0.2, 0.2) for z in (-0.2, 0.2)]
    dumbbell = [{"shape": "sphere", "radius": 0.2, "position": [0.0, 0.0, 0.0]},
                {"shape": "convex", "points": cube, "position": [0.5, 0.0, 0.0], "rpy": [0.0, 0.0, 0.3]}]
    for k, shape in enumerate(({"size": [0.5, 0.5, 0.5]}, {"shape": "sphere", "radius": 0.3},
                               {"shape": "capsule", "radius": 0.2, "length": 0.5},
                               {"shape": "cylinder", "radius": 0.3, "length": 0.4},
                               {"shape": "convex", "points": cube}, {"shape": "compound", "parts": dumbbell})):
        world.add_body({**shape, "position": [1.2 * k - 2.4, 0.0, 1.0 + 0.3 * k]})
    world.add_vehicle({"name": "car", "position": [0.0, 2.5, 1.0],
                       "chassis": {"size": [2.0, 1.0, 0.4], "mass": 400.0},
                       "wheels": [{"mount": [x, y, -0.2], "radius": 0.25}
                                  for x in (0.7, -0.7) for y in (0.5, -0.5)]})
    names = world.body_names()
    world.add_joint({"type": "revolute", "parent": names[0], "child": names[1], "axis": [0, 1, 0],
                     "lower": -1.0, "upper": 1.0, "motor": {"mode": "position", "max_effort": 10.0}})
    world.add_joint({"type": "prismatic", "child": names[2], "lower": -0.5,
                     "motor": {"mode": "velocity", "target": 0.1}})
    world.add_joint({"type": "fixed", "parent": names[3], "child": names[4]})
    world.add_joint({"type": "continuous", "parent": names[4], "child": names[0]})
    return world


def warm_up():
    """Compiles (or loads) the kernels of everything a world does (jit_cache.compile_once): a
    step of the warm-up world (the step's whole call tree compiles at its first call), ray
    casts, contacts, the octree's cells, joints and state."""
    world = warm_up_world()
    world.step(8)
    query(world)


def query(world):
    """What is asked of a world between steps."""
    world.joint(world.joint_names()[0])
    world.cast_rays(np.zeros((2, 3)), np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]), 10.0)
    world.contacts()
    world.octree_cells()
    world.state()


def step_context(world):
    """`world`'s StepContext, as step_world gets it, and its contact buffers."""
    world.step(0)  # fits the octree's root; steps nothing
    ctx = world.step_context(np.zeros(5, np.int64))
    return ctx, ctx.contacts.pair[0]


def types_of(*arguments):
    """The Numba types of `arguments`: the signature a kernel compiles for (kernel.compile)."""
    return tuple(typeof(a) for a in arguments)


def compile_solver_and_wheels():
    """The contact solver's stages (pipeline.step_world steps 4 and 6), with joints and without,
    and the cars' wheels (step 5)."""
    ctx, contacts = step_context(warm_up_world())
    bodies, joints, s = ctx.bodies, ctx.joints, ctx.settings
    drive_vehicles.compile(types_of(ctx.vehicles, bodies, ctx.hulls, ctx.parts, ctx.broad, ctx.playground, s))
    prepare_contacts.compile(types_of(contacts, bodies, s.ground_material, s.gravity, s.dt))
    prepare_joints.compile(types_of(joints, bodies, s.dt))
    # The collision pass takes the scene's iterations, the contact pass twice as many: one type.
    with_joints = types_of(contacts, joints, bodies, s.resolve_iterations, s.gravity, s.solver_threads)
    collision_pass_with_joints.compile(with_joints)
    contact_pass_with_joints.compile(with_joints)
    without_joints = types_of(contacts, bodies, s.resolve_iterations, s.gravity, s.solver_threads)
    collision_pass.compile(without_joints)
    contact_pass.compile(without_joints)


def compile_detection_and_queries():
    """Collision detection (step_world step 2), then what worlds are asked between steps (their
    own kernels, called from Python)."""
    world = warm_up_world()
    ctx, contacts = step_context(world)
    live = ctx.broad.moving_ids[:1]  # list_live_bodies' result: a view of these
    detect.compile(types_of(ctx.bodies, ctx.hulls, ctx.parts, ctx.broad, ctx.playground, contacts,
                            ctx.settings, live, ctx.joints.excluded_pairs))
    query(world)
