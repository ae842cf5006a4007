"""How long the engine takes to compile cold, and which kernels that time goes to.

Runs the engine's warm-up (`World()` on an empty kernel cache: jit_cache.compile_once) in a
fresh subprocess with its own empty cache directory, and prints the whole warm-up's wall and CPU
seconds, then the kernels by exclusive compile time (their own typing, lowering, LLVM
optimisation and machine code, without the kernels they call compiling at their first call) and
by inclusive time, from Numba's event API (`numba:compile`, `numba:llvm_lock`). A kernel with
several specialisations (argument types, literal values) is one row; the count says how many.

LLVM's share is split into the per-function passes, the module passes of the final module (each
kernel's module with the modules of every kernel it calls linked in: Numba optimises a callee
again inside every caller) and machine code. `--modules` also counts the instructions each
final module holds and how many of them came from callees linked in (optimised and emitted
again) or are the wrappers Numba adds to each kernel for calls from Python and C, at some cost
to the times.

Where a second core is free the warm-up compiles in helper processes too (jit_cache.
compile_shares): the kernels listed are then the filling process's alone, and watching them
slows it (its helpers not); `--wall` times the warm-up unwatched, the figure users wait for.

    python bench/compile_time.py [--top 25] [--modules] [--wall] [--json out.json] [--keep DIR]

NUMBA_OPT, VPLAYGROUND_COMPILE_PROCESSES and other variables pass through to the subprocess.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# Prefixes of the wrappers Numba adds to every compiled kernel, for calls from Python and from C.
WRAPPERS = ("cpython.", "cfunc.")


def child(modules):
    """Compiles the engine into the (empty) cache directory that VPLAYGROUND_JIT_CACHE names and
    returns the measurements as a dict."""
    from numba.core import codegen, cpu, event

    kernels = defaultdict(lambda: {"specialisations": set(), "inclusive": 0.0, "exclusive": 0.0,
                                   "llvm": 0.0, "function passes": 0.0, "module passes": 0.0,
                                   "machine code": 0.0, "wrappers": 0.0, "instructions": 0, "linked instructions": 0,
                                   "wrapper instructions": 0, "passes": defaultdict(float),
                                   "callers": set()})
    frames = []  # the compiles under way, outermost first

    def innermost():
        return kernels[frames[-1]["key"]] if frames else kernels["(outside any compile)"]

    class Compiles(event.Listener):
        def on_start(self, ev):
            dispatcher = ev.data["dispatcher"]
            name = f"{dispatcher.py_func.__module__.rsplit('.', 1)[-1]}.{dispatcher.py_func.__qualname__}"
            kernels[name]["specialisations"].add(str(ev.data["args"]))
            if frames:
                kernels[name]["callers"].add(frames[-1]["key"])
            frames.append({"key": name, "start": time.perf_counter(), "children": 0.0})

        def on_end(self, ev):
            frame = frames.pop()
            inclusive = time.perf_counter() - frame["start"]
            kernel = kernels[frame["key"]]
            kernel["exclusive"] += inclusive - frame["children"]
            if frame["key"] not in (f["key"] for f in frames):  # recursion counts once
                kernel["inclusive"] += inclusive
            if frames:
                frames[-1]["children"] += inclusive
            if Passes.stack:  # the pass that set this compile off
                Passes.stack[-1][1] += inclusive

    class LlvmLock(event.Listener):
        depth, start = 0, 0.0

        def on_start(self, ev):
            if self.depth == 0:
                self.start = time.perf_counter()
            self.depth += 1

        def on_end(self, ev):
            self.depth -= 1
            if self.depth == 0:
                innermost()["llvm"] += time.perf_counter() - self.start

    class Passes(event.Listener):
        """Each compiler pass's own seconds (without the compiles it sets off), by kernel."""
        stack = []

        def on_start(self, ev):
            self.stack.append([time.perf_counter(), 0.0, len(frames)])

        def on_end(self, ev):
            start, children, depth = self.stack.pop()
            duration = time.perf_counter() - start
            innermost()["passes"][ev.data["name"].split(" [")[0]] += duration - children
            if self.stack and self.stack[-1][2] == depth:  # a pass of a callee's compile counts
                self.stack[-1][1] += duration               # as that compile (Compiles.on_end)

    event.register("numba:compile", Compiles())
    event.register("numba:llvm_lock", LlvmLock())
    event.register("numba:run_pass", Passes())

    def timed(cls, method, field, after=None):
        original = getattr(cls, method)

        def wrapper(self, *args, **kwargs):
            start = time.perf_counter()
            result = original(self, *args, **kwargs)
            innermost()[field] += time.perf_counter() - start
            if after:
                after(self, *args)
            return result
        setattr(cls, method, wrapper)

    own_functions = {}  # library -> names of the functions its own IR defines (not linked in)

    def note_own(library, ll_module):
        own_functions.setdefault(id(library), set()).update(
            f.name for f in ll_module.functions if not f.is_declaration)

    def count_instructions(library):
        own = own_functions.get(id(library), set())
        for function in library._final_module.functions:
            if function.is_declaration:
                continue
            size = sum(len(list(block.instructions)) for block in function.blocks)
            innermost()["instructions"] += size
            if function.name not in own:
                innermost()["linked instructions"] += size
            elif function.name.startswith(WRAPPERS):
                innermost()["wrapper instructions"] += size

    timed(codegen.CPUCodeLibrary, "_optimize_functions", "function passes")
    timed(codegen.CPUCodeLibrary, "_optimize_final_module", "module passes",
          after=count_instructions if modules else None)
    timed(codegen.JITCodeLibrary, "_finalize_specific", "machine code")
    # Building each wrapper's IR and its function passes (its share of the module passes and
    # machine code is in those columns).
    timed(cpu.CPUContext, "create_cpython_wrapper", "wrappers")
    timed(cpu.CPUContext, "create_cfunc_wrapper", "wrappers")
    if modules:
        original_add = codegen.CPUCodeLibrary.add_llvm_module

        def add_llvm_module(self, ll_module):
            note_own(self, ll_module)
            return original_add(self, ll_module)
        codegen.CPUCodeLibrary.add_llvm_module = add_llvm_module

    return {**timed_warm_up(), "kernels": {name: {**k, "specialisations": sorted(k["specialisations"]),
                                                  "callers": sorted(k["callers"])}
                                           for name, k in kernels.items()}}


def timed_warm_up():
    """The engine's import and whole warm-up into the empty cache: wall and CPU seconds (this
    process's and its helpers', jit_cache.compile_shares), and how many processes compiled."""
    from numba.core import config
    started, cpu_started = time.perf_counter(), time.process_time()
    from vplayground_ros.physics import World, jit_cache, warm_up
    imported = time.perf_counter() - started
    World()  # an empty cache: the whole warm-up (jit_cache.compile_once)
    wall = time.perf_counter() - started
    helpers = resource.getrusage(resource.RUSAGE_CHILDREN)
    if not (jit_cache.cache_directory() / jit_cache.COMPLETE_MARKER).exists():
        raise SystemExit("the warm-up did not complete the cache")
    return {"wall": wall, "cpu": time.process_time() - cpu_started + helpers.ru_utime + helpers.ru_stime,
            "import": imported, "numba_opt": config.OPT,
            "processes": jit_cache.share_processes(warm_up.SHARES)}


def report(result, top, modules):
    print(f"cold compile (whole warm-up, NUMBA_OPT={result['numba_opt']}, {result['processes']} "
          f"process{'es' if result['processes'] > 1 else ''}): {result['wall']:.1f} s wall, "
          f"{result['cpu']:.1f} s CPU ({result['cpu'] / result['wall']:.2f} CPU/wall); import "
          f"{result['import']:.1f} s")
    kernels = result.get("kernels")
    if kernels is None:
        return
    if result["processes"] > 1:
        print("  (the kernels below are the filling process's; its helpers' are not watched, and "
              "the watching slows it: VPLAYGROUND_COMPILE_PROCESSES=1 lists them all)")
    llvm = sum(k["llvm"] for k in kernels.values())
    print(f"  {sum(len(k['specialisations']) for k in kernels.values())} compiles of {len(kernels)} "
          f"kernels; LLVM {llvm:.1f} s")
    passes = defaultdict(float)
    for k in kernels.values():
        for name, seconds in k["passes"].items():
            passes[name] += seconds
    print("  Numba's passes (own seconds; native_lowering includes LLVM): " + ", ".join(
        f"{name} {seconds:.1f}" for name, seconds in sorted(passes.items(), key=lambda p: -p[1])[:8]))
    phases = ("function passes", "module passes", "machine code")
    print("  LLVM: " + ", ".join(f"{p} {sum(k[p] for k in kernels.values()):.1f} s" for p in phases)
          + f"; the kernels' wrappers (for calls from Python and C) built and passed over in "
          f"{sum(k['wrappers'] for k in kernels.values()):.1f} s")
    if modules:
        total = sum(k["instructions"] for k in kernels.values())
        linked = sum(k["linked instructions"] for k in kernels.values())
        wrappers = sum(k["wrapper instructions"] for k in kernels.values())
        print(f"  final modules: {total} instructions optimised, {linked} ({linked / max(total, 1):.0%}) "
              f"of them in callees' functions linked in, {wrappers} ({wrappers / max(total, 1):.0%}) in "
              "the kernels' own wrappers (for calls from Python and C)")
    columns = ("exclusive", "inclusive", "llvm", "module passes", "machine code", "wrappers")
    for order in ("exclusive", "inclusive"):
        print(f"\ntop {top} by {order} seconds:")
        print(f"  {'kernel':<48} {'n':>3} " + " ".join(f"{c[:12]:>12}" for c in columns)
              + (f" {'instructions':>12} {'linked':>7} {'wrappers':>8}" if modules else ""))
        ranked = sorted(kernels.items(), key=lambda item: -item[1][order])[:top]
        for name, k in ranked:
            print(f"  {name[:48]:<48} {len(k['specialisations']):>3} "
                  + " ".join(f"{k[c]:>12.1f}" for c in columns)
                  + (f" {k['instructions']:>12} {k['linked instructions'] / max(k['instructions'], 1):>7.0%}"
                     f" {k['wrapper instructions'] / max(k['instructions'], 1):>8.0%}" if modules else "")
                  + "  " + ", ".join(f"{p} {t:.1f}" for p, t in sorted(k["passes"].items(), key=lambda p: -p[1])[:2]))
    several = [(name, k) for name, k in kernels.items() if len(k["specialisations"]) > 1]
    if several:
        print("\nkernels compiled more than once (exclusive s: argument types):")
        for name, k in sorted(several, key=lambda item: -item[1]["exclusive"]):
            print(f"  {name} x{len(k['specialisations'])}, {k['exclusive']:.1f} s")
            for args in k["specialisations"][:4]:
                print(f"      {args[:150]}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--top", type=int, default=25, help="kernels listed per ranking")
    parser.add_argument("--modules", action="store_true",
                        help="count the final modules' instructions (slows the compile)")
    parser.add_argument("--wall", action="store_true",
                        help="only the wall and CPU seconds, the compile not watched kernel by kernel")
    parser.add_argument("--json", help="also write the measurements to this file")
    parser.add_argument("--keep", metavar="DIR",
                        help="compile into DIR (new or empty) and keep it, to run benchmarks on "
                             "(VPLAYGROUND_JIT_CACHE=DIR); else a temporary directory")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        json.dump(timed_warm_up() if args.wall else child(args.modules), sys.stdout)
        return
    if args.keep and Path(args.keep).exists() and any(Path(args.keep).iterdir()):
        parser.error(f"{args.keep} is not empty: a cold compile needs an empty cache")
    with tempfile.TemporaryDirectory(prefix="vplayground-compile-time-") as temporary:
        env = {**os.environ, "VPLAYGROUND_JIT_CACHE": args.keep or temporary,
               "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
        out = subprocess.run([sys.executable, __file__, "--child"] + (["--modules"] if args.modules else [])
                             + (["--wall"] if args.wall else []),
                             env=env, stdout=subprocess.PIPE, check=True, cwd=ROOT)
    result = json.loads(out.stdout)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    report(result, args.top, args.modules)


if __name__ == "__main__":
    main()
