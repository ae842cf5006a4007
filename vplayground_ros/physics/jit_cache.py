"""Where compiled kernels are cached.

Numba invalidates a cached kernel only when the file defining it changes, not when a kernel it
calls (in another file) does, and would then run stale machine code. Keying the cache directory
on a hash of every engine source makes any edit recompile everything once, and an unchanged
engine start warm (SPEC 8: start to first pose under 5 s).
"""
import hashlib
import os
import threading
from pathlib import Path

import numba
from numba.core import event


def use_source_keyed_cache():
    engine = Path(__file__).parent
    sources = sorted(engine.rglob("*.py"))  # the shapes/ package too
    digest = hashlib.sha256(b"".join(str(p.relative_to(engine)).encode() + p.read_bytes() for p in sources))
    base = os.environ.get("VPLAYGROUND_JIT_CACHE") or Path.home() / ".cache" / "vplayground_ros" / "numba"
    numba.config.CACHE_DIR = str(Path(base) / digest.hexdigest()[:16])


class CompilerActivity(event.Listener):
    """Counts the threads in Numba's compiler (its lock: a kernel's cache load or compile)."""

    def __init__(self):
        self._lock = threading.Lock()
        self.threads = 0

    def on_start(self, _event):
        with self._lock:
            self.threads += 1

    def on_end(self, _event):
        with self._lock:
            self.threads -= 1


_activity = CompilerActivity()
event.register("numba:compiler_lock", _activity)


def compiling():
    """Whether a thread is loading or compiling kernels now: a kernel's first call does, which
    on a first run (or after an engine edit) takes up to minutes."""
    return _activity.threads > 0
