"""Where compiled kernels are cached, and how a cache is filled.

Numba invalidates a cached kernel only when the file defining it changes, not when a kernel it
calls (in another file) does, and would then run stale machine code. Keying the cache directory
on a hash of every engine source makes any edit recompile everything once, and an unchanged
engine start warm (SPEC 8: start to first pose under 5 s).

A cache is filled under one process's lock, start to end (`compile_once`): the first World of
a process whose cache is not marked complete takes a lock on it, clears what an interrupted
process left, compiles the step and the other entry points (`warm_up`), and marks it complete;
other processes wait for the lock, then load. Where there are cores to spare, helper processes
compile shares of the step's call tree meanwhile (`shares`: kernels the step calls, compiled
into the cache before the warm-up links them in from there).

Two things make kernels that several processes compiled safe to load into one (`share_safely`,
installed with the cache directory). Numba names compiled code after a per-process counter, so
two processes could give one name to different code (two specialisations of one kernel), and
the loader binds every use of a name to its first definition: a cache that one process began
and another finished once held a step that segfaulted in every later process, until the
directory was deleted (Numba issues #10128, #10486). The counter here starts at a random 62-bit
number in each process, as PyTensor does. And Numba picks a new entry's file name in a kernel's
index as the first unused one, unlocked: two processes adding two specialisations of one
kernel at once could both take the first, and one index entry would then name the other's
code. Index updates here hold a lock file beside the index.

Every engine edit, version or checkout path makes a new directory (~15 MB): each process that
finds its cache complete marks it used (the marker's time), and a process that has just filled
a new one removes the directories beside it unused for KEEP_UNUSED_DAYS, always keeping the
KEEP_NEWEST most recently used (a developer's 44 directories had grown to 661 MB).
"""
import hashlib
import importlib
import itertools
import logging
import os
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: no lock between processes
    fcntl = None

import numba
from numba.core import caching, event
from numba.core.bytecode import FunctionIdentity
from numba.core.registry import cpu_target


def use_source_keyed_cache():
    base = os.environ.get("VPLAYGROUND_JIT_CACHE") or Path.home() / ".cache" / "vplayground_ros" / "numba"
    numba.config.CACHE_DIR = str(source_keyed_directory(Path(__file__).parent, Path(base)))
    share_safely()


# What share_safely found: whether kernels compiled by several processes may fill one cache.
_sharing = {"safe": False}
INDEX_LOCK = "index.lock"  # beside kernels' indexes: held while one is updated


def share_safely():
    """Makes the kernels several processes compile safe to load into one (see the module's
    note): this process's compiled names numbered from a random start, and Numba's index
    updates locked against other processes. Only where Numba has the counter and the index
    class this expects and the locks exist (else the cache is filled by one process alone);
    once a process."""
    if _sharing["safe"] or fcntl is None:
        return
    save = getattr(caching.IndexDataCacheFile, "save", None)
    if not isinstance(getattr(FunctionIdentity, "_unique_ids", None), itertools.count) or save is None:
        return
    FunctionIdentity._unique_ids = itertools.count(int.from_bytes(os.urandom(8), "little") >> 2)

    def locked_save(index, key, data):
        # The lock beside the index (where Numba keeps it: this cache directory, or __pycache__
        # beside a source when that cannot be written); none where none can be taken there.
        try:
            lock = open(os.path.join(index._cache_path, INDEX_LOCK), "a")
        except (AttributeError, OSError, TypeError):
            return save(index, key, data)
        with lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
            except OSError:  # a file system without locks
                pass
            return save(index, key, data)
    caching.IndexDataCacheFile.save = locked_save
    _sharing["safe"] = True


def source_keyed_directory(engine, base):
    """The cache directory under `base` of the engine whose sources are in `engine`: keyed on
    every source, Numba's and Python's versions and the CPU the code is compiled for (a cache
    marked complete holds one compiler's code for one target), and where the engine lies.
    Numba files a kernel under a hash of its source file's full path, so two copies of one
    engine (two checkouts, a colcon install beside its source) sharing a directory shared its
    complete marker but not the kernels: the second copy then compiled kernel by kernel, in
    whichever processes came first. Numba keys each kernel on its target too (CPU name and
    features, NUMBA_CPU_NAME's or the host's), so a home directory shared by two kinds of CPU,
    or a process with NUMBA_CPU_NAME set, likewise found the marker and compiled everything
    again kernel by kernel, unlocked. (The path as Numba takes it: absolute, symbolic links
    kept.)"""
    engine = Path(os.path.abspath(engine))
    sources = sorted(engine.rglob("*.py"))  # the shapes/ package too
    target = cpu_target.target_context.codegen().magic_tuple()  # (triple, CPU name, features)
    digest = hashlib.sha256(f"{numba.__version__} {sys.version} {target} {engine}".encode()
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


def compile_once(warm_up, shares=()):
    """Makes sure the cache directory is complete before this process steps a world: if it is
    not marked so, under an exclusive lock on it (other processes wait, counted as compiler
    activity), empties it and runs `warm_up` (which compiles the kernels it calls), then marks
    it complete. Worlds that `warm_up` itself builds pass straight through.

    `shares`: "module:function" names of functions that compile parts of what `warm_up` needs
    (shares of the step's call tree), run first: the first here, the others in helper processes
    beside it, as many as there are cores to spare (share_processes); `warm_up` then finds
    their kernels in the cache. A share that fails only leaves its kernels to the warm-up."""
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
                processes = share_processes(shares)
                _log.warning(f"compiling the engine once into {directory} ({processes} process"
                             f"{'es' if processes > 1 else ''}; about 1.5 minutes in two on 2 cores, "
                             f"2.5 in one); later starts load it in about a second")
                # What an interrupted process left; also what this one compiled before its first
                # World (kernels called directly): those load or compile later, as before.
                for entry in directory.rglob("*"):
                    if entry.is_file() and entry.name != INDEX_LOCK:  # (another process may hold it)
                        entry.unlink()
                _warming.active = True
                try:
                    compile_shares(shares, processes)
                    warm_up()
                finally:
                    _warming.active = False
                (directory / COMPLETE_MARKER).touch()
            prune(directory.parent, keep=directory)
        finally:
            _activity.on_end(None)


def usable_cores():
    """The cores this process may run on (its CPU affinity; every core where the OS does not
    say)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def share_processes(shares):
    """How many processes compile `shares` side by side: one per core this process may use, up
    to one per share; 1 where the cache cannot safely take kernels from several processes
    (share_safely) or VPLAYGROUND_COMPILE_PROCESSES says so."""
    cores = usable_cores()
    wanted = os.environ.get("VPLAYGROUND_COMPILE_PROCESSES", "").strip()
    if wanted.isdigit() and int(wanted) > 0:
        cores = int(wanted)
    return max(1, min(cores, len(shares))) if _sharing["safe"] else 1


# A helper still compiling after this long is stopped, and its part left to the warm-up.
HELPER_TIMEOUT = 1800.0


def compile_shares(shares, processes):
    """Runs the first of `shares` here and each other one in a helper process of its own (this
    Python, this engine's source, this cache directory), at most `processes` (share_processes)
    at a time including this one, then waits for the helpers (with one process, none: the
    warm-up compiles everything). A share that fails (or a helper that cannot start) is said in
    the log and left to the warm-up. A helper ends when this process does, however it ends: it
    stops when its standard input closes (helper_main)."""
    if processes < 2:
        return  # the warm-up compiles it all
    here, helpers = list(shares), []
    engine_root = str(Path(os.path.abspath(__file__)).parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [engine_root, os.environ.get("PYTHONPATH")])),
           "VPLAYGROUND_SHARE_CACHE": numba.config.CACHE_DIR}
    try:
        for share in shares[1:processes]:
            try:
                helpers.append(subprocess.Popen(
                    [sys.executable, "-c", f"from {__name__} import helper_main; helper_main({share!r})"],
                    env=env, cwd=engine_root, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL))
            except OSError as error:
                _log.warning(f"cannot start a helper compiling part of the engine ({error}); this process "
                             "compiles it")
                continue
            here.remove(share)
        for share in here:
            try:
                run_share(share)
            except Exception:
                _log.warning(f"compiling {share} failed; the warm-up compiles what it left", exc_info=True)
        for helper in helpers:
            try:
                status = helper.wait(timeout=HELPER_TIMEOUT)
            except subprocess.TimeoutExpired:
                status = f"still running after {HELPER_TIMEOUT:.0f} s"
            if status != 0:
                _log.warning(f"a helper compiling part of the engine stopped (exit status {status}); "
                             "the warm-up compiles what it left")
    finally:
        for helper in helpers:
            if helper.poll() is None:
                helper.kill()
            helper.wait()
            helper.stdin.close()


def helper_main(share):
    """A helper process of compile_shares: runs `share`, and ends at once when its parent
    closes its standard input (it ended, however: an interrupted make, a killed node), so that
    no helper goes on writing into a cache the next fill clears."""
    def parent_gone():
        while os.read(0, 4096):  # (the file descriptor: a thread left in sys.stdin's buffered
            pass                 # reader at exit aborts the interpreter)
        os._exit(1)
    threading.Thread(target=parent_gone, daemon=True).start()
    run_share(share)


def run_share(share):
    """Runs one share ("module:function") of a fill (compile_shares), into the cache directory
    being filled, whose lock the filling process holds (so the worlds the share builds must not
    wait for it). In a helper (VPLAYGROUND_SHARE_CACHE names that directory), an engine that
    would compile anywhere else (another copy on the helper's path) stops first."""
    if os.environ.get("VPLAYGROUND_SHARE_CACHE", numba.config.CACHE_DIR) != numba.config.CACHE_DIR:
        sys.exit(f"a share of the engine's compile would fill {numba.config.CACHE_DIR}, "
                 f"not {os.environ['VPLAYGROUND_SHARE_CACHE']}")
    module, function = share.split(":")
    was, _warming.active = getattr(_warming, "active", False), True
    try:
        getattr(importlib.import_module(module), function)()
    finally:
        _warming.active = was


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
