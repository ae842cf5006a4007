"""How the kernel cache is filled (physics.jit_cache.compile_once): by one process, start to end,
and never finished by another. Behaviour with a stand-in warm-up (nothing compiles here)."""
import os
import shutil
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numba
import pytest

from helpers import wait_for
from vplayground_ros.physics import jit_cache
from vplayground_ros.physics.jit_cache import COMPLETE_MARKER, compile_once, compiler_activity


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    """An empty cache directory of its own, as numba.config.CACHE_DIR."""
    directory = tmp_path / "0123456789abcdef"
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(directory))
    return directory


def test_an_interrupted_fill_is_cleared_and_the_cache_filled_once(cache_dir):
    """What a process left without marking the cache complete (it died mid-compile) goes before
    the warm-up runs; the warm-up runs once, and the worlds it builds itself pass straight
    through."""
    (cache_dir / "physics_left").mkdir(parents=True)
    (cache_dir / "physics_left" / "pipeline.step_world-194.py311.1.nbc").write_bytes(b"half")
    (cache_dir / "stray.nbi").write_bytes(b"half")
    runs = []

    def warm_up():
        runs.append([p for p in cache_dir.rglob("*") if p.is_file()])
        compile_once(warm_up)  # a World built by the warm-up: no lock taken again, no recursion
    compile_once(warm_up)
    assert runs == [[]]
    assert (cache_dir / COMPLETE_MARKER).exists()
    compile_once(warm_up)
    assert len(runs) == 1


def test_a_failed_warm_up_leaves_the_cache_incomplete(cache_dir):
    def failing():
        raise RuntimeError("killed mid-compile")
    with pytest.raises(RuntimeError):
        compile_once(failing)
    assert not (cache_dir / COMPLETE_MARKER).exists()
    runs = []
    compile_once(lambda: runs.append(1))
    assert runs == [1] and (cache_dir / COMPLETE_MARKER).exists()


def test_a_cache_that_cannot_be_written_is_left_to_numba(tmp_path, monkeypatch, caplog):
    """A cache directory that cannot be made (here under a regular file): said once, no warm-up,
    no error; Numba then caches where it can, or compiles in memory."""
    (tmp_path / "file").write_text("not a directory")
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "file" / "0123456789abcdef"))
    runs = []
    for _ in range(2):
        compile_once(lambda: runs.append(1))
    assert runs == []
    said = [r.getMessage() for r in caplog.records if "cannot cache" in r.getMessage()]
    assert len(said) == 1 and "file/0123456789abcdef" in said[0]


@pytest.mark.skipif(jit_cache.fcntl is None, reason="no lock between processes here")
def test_a_second_process_waits_for_the_first_to_fill_the_cache(cache_dir, monkeypatch):
    """Another process holds the cache's lock (its warm-up running) and then marks the cache
    complete: this one waits for it, counted as compiler activity (so requests wait too), and
    does not compile or clear anything itself."""
    monkeypatch.setattr(jit_cache, "_activity", jit_cache.CompilerActivity())  # this test's only
    cache_dir.mkdir(parents=True)
    (cache_dir / "kernel.nbc").write_bytes(b"theirs")
    holder = textwrap.dedent(f"""
        import fcntl, time
        with open({str(cache_dir.parent / (cache_dir.name + ".lock"))!r}, "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            print("locked", flush=True)
            time.sleep(1.5)
            open({str(cache_dir / COMPLETE_MARKER)!r}, "w").close()
    """)
    other = subprocess.Popen([sys.executable, "-c", holder], stdout=subprocess.PIPE, text=True)
    try:
        assert other.stdout.readline().strip() == "locked"
        runs = []
        waiter = threading.Thread(target=compile_once, args=(lambda: runs.append(1),))
        started = time.monotonic()
        waiter.start()
        wait_for(lambda: compiler_activity() == (1, 0), timeout=5.0)  # waiting, counted
        waiter.join(timeout=30.0)
        assert not waiter.is_alive()
        assert time.monotonic() - started >= 1.0  # it waited for the other's lock
        assert runs == [] and (cache_dir / "kernel.nbc").read_bytes() == b"theirs"
        assert compiler_activity() == (0, 1)
    finally:
        other.wait(timeout=30.0)


def test_each_copy_of_the_engine_has_a_cache_of_its_own(tmp_path):
    """Numba files kernels under their source file's full path: two copies of one engine (two
    checkouts, a colcon install beside its source) sharing a directory would share its complete
    marker but not its kernels. The same copy keeps its directory, and a path through a symbolic
    link is another copy (Numba does not resolve links either); an edit to any source moves
    it."""
    engine = Path(jit_cache.__file__).parent
    copies = [tmp_path / name / "physics" for name in ("checkout", "install")]
    for copy in copies:
        shutil.copytree(engine, copy, ignore=shutil.ignore_patterns("__pycache__"))
    base = tmp_path / "cache"
    first, second = (jit_cache.source_keyed_directory(copy, base) for copy in copies)
    assert first.parent == second.parent == base and first != second
    assert jit_cache.source_keyed_directory(copies[0], base) == first
    (tmp_path / "link").symlink_to(copies[0].parent)
    assert jit_cache.source_keyed_directory(tmp_path / "link" / "physics", base) not in (first, second)
    with open(copies[0] / "shapes" / "__init__.py", "a") as source:
        source.write("\n")
    assert jit_cache.source_keyed_directory(copies[0], base) not in (first, second)


def test_each_cpu_target_has_a_cache_of_its_own(tmp_path):
    """Numba keys each kernel on the CPU it was compiled for: a process compiling for another
    one (NUMBA_CPU_NAME, or another machine on a shared home directory) found a cache marked
    complete and compiled every kernel again inside it, one by one."""
    def directory(**env):
        code = "import numba; import vplayground_ros.physics; print(numba.config.CACHE_DIR)"
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                             env={**os.environ, "VPLAYGROUND_JIT_CACHE": str(tmp_path), **env})
        assert run.returncode == 0, run.stderr[-2000:]
        return run.stdout.strip()
    host, generic = directory(), directory(NUMBA_CPU_NAME="generic")
    assert Path(host).parent == Path(generic).parent == tmp_path and host != generic
    assert directory() == host


def test_every_kernel_is_cached_free_of_the_gil_and_without_a_c_wrapper():
    """The engine's kernels are @njit(cache=True, nogil=True, no_cfunc_wrapper=True) (see
    physics/__init__): a kernel left out of the cache would compile in every process, and the
    C wrapper nothing calls cost 9 % of the cold compile."""
    import importlib
    import pkgutil

    from numba.core.caching import NullCache
    from numba.core.registry import CPUDispatcher

    import vplayground_ros.physics as physics
    kernels = {}
    for module_info in pkgutil.walk_packages(physics.__path__, physics.__name__ + "."):
        module = importlib.import_module(module_info.name)
        kernels.update({f"{module.__name__}.{name}": value for name, value in vars(module).items()
                        if isinstance(value, CPUDispatcher) and value.__module__ == module.__name__})
    assert len(kernels) > 100
    wrong = [name for name, kernel in kernels.items()
             if isinstance(kernel._cache, NullCache) or not kernel.targetoptions.get("nogil")
             or not kernel.targetoptions.get("no_cfunc_wrapper")]
    assert wrong == []


def test_unused_caches_beside_a_new_one_are_pruned(tmp_path):
    """Each engine edit or checkout makes a cache directory: those unused for two weeks go when
    a new one is filled, the four most recently used stay whatever their age, and what is not a
    cache directory is left alone."""
    from vplayground_ros.physics import jit_cache

    day, now = 86400, 1_000_000_000.0
    ages = {"a" * 16: 1, "b" * 16: 20, "c" * 16: 30, "d" * 16: 40, "e" * 16: 50, "f" * 16: 60}
    for name, age in ages.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "kernel.nbc").write_bytes(b"x")
        marker = tmp_path / name / COMPLETE_MARKER
        marker.touch()
        os.utime(marker, (now - age * day, now - age * day))
        (tmp_path / f"{name}.lock").touch()
    interrupted = tmp_path / ("9" * 16)  # never marked complete: its own time counts
    interrupted.mkdir()
    os.utime(interrupted, (now - 90 * day, now - 90 * day))
    (tmp_path / "notes").mkdir()  # not a cache directory
    new = tmp_path / ("0" * 16)
    new.mkdir()
    removed = jit_cache.prune(tmp_path, keep=new, now=now)
    # Kept: the new one and the three most recently used others (a, b, c); d, e, f and the
    # interrupted one were unused for more than 14 days.
    assert sorted(removed) == sorted(["d" * 16, "e" * 16, "f" * 16, "9" * 16])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["0" * 16, "a" * 16, "b" * 16, "c" * 16, "notes"] + [f"{n * 16}.lock" for n in "abc"])
    assert jit_cache.prune(tmp_path, keep=new, now=now + 300 * day) == []  # the newest four stay, however old


def test_a_complete_cache_is_marked_used_when_found(tmp_path, monkeypatch):
    from vplayground_ros.physics import jit_cache

    directory = tmp_path / ("1" * 16)
    directory.mkdir()
    marker = directory / COMPLETE_MARKER
    marker.touch()
    os.utime(marker, (0, 0))
    monkeypatch.setattr(jit_cache, "cache_directory", lambda: directory)
    monkeypatch.setattr(jit_cache, "_marked", set())
    compile_once(lambda: pytest.fail("a complete cache is not filled again"))
    assert time.time() - marker.stat().st_mtime < 60


def test_no_python_code_calls_a_kernel_without_its_python_wrapper():
    """A kernel compiled with no_cpython_wrapper=True (one only other kernels call: its wrapper
    cost 7 % of the cold compile) cannot be called from Python: the call segfaults. So no Python
    code of the package, the tests or the benchmarks names one outside a kernel (but to compile
    it for given types, `kernel.compile`): the names each file imports from the engine, or
    reaches through an engine module it imports, are resolved to the objects themselves."""
    import ast
    import importlib

    from numba.core.registry import CPUDispatcher

    root = Path(__file__).resolve().parent.parent
    files = [p for folder in ("vplayground_ros", "test", "bench") for p in (root / folder).rglob("*.py")]

    def in_kernel(function):
        return any("jit" in ast.unparse(d) for d in function.decorator_list)

    def wrapperless(value):
        return isinstance(value, CPUDispatcher) and value.targetoptions.get("no_cpython_wrapper")

    def package_of(path):
        parts = path.relative_to(root).with_suffix("").parts
        return ".".join(parts[:-1]) if parts[-1] != "__init__" else ".".join(parts[:-1])

    wrong = []
    for path in files:
        tree = ast.parse(path.read_text())
        names, modules = {}, {}  # a name -> the engine object it is; a name -> the engine module
        engine_module = None
        if path.is_relative_to(root / "vplayground_ros" / "physics"):
            engine_module = importlib.import_module(".".join(path.relative_to(root).with_suffix("").parts)
                                                    .removesuffix(".__init__"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                module = node.module or ""
                if node.level:
                    base = package_of(path).split(".")
                    base = base[:len(base) - node.level + 1]
                    module = ".".join(base + ([module] if module else []))
                if not module.startswith("vplayground_ros.physics"):
                    continue
                source = importlib.import_module(module)
                for alias in node.names:
                    value = getattr(source, alias.name, None)
                    if value is None:
                        value = importlib.import_module(f"{module}.{alias.name}")
                    (modules if isinstance(value, type(source)) else names)[alias.asname or alias.name] = value
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("vplayground_ros.physics") and alias.asname:
                        modules[alias.asname] = importlib.import_module(alias.name)

        class Calls(ast.NodeVisitor):
            def visit_FunctionDef(self, node):
                if not in_kernel(node):
                    self.generic_visit(node)

            def visit_Name(self, node):
                value = names.get(node.id, getattr(engine_module, node.id, None))
                if wrapperless(value):
                    wrong.append(f"{path.relative_to(root)}:{node.lineno} {node.id}")

            def visit_Attribute(self, node):
                if node.attr == "compile" and isinstance(node.value, ast.Name):
                    return  # compiling a kernel for given types (warm_up's shares) is no call
                if isinstance(node.value, ast.Name) and node.value.id in modules:
                    if wrapperless(getattr(modules[node.value.id], node.attr, None)):
                        wrong.append(f"{path.relative_to(root)}:{node.lineno} {node.value.id}.{node.attr}")
                self.generic_visit(node)

            def visit_ImportFrom(self, node):
                pass  # a kernel imported by a kernel module is called by its kernels

        Calls().visit(tree)
    assert wrong == []


SHARES_MODULE = """
import os
from pathlib import Path

import numba


def record(name):
    Path(numba.config.CACHE_DIR, name + ".ran").write_text(str(os.getpid()))


def first():
    record("first")


def second():
    record("second")


def third():
    record("third")


def failing():
    raise RuntimeError("this share failed")


def slow():
    record("slow")
    import time
    time.sleep(120)
"""


@pytest.fixture
def shared_fill(tmp_path, monkeypatch):
    """A cache directory as use_source_keyed_cache makes it (helpers compute the same one) and
    stand-in shares a helper process can import: (directory, what each share's process was)."""
    require_sharing()
    base = tmp_path / "cache"
    directory = jit_cache.source_keyed_directory(Path(jit_cache.__file__).parent, base)
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(directory))
    monkeypatch.setenv("VPLAYGROUND_JIT_CACHE", str(base))
    monkeypatch.setenv("VPLAYGROUND_COMPILE_PROCESSES", "2")
    (tmp_path / "stand_in_shares.py").write_text(SHARES_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))

    def ran():
        return {p.stem: int(p.read_text()) for p in directory.glob("*.ran")}
    return directory, ran


def test_shares_compile_in_helpers_before_the_warm_up(shared_fill):
    """The first share runs in the filling process, the next in a helper process of its own
    (two processes here), one more after them back in the filling process; the warm-up only
    once all of them are done."""
    directory, ran = shared_fill
    before_warm_up = []
    compile_once(lambda: before_warm_up.append(ran()),
                 ("stand_in_shares:first", "stand_in_shares:second", "stand_in_shares:third"))
    assert (directory / COMPLETE_MARKER).exists()
    processes = before_warm_up[0]
    assert sorted(processes) == ["first", "second", "third"]
    assert processes["first"] == processes["third"] == os.getpid() != processes["second"]


def test_a_failed_share_leaves_its_kernels_to_the_warm_up(shared_fill, caplog):
    directory, ran = shared_fill
    runs = []
    compile_once(lambda: runs.append(1), ("stand_in_shares:first", "stand_in_shares:failing"))
    assert runs == [1] and (directory / COMPLETE_MARKER).exists()
    assert any("stopped (exit status 1)" in r.getMessage() for r in caplog.records)


def test_a_helper_ends_with_the_process_it_helps(shared_fill):
    """However the filling process ends (an interrupted make, a killed node: no Python code of
    its runs), its helpers' standard input closes and they stop, not writing on into a cache
    the next fill clears."""
    directory, ran = shared_fill
    directory.mkdir(parents=True)
    env = {**os.environ, "VPLAYGROUND_SHARE_CACHE": str(directory)}
    helper = subprocess.Popen([sys.executable, "-c", "from vplayground_ros.physics.jit_cache import helper_main; "
                               "helper_main('stand_in_shares:slow')"], stdin=subprocess.PIPE, env=env)
    try:
        wait_for(lambda: "slow" in ran(), timeout=60.0)
        helper.stdin.close()  # what the parent's end does
        assert helper.wait(timeout=10.0) == 1
    finally:
        helper.kill()
        helper.wait()


def test_a_helper_of_another_engine_copy_compiles_nothing(monkeypatch):
    """A helper whose engine would fill another cache directory than its parent's (another copy
    of the engine on its path) stops before its share runs."""
    monkeypatch.setenv("VPLAYGROUND_SHARE_CACHE", "/elsewhere/0123456789abcdef")
    with pytest.raises(SystemExit, match="would fill"):
        jit_cache.run_share("stand_in_shares:first")


def test_each_process_numbers_its_compiled_code_apart():
    """Numba names compiled code after a per-process counter: from 1 in every process, two
    processes could name different code alike, and a process loading both would run the wrong
    one. Each process's count starts at a random 62-bit number."""
    require_sharing()
    script = ("import vplayground_ros.physics; from numba.core.bytecode import FunctionIdentity; "
              "print(next(FunctionIdentity._unique_ids))")
    starts = [int(subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                                 check=True).stdout) for _ in range(2)]
    assert starts[0] != starts[1] and min(starts) > 1_000_000


def test_kernel_index_updates_from_several_processes_keep_every_entry(tmp_path):
    """Numba names a new entry's file as the first one its kernel's index does not list, without
    a lock: processes adding entries to one index at once took the same file, and an entry then
    named another's code (100 of these 400 without the lock). Four processes, each ready with the
    engine imported, add 100 entries each to one index at the same moment: every entry finds its
    own data."""
    require_sharing()
    script = textwrap.dedent(f"""
        import sys
        from pathlib import Path
        import vplayground_ros.physics  # the lock on index updates
        from numba.core.caching import IndexDataCacheFile
        index = IndexDataCacheFile({str(tmp_path)!r}, "kernel", "stamp")
        worker = int(sys.argv[1])
        Path({str(tmp_path)!r}, f"ready{{worker}}").touch()
        sys.stdin.readline()  # all at once
        for k in range(100):
            index.save((worker, k), ("code of", worker, k))
    """)
    workers = [subprocess.Popen([sys.executable, "-c", script, str(w)], stdin=subprocess.PIPE)
               for w in range(4)]
    try:
        wait_for(lambda: len(list(tmp_path.glob("ready*"))) == 4, timeout=120.0)
        for w in workers:
            w.stdin.write(b"go\n")
            w.stdin.flush()
        assert [w.wait(timeout=60) for w in workers] == [0] * 4
    finally:
        for w in workers:
            w.kill()
            w.wait()
    from numba.core.caching import IndexDataCacheFile
    index = IndexDataCacheFile(str(tmp_path), "kernel", "stamp")
    wrong = [(w, k) for w in range(4) for k in range(100) if index.load((w, k)) != ("code of", w, k)]
    assert wrong == []


def test_a_kernel_outside_the_engines_cache_saves_beside_its_source(tmp_path, monkeypatch):
    """Where the engine's cache directory cannot be written, Numba keeps kernels in __pycache__
    beside their source (README): their index updates lock there, not in the directory that
    cannot be made."""
    (tmp_path / "file").write_text("not a directory")
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "file" / "0123456789abcdef"))
    (tmp_path / "toy_kernel.py").write_text("from numba import njit\n\n\n@njit(cache=True)\n"
                                             "def twice(x):\n    return 2 * x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import toy_kernel
    assert toy_kernel.twice(21) == 42
    assert list((tmp_path / "__pycache__").glob("toy_kernel.twice-*.nbi"))


def require_sharing():
    """On Linux the cache takes kernels from several processes (share_safely): a Numba whose
    internals differ from what it expects fails here rather than quietly compiling on one core."""
    if not sys.platform.startswith("linux"):
        pytest.skip("the cache is filled by one process here")
    assert jit_cache._sharing["safe"]
