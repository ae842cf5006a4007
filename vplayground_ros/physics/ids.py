"""What the negative numbers in contact and ray results mean, in one place.

A contact's `body_b` and a ray's `hit` are a body slot (>= 0), or one of the static world's
codes below. Warm-start keys and octree query stamps need ids of their own too: each playground
triangle is its own manifold, and every wheel ray of a step its own query.
"""
from numba import njit

GROUND = -1        # the ground plane
PLAYGROUND = -2    # the playground mesh (any triangle)
NOTHING = -3       # a ray that hits nothing


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def triangle_key(triangle):
    """The warm-start key of playground triangle `triangle` (a manifold each): below NOTHING."""
    return -3 - triangle


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def wheel_query(vehicle, wheel, wheels):
    """The octree query stamp of one wheel's ray in a step (unique per wheel, below every other
    id; the stamps are reset each step)."""
    return -10 - wheels * vehicle - wheel
