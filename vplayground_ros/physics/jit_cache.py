"""Where compiled kernels are cached, and how a cache is filled.

Numba invalidates a cached kernel only when the file defining it changes, not when a kernel it
calls (in another file) does, and would then run stale machine code. Keying the cache directory
on a hash of every engine source makes any edit recompile everything once, and an unchanged
engine start warm (SPEC 8: start to first pose under 5 s).

A cache is filled by one process, start to end (`compile_once`). Numba names compiled code
after a per-process counter, and a kernel cached by one process may refer to its callees by
those names: a cache that one process began and another finished (the first interrupted during
the first compile, minutes long) once held a step that segfaulted in every later process, until
the directory was deleted (Numba issues #10128, #10486 describe the same names across
processes). So the first World of a process whose cache is not marked complete takes a lock on
it, clears what an interrupted process left, compiles the step and the other entry points in
one go (`warm_up`), and marks it complete; other processes wait for the lock, then load.

Every engine edit, version or checkout path makes a new directory (~15 MB): each process that
finds its cache complete marks it used (the marker's time), and a process that has just filled
a new one removes the directories beside it unused for KEEP_UNUSED_DAYS, always keeping the
KEEP_NEWEST most recently used (a developer's 44 directories had grown to 661 MB).
"""
import hashlib
import logging
import os
import re
import shutil
import sys
import threading
import time
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: no lock between processes
    fcntl = None

import numba
from numba.core import event


def use_source_keyed_cache():
    base = os.environ.get("VPLAYGROUND_JIT_CACHE") or Path.home() / ".cache" / "vplayground_ros" / "numba"
    numba.config.CACHE_DIR = str(source_keyed_directory(Path(__file__).parent, Path(base)))


def source_keyed_directory(engine, base):
    """The cache directory under `base` of the engine whose sources are in `engine`: keyed on
    every source, Numba's and Python's versions (a cache marked complete holds one compiler's
    code), and where the engine lies. Numba files a kernel under a hash of its source file's
    full path, so two copies of one engine (two checkouts, a colcon install beside its source)
    sharing a directory shared its complete marker but not the kernels: the second copy then
    compiled kernel by kernel, in whichever processes came first. (The path as Numba takes it:
    absolute, symbolic links kept.)"""
    engine = Path(os.path.abspath(engine))
    sources = sorted(engine.rglob("*.py"))  # the shapes/ package too
    digest = hashlib.sha256(f"{numba.__version__} {sys.version} {engine}".encode()
                            + b"".join(str(p.relative_to(engine)).encode() + p.read_bytes() for p in sources))
    return base / digest.hexdigest()[:16]


# The file in a complete cache directory (compile_once wrote it after a whole warm-up); its
# modification time is when a process last found the directory complete.
COMPLETE_MARKER = "complete"
KEEP_NEWEST = 4          # cache directories kept whatever their age (other checkouts, versions)
KEEP_UNUSED_DAYS = 14    # ... and the others kept while used this recently


def cache_directory():
    return Path(numba.config.CACHE_DIR)


class CompilerActivity(event.Listener):
    """Counts the threads in Numba's compiler (its lock: a kernel's cache load or compile), or
    waiting for another process to fill the cache (compile_once), and the times one left."""

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


_compile_lock = threading.Lock()
_warming = threading.local()
_uncacheable = set()  # cache directories that could not be created or locked (said once)
_marked = set()       # cache directories this process marked used
CACHE_NAME = re.compile(r"[0-9a-f]{16}")  # source_keyed_directory's names
_log = logging.getLogger(__name__)


def compile_once(warm_up):
    """Makes sure the cache directory is complete before this process steps a world: if it is
    not marked so, under an exclusive lock on it (other processes wait, counted as compiler
    activity), empties it and runs `warm_up` (which compiles the kernels it calls), then marks
    it complete. Worlds that `warm_up` itself builds pass straight through."""
    directory = cache_directory()
    if getattr(_warming, "active", False) or directory in _uncacheable:
        return
    if (directory / COMPLETE_MARKER).exists():
        mark_used(directory)
        return
    with _compile_lock:
        _activity.on_start(None)
        try:
            try:
                directory.mkdir(parents=True, exist_ok=True)
                lock = open(directory.parent / f"{directory.name}.lock", "w")
            except OSError as error:  # left to Numba: its own cache locations, or memory
                _log.warning(f"cannot cache the engine's kernels in {directory}: {error}")
                _uncacheable.add(directory)
                return
            with lock:
                if fcntl is not None:
                    try:
                        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    except BlockingIOError:
                        _log.warning(f"waiting for another process compiling the engine into {directory}")
                        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
                if (directory / COMPLETE_MARKER).exists():  # another process filled it meanwhile
                    return
                _log.warning(f"compiling the engine once into {directory} (about 2 minutes on "
                             f"2 cores); later starts load it in about a second")
                # What an interrupted process left; also what this one compiled before its first
                # World (kernels called directly): those load or compile later, as before.
                for entry in directory.rglob("*"):
                    if entry.is_file():
                        entry.unlink()
                _warming.active = True
                try:
                    warm_up()
                finally:
                    _warming.active = False
                (directory / COMPLETE_MARKER).touch()
            prune(directory.parent, keep=directory)
        finally:
            _activity.on_end(None)


def mark_used(directory):
    """Once a process: the marker's time says the directory is in use (prune keeps it)."""
    if directory in _marked:
        return
    _marked.add(directory)
    try:
        os.utime(directory / COMPLETE_MARKER)
    except OSError:  # read-only, or removed meanwhile: only pruning is less informed
        pass


def prune(base, keep, now=None):
    """Removes the cache directories in `base` (other than `keep`) last used more than
    KEEP_UNUSED_DAYS ago, beyond the KEEP_NEWEST most recently used; a directory never marked
    complete counts from its own time (an interrupted fill). Returns the names removed."""
    now = time.time() if now is None else now
    entries = []
    for entry in base.iterdir() if base.is_dir() else ():
        if entry == keep or not entry.is_dir() or not CACHE_NAME.fullmatch(entry.name):
            continue
        marker = entry / COMPLETE_MARKER
        try:
            entries.append(((marker if marker.exists() else entry).stat().st_mtime, entry))
        except OSError:
            continue
    entries.sort(reverse=True)
    removed = []
    for used, entry in entries[max(KEEP_NEWEST - 1, 0):]:  # `keep` is one of the newest
        if now - used > KEEP_UNUSED_DAYS * 86400:
            shutil.rmtree(entry, ignore_errors=True)
            (base / f"{entry.name}.lock").unlink(missing_ok=True)
            removed.append(entry.name)
    if removed:
        _log.info(f"removed {len(removed)} engine caches unused for {KEEP_UNUSED_DAYS} days from {base}")
    return removed


def compiler_activity():
    """(threads loading or compiling kernels now, loads and compiles finished so far). A kernel
    compiles at its first call, which on a first run (or after an engine edit) takes up to
    minutes, kernel after kernel: between two of them no thread is in the compiler, so a
    finished count that moved says a compile was under way too."""
    return _activity.threads, _activity.finished
