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
    """Counts the threads in Numba's compiler (its lock: a kernel's cache load or compile) and
    the times one left it."""

    def __init__(self):
        self._lock = threading.Lock()
        self.threads = 0
        self.finished = 0

    def on_start(self, _event):
        with self._lock:
            self.threads += 1

    def on_end(self, _event):
        with self._lock:
            self.threads -= 1
            self.finished += 1


_activity = CompilerActivity()
event.register("numba:compiler_lock", _activity)


def compiler_activity():
    """(threads loading or compiling kernels now, loads and compiles finished so far). A kernel
    compiles at its first call, which on a first run (or after an engine edit) takes up to
    minutes, kernel after kernel: between two of them no thread is in the compiler, so a
    finished count that moved says a compile was under way too."""
    return _activity.threads, _activity.finished
