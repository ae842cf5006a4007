"""Bodies as structure-of-arrays: one row (slot) per body, owned by the World.

A namedtuple of numpy arrays is what the compiled kernels receive; it keeps the kernels' argument
lists short and every field named. Kernels unpack the arrays they need once, outside their loops:
Numba pays reference counting for every array handed to a call, which in a per-contact loop
costs more than the physics. Slots of removed bodies are marked inactive and reused.
"""
from collections import namedtuple

import numpy as np

BodyArrays = namedtuple("BodyArrays", [
    "active",                # slot holds a body
    "position",              # (N, 3) centre of mass, world, m
    "orientation",           # (N, 4) quaternion x, y, z, w, body -> world
    "velocity",              # (N + 1, 6) linear m/s, angular rad/s (world); the extra last
                             # row is the static world (ground, mesh): always zero
    "mass",                  # (N,) kg (kept as given, so saving reproduces it exactly)
    "inv_mass",              # (N,) 1/kg
    "inv_inertia",           # (N, 3, 3) inverse inertia tensor about the centre of mass, body frame
    "shape",                 # (N,) int64 shape code (physics.shapes)
    "dimensions",            # (N, 3) the shape's numbers (physics.shapes.<shape>), m
    "half_extents",          # (N, 3) m, of the shape's bounding box in the body frame
    "elasticity",            # (N,) coefficient of restitution
    "static_friction",       # (N,)
    "dynamic_friction",      # (N,)
    "immovable",             # (N,) infinite mass, never moves
    "collides",              # (N,) touches other bodies, the ground and the playground and
                             # stops rays (else it passes through all: joints alone hold it)
    "allow_freezing",        # (N,)
    "frozen",                # (N,) not simulated, static for others
    "jointed",               # (N,) a joint holds it: it freezes and wakes with its group
    "freeze_timer",          # (N,) seconds spent below the freezing thresholds
    "static_indexed",        # (N,) the body sits in the rarely rebuilt static octree index
    "external_impulse",      # (N, 3) N*s applied at the next step, then cleared (~/push)
    "external_angular_impulse",  # (N, 3) N*m*s likewise
    # Derived each step, for the solver:
    "awake",                 # (N,) active, not frozen, not immovable: the bodies that move
    "rotation",              # (N, 3, 3) from orientation
    "solver_inv_mass",       # (N,) inv_mass of awake bodies, 0 for the others (static to all)
    "inv_inertia_world",     # (N, 3, 3) R diag(inv_inertia) R^T of awake bodies, else 0
    "pseudo_velocity",       # (N + 1, 6) split-impulse position correction, this step only
    "speculative_reach",     # (N,) m the body's surface can move in this step
    "aabb_min", "aabb_max",  # (N, 3) bounds for the broad phase, grown by the step's motion
    "octree_level",          # (N,) int64 octree level of the body's bounds
])


def allocate_bodies(capacity):
    f = lambda *shape: np.zeros((capacity,) + shape)  # noqa: E731
    b = lambda: np.zeros(capacity, dtype=np.bool_)  # noqa: E731
    orientation = f(4)
    orientation[:, 3] = 1.0
    return BodyArrays(
        active=b(), position=f(3), orientation=orientation,
        velocity=np.zeros((capacity + 1, 6)), mass=f(), inv_mass=f(), inv_inertia=f(3, 3),
        shape=np.zeros(capacity, np.int64), dimensions=f(3), half_extents=f(3),
        elasticity=f(), static_friction=f(), dynamic_friction=f(), immovable=b(),
        collides=np.ones(capacity, dtype=np.bool_),
        allow_freezing=b(), frozen=b(), jointed=b(), freeze_timer=f(), static_indexed=b(),
        external_impulse=f(3), external_angular_impulse=f(3), awake=b(), rotation=f(3, 3),
        solver_inv_mass=f(), inv_inertia_world=f(3, 3), pseudo_velocity=np.zeros((capacity + 1, 6)),
        speculative_reach=f(), aabb_min=f(3), aabb_max=f(3),
        octree_level=np.zeros(capacity, np.int64))


def grow_bodies(bodies, capacity):
    """A copy with room for `capacity` slots; existing slots keep their index."""
    grown = allocate_bodies(capacity)
    n = len(bodies.active)
    for field, old in zip(BodyArrays._fields, bodies):
        getattr(grown, field)[:n] = old[:n]  # velocity's static-world row stays last (zero)
    return grown
