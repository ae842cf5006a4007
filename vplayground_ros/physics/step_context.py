"""Everything one compiled call of the step works on, bundled as Box2D's b2StepContext is: the
stages take the context (or the parts of it they need) instead of long argument lists.

The contact buffers are a pair: each step fills one from the other (the warm start reads the
older), then `newest` names the one it filled. The World reads contacts through newest_contacts.
Only what the warm start reads needs two copies; the solver's per-step fields (STEP_SCRATCH) are
one set of arrays that both buffers share.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .contact import allocate_contacts

Settings = namedtuple("Settings", [
    "gravity", "dt", "resolve_iterations", "octree_depth",
    "freezing_enabled", "freezing_time", "freezing_linear_speed", "freezing_angular_speed",
    "ground_enabled", "ground_height", "ground_material",  # (elasticity, static, dynamic)
    "root_min", "root_size",  # the octree's root cube
    "solver_threads",  # threads the contact solve may use (World.solver_threads)
])

ContactBuffers = namedtuple("ContactBuffers", [
    "pair",    # (Contacts, Contacts)
    "newest",  # (1,) int64: which of pair the newest step filled
])

StepContext = namedtuple("StepContext", [
    "bodies", "hulls", "parts", "playground", "vehicles", "broad", "contacts",  # ContactBuffers
    "joints",    # joints.JointArrays
    "settings",
    "stats",     # (STAT_*,) int64 counters summed over the steps (the caller zeroes them)
    "stage_ns",  # (len(STAGES),) int64 CPU ns per stage, summed while `profile`
    "profile",
])


# Contacts fields a step rebuilds from its own points before reading them (rows, masses,
# targets, the sweep and support orders, the passes' own accumulators); the step before is read
# only for its impulses, friction vectors, manifolds and points (warm_start_from). One set serves
# both buffers: 584 bytes a point of capacity (16 a body of capacity: 93 MB at 10,000), the
# same results bit for bit. Read between steps, they are the newest step's. (The step's time did
# not change measurably: the loose pile's landing, in-process A/B of 6-8 runs, quiet or with the
# other core streaming memory.)
STEP_SCRATCH = (
    "velocity_a", "velocity_b", "rows", "row_inv_mass", "row_mass", "restitution",
    "friction_coefficient", "approach_speed", "collision_impulse", "collision_friction", "friction",
    "position_impulse", "collision_target", "contact_target", "position_target", "solve_order",
    "sweep_points", "support_order", "support_body", "support_mass", "support_friction")


def allocate_contact_buffers(points, manifolds):
    first = allocate_contacts(points, manifolds)
    second = allocate_contacts(points, manifolds)._replace(**{f: getattr(first, f) for f in STEP_SCRATCH})
    return ContactBuffers((first, second), np.zeros(1, np.int64))


def newest_contacts(buffers):
    return buffers.pair[buffers.newest[0]]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def swap_contacts(buffers):
    """The buffer just filled becomes the newest; the other is the next step's to fill."""
    buffers.newest[0] = 1 - buffers.newest[0]


def kernel_settings(settings, ground, default_ground, root, solver_threads=1):
    """The World's validated settings (SPEC 3) as the kernels take them."""
    s, g = settings, ground
    m = g or default_ground
    root_min, root_size = root
    freezing = s["freezing"]
    return Settings(
        gravity=np.asarray(s["gravity"], dtype=np.float64),
        dt=1.0 / s["steps_per_second"],
        resolve_iterations=int(s["resolve_iterations"]),
        octree_depth=int(s["octree_depth"]),
        freezing_enabled=bool(freezing["enabled"]),
        freezing_time=float(freezing["time"]),
        freezing_linear_speed=float(freezing["linear_speed"]),
        freezing_angular_speed=float(freezing["angular_speed"]),
        ground_enabled=g is not None,
        ground_height=float(g["height"]) if g else 0.0,
        # The playground is made of the ground's material (the defaults without a ground).
        ground_material=(float(m["elasticity"]), float(m["static_friction"]),
                         float(m["dynamic_friction"])),
        root_min=np.asarray(root_min, dtype=np.float64),
        root_size=float(root_size),
        solver_threads=int(solver_threads),
    )
