"""The ROS-free physics engine: numpy + Numba only (SPEC 4).

Kernels are @njit(cache=True, nogil=True, no_cfunc_wrapper=True): cached (jit_cache), free of
the GIL, and without the C-callable wrapper Numba otherwise compiles beside each one (for
numba.cfunc and first-class function values, which the engine does not use), 9 % of the cold
compile (bench/compile_time.py). Kernels that only other kernels call also take
no_cpython_wrapper=True: the wrapper for calls from Python cost 7 % more. Called from Python,
such a kernel segfaults, so test_jit_cache checks that no Python code names one."""
from .jit_cache import use_source_keyed_cache

use_source_keyed_cache()  # before any kernel module is imported

from .world import World  # noqa: E402

__all__ = ["World"]
