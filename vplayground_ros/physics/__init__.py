"""The ROS-free physics engine: numpy + Numba only (SPEC 4)."""
from .jit_cache import use_source_keyed_cache

use_source_keyed_cache()  # before any kernel module is imported

from .world import World  # noqa: E402

__all__ = ["World"]
