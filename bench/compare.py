"""Side by side: this engine, PyBullet (DIRECT, fixed step 1/128, one substep) and MuJoCo
(timestep 1/128, boxes on free joints: its defaults, with its sleeping, and with its CG solver) in
this process, and Rapier and Jolt (bench/peers: a Rust program each, single-threaded, the
engine's defaults, time step 1/128, sleeping on) in their own, on the same box lists
(bench/scenes.py). Each engine is timed after its warm-up (our Numba compile or cache load is
timed separately). Prints one table and writes JSON and a PNG of ms/step over simulated time.

Materials: boxes 0.6 static / 0.4 dynamic friction and 0.2 elasticity, the ground 0.8 / 0.6 and
0.1 (our defaults). Rapier and Jolt have one friction coefficient: they get the static one, and
combine a pair their own way (Rapier: averages; Jolt: friction's geometric mean, the larger
restitution). PyBullet and MuJoCo keep their default materials.

Every step is timed twice: the thread's CPU time (time.thread_time_ns), which other processes on
a shared machine do not inflate and which the ratios use, and wall time. A run that spends more
than --budget CPU seconds stops early and says so (MuJoCo's default Newton solver factors each
contact island's Hessian, which on one island of hundreds of boxes costs ~0.2 s a step here).

    python bench/compare.py                   # the full suite (~13 minutes on a shared 2-core VM)
    python bench/compare.py --quick           # a few seconds: small scenes, for the regression guard
    python bench/compare.py --scenes columns  # the pile and the 5,000 asleep only (~5 minutes)

PyBullet, MuJoCo and matplotlib come from `pip install .[bench]`, the Rust peers from
`bench/peers/build.sh` (make bench runs both); missing ones are skipped.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import scenes  # noqa: E402
from pile import world_of  # noqa: E402
from vplayground_ros.physics.specs import BODY_DEFAULTS, DEFAULT_GROUND  # noqa: E402

RATE = 128
DT = 1.0 / RATE
FALLING_SECONDS = 2.0  # the falling phase of a pile (SPEC 8)
# The peers run on one thread each, so ours does too (World.solver_threads; bench/pile.py
# --compare-threads measures what the second thread adds).
SOLVER_THREADS = 1
PEER_PROGRAMS = Path(__file__).parent / "peers" / "target" / "release"


class Ours:
    name = "vplayground"

    def __init__(self, boxes, world=None, threads=SOLVER_THREADS, measure_threads=False):
        """On `threads` solver threads for every step; with measure_threads, the second
        only while it measures that it pays (World.measure_threads, the World's default)."""
        self.world = world if world is not None else world_of(boxes, solver_threads=threads,
                                                              measure_threads=measure_threads)

    def step(self):
        self.world.step(1)

    def positions(self):
        return self.world.state()["positions"]

    def resting_count(self):
        return int(self.world.state()["frozen"].sum())


class PyBullet:
    name = "pybullet"

    def __init__(self, boxes):
        import pybullet
        self.p = pybullet
        self.client = pybullet.connect(pybullet.DIRECT)
        p, c = self.p, self.client
        p.setGravity(0, 0, -9.81, physicsClientId=c)
        p.setPhysicsEngineParameter(fixedTimeStep=DT, numSubSteps=1, physicsClientId=c)
        ground = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=c)
        p.createMultiBody(0, ground, physicsClientId=c)
        self.ids = []
        for size, position, quaternion, mass in boxes:
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=(size / 2).tolist(), physicsClientId=c)
            self.ids.append(p.createMultiBody(mass, shape, basePosition=position.tolist(),
                                              baseOrientation=quaternion.tolist(), physicsClientId=c))

    def step(self):
        self.p.stepSimulation(physicsClientId=self.client)

    def positions(self):
        return np.array([self.p.getBasePositionAndOrientation(i, physicsClientId=self.client)[0] for i in self.ids])

    def resting_count(self):
        return None  # PyBullet deactivates bodies too, but does not report how many


class MuJoCo:
    def __init__(self, boxes, sleeping=False, solver=None):
        import mujoco
        self.name = "mujoco" + (f"-{solver.lower()}" if solver else "") + ("+sleep" if sleeping else "")
        bodies = "".join(  # MuJoCo's quaternions are w, x, y, z; its box sizes are half sizes
            f'<body pos="{p[0]} {p[1]} {p[2]}" quat="{q[3]} {q[0]} {q[1]} {q[2]}"><freejoint/>'
            f'<geom type="box" size="{s[0] / 2} {s[1] / 2} {s[2] / 2}" mass="{m}"/></body>'
            for s, p, q, m in boxes)
        flags = '<flag sleep="enable"/>' if sleeping else ""
        solver_option = f' solver="{solver}"' if solver else ""
        # MuJoCo sizes its arena from the model: thousands of boxes in contact need more.
        memory = max(64, len(boxes) // 4)
        xml = (f'<mujoco><option timestep="{DT}"{solver_option}>{flags}</option><size memory="{memory}M"/>'
               f'<worldbody><geom type="plane" size="0 0 1"/>{bodies}</worldbody></mujoco>')
        self.mujoco = mujoco
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        self.sleeping = sleeping

    def step(self):
        self.mujoco.mj_step(self.model, self.data)

    def positions(self):
        # From the free joints' qpos (x, y, z, then the quaternion): valid before the first step,
        # unlike xpos, which only mj_forward fills.
        return self.data.qpos.reshape(-1, 7)[:, :3].copy()

    def resting_count(self):
        # nbody counts the world body, which is never asleep
        return int(self.model.nbody - self.data.nbody_awake) if self.sleeping else None


class PeerMissing(ImportError):
    """A Rust peer whose program has not been built."""


class RustPeer:
    """An engine in its own process (bench/peers): it gets the scene as a JSON file, runs all of
    its steps, timing each on its thread's CPU clock and the wall clock, and prints the times,
    the final positions and how many bodies sleep. Z up, SI units. `threads`: how many threads
    it may step on (the calling one included; Rapier's one-thread program takes only 1)."""
    program = None
    # Whether one thread means the calling thread: its thread CPU is then the engine's all.
    steps_on_calling_thread = True

    @classmethod
    def built(cls):
        """Whether bench/peers/build.sh has built this peer's program."""
        return (PEER_PROGRAMS / cls.program).exists()

    def __init__(self, boxes, sleeping=True, threads=1):
        self.path = PEER_PROGRAMS / self.program
        if not self.built():
            raise PeerMissing(self.path)
        self.boxes, self.sleeping, self.threads = boxes, sleeping, threads
        self.final_positions, self.asleep = None, None

    def scene(self, steps, budget_s):
        body, ground = BODY_DEFAULTS, DEFAULT_GROUND
        return {"dt": DT, "steps": steps, "gravity": [0.0, 0.0, -9.81], "sleeping": self.sleeping,
                "budget_s": budget_s, "threads": self.threads,
                "ground": {"height": ground["height"], "friction": ground["static_friction"],
                           "restitution": ground["elasticity"]},
                "boxes": [{"half_extents": (size / 2).tolist(), "position": position.tolist(),
                           "quaternion": quaternion.tolist(), "mass": mass,
                           "friction": body["static_friction"], "restitution": body["elasticity"]}
                          for size, position, quaternion, mass in self.boxes]}

    def run(self, steps, budget_s):
        """The program's report on `steps` steps (it stops after budget_s CPU seconds)."""
        with tempfile.NamedTemporaryFile("w", suffix=".json") as scene_file:
            json.dump(self.scene(steps, budget_s), scene_file)
            scene_file.flush()
            result = subprocess.run([str(self.path), scene_file.name], capture_output=True, text=True,
                                    timeout=max(600, 10 * budget_s))
        if result.returncode != 0:
            raise RuntimeError(f"{self.program} failed: {result.stderr[-1000:]}")
        report = json.loads(result.stdout)
        self.final_positions, self.asleep = np.array(report["positions"]), report["asleep"]
        return report

    def positions(self):
        if self.final_positions is None:
            return np.array([position for _, position, _, _ in self.boxes])
        return self.final_positions

    def resting_count(self):
        return self.asleep if self.sleeping else None


class Rapier(RustPeer):
    name = "rapier"
    program = "rapier_bench"


class RapierParallel(RustPeer):
    """Rapier built with its "parallel" feature (a rayon pool of `threads`)."""
    name = "rapier-parallel"
    program = "rapier_parallel_bench"
    steps_on_calling_thread = False  # rayon's pool steps it, one thread or more


class Jolt(RustPeer):
    name = "jolt"
    program = "jolt_bench"


def rust_peers_status():
    """A line saying which Rust peers will run, and why any will not."""
    missing = [peer.program for peer in (Rapier, RapierParallel, Jolt) if not peer.built()]
    if not missing:
        return "Rust peers: Rapier (one-thread and parallel builds) and Jolt (bench/peers)"
    why = ("cargo is not installed" if shutil.which("cargo") is None
           else "not built: run bench/peers/build.sh (make bench does)")
    return f"Rust peers skipped ({', '.join(missing)}): {why}"


def engines(boxes, peers=True, sleep=True, cg=True, ours=None, python_peers=True):
    """Every engine that is installed, built on the same boxes (ours: unless given)."""
    makers = [lambda: ours or Ours(boxes)]
    if peers:
        makers += [lambda: Rapier(boxes), lambda: Jolt(boxes)]
    if peers and python_peers:
        makers += [lambda: PyBullet(boxes), lambda: MuJoCo(boxes)]
        if sleep:
            makers.append(lambda: MuJoCo(boxes, sleeping=True))
        if cg:
            makers.append(lambda: MuJoCo(boxes, solver="CG"))
    for make in makers:
        try:
            yield make()
        except ImportError:
            continue


def significant(value, digits=4):
    return float(f"{value:.{digits}g}")


def progress(rows):
    """Each finished row on stderr as it comes (the full table is printed at the end)."""
    for row in rows:
        print(f"  {row['scene']}, {row['engine']}: RTF {row['rtf']} over {row['simulated_s']} s {row['note']}",
              file=sys.stderr, flush=True)
    return rows


class Timing:
    """CPU (this thread) and wall milliseconds of every step run."""

    def __init__(self):
        self.cpu_ms, self.wall_ms = [], []
        self.cpu_spent_ms = 0.0
        self.warnings = []

    def run(self, engine, seconds, budget_s):
        """Steps `engine` for `seconds` of simulated time, or until this timing has spent
        budget_s CPU seconds. Returns True when every step was run."""
        if isinstance(engine, RustPeer):
            return self.run_peer(engine, seconds, budget_s)
        for _ in range(int(round(seconds * RATE))):
            if self.cpu_spent_ms > budget_s * 1e3:
                return False
            wall0, cpu0 = time.perf_counter(), time.thread_time_ns()
            engine.step()
            self.cpu_ms.append((time.thread_time_ns() - cpu0) * 1e-6)
            self.wall_ms.append((time.perf_counter() - wall0) * 1e3)
            self.cpu_spent_ms += self.cpu_ms[-1]
        return True

    def run_peer(self, peer, seconds, budget_s):
        """A Rust peer times its own steps in its own process."""
        report = peer.run(int(round(seconds * RATE)), budget_s - self.cpu_spent_ms / 1e3)
        self.cpu_ms += report["cpu_ms"]
        self.wall_ms += report["wall_ms"]
        self.cpu_spent_ms += sum(report["cpu_ms"])
        self.warnings += report["errors"]
        # Its process's CPU time well above its thread's would mean the engine used more threads.
        if (peer.threads == 1 and peer.steps_on_calling_thread
                and report["process_cpu_s"] > 1.1 * self.cpu_spent_ms / 1e3 + 0.05):
            self.warnings.append(f"process CPU {report['process_cpu_s']:.2f} s > thread CPU "
                                 f"{self.cpu_spent_ms / 1e3:.2f} s")
        return report["complete"]

    def phase(self, first, last):
        cpu, wall = np.array(self.cpu_ms[first:last]), np.array(self.wall_ms[first:last])
        if len(cpu) == 0:
            return None
        # four decimals: a step of thousands of sleeping bodies in Rapier or Jolt is under 1 microsecond
        return {"median_ms": round(float(np.median(cpu)), 4), "p95_ms": round(float(np.percentile(cpu, 95)), 4),
                "max_ms": round(float(cpu.max()), 4), "wall_median_ms": round(float(np.median(wall)), 3),
                "wall_max_ms": round(float(wall.max()), 2)}

    def row(self, scene, bodies, engine, complete, seconds, rtf_from=0):
        """The scene's row; its real-time factors cover the steps from `rtf_from` on."""
        simulated = len(self.cpu_ms) / RATE
        timed = len(self.cpu_ms[rtf_from:]) / RATE
        return {"scene": scene, "bodies": bodies, "engine": engine.name,
                "simulated_s": round(simulated, 2), "complete": complete,
                "max_ms": round(max(self.cpu_ms), 2),  # the longest single step of the whole run
                "rtf": significant(timed / (sum(self.cpu_ms[rtf_from:]) / 1e3)),
                "rtf_wall": significant(timed / (sum(self.wall_ms[rtf_from:]) / 1e3)),
                "note": "; ".join(self.warnings + ([] if complete else
                                                   [f"CPU budget spent at {simulated:.1f} of {seconds:g} s"]))}


def pile_scene(count, seconds, budget_s):
    """Issue 20's loose pile (scenes.loose_pile) falling and settling."""
    rows, curves = [], {}
    boxes = scenes.loose_pile(count)
    falling = int(FALLING_SECONDS * RATE)
    for engine in engines(boxes):
        timing = Timing()
        complete = timing.run(engine, seconds, budget_s)
        p = engine.positions()
        row = timing.row(f"loose pile of {count}", count, engine, complete, seconds)
        row["falling"] = timing.phase(0, falling)
        if complete:
            row["resting"] = timing.phase(-RATE, None)
        row["stable"] = bool(np.all(np.isfinite(p)) and p[:, 2].min() > 0.1)
        row["at_rest"] = engine.resting_count()
        rows.append(row)
        curves[engine.name] = timing.cpu_ms
    return progress(rows), curves


def settled_pile(count, seconds):
    """The pile after `seconds` in this engine: the world, and its boxes as a box list from
    which the peers start (settling thousands of boxes from the drop would take PyBullet and
    MuJoCo's default solver hours here)."""
    boxes = scenes.pile(count)
    world = world_of(boxes, solver_threads=SOLVER_THREADS)
    world.step(int(seconds * RATE))
    state = world.state()
    return world, [(size, position, quaternion, mass) for (size, _, _, mass), position, quaternion
                   in zip(boxes, state["positions"], state["quaternions"])]


def resting_scene(count, settle_seconds, rest_seconds, budget_s, peers):
    """The settled pile: this engine goes on from its settled world; the peers start from its
    boxes and get rest_seconds to come to rest in their own contact models (and to sleep). Then
    one second is timed (its figures and real-time factor)."""
    rows = []
    world, boxes = settled_pile(count, settle_seconds)
    for engine in engines(boxes, peers=peers, cg=False, ours=Ours(boxes, world)):
        timing = Timing()
        complete = timing.run(engine, rest_seconds + 1.0, budget_s)
        row = timing.row(f"{count} at rest", count, engine, complete, rest_seconds + 1.0,
                         rtf_from=-RATE)
        row["resting"] = timing.phase(-RATE, None)
        row["at_rest"] = engine.resting_count()
        rows.append(row)
    return progress(rows)


def drift_figures(start, end):
    """How far the boxes that should have stood still moved (m), and whether that is standing."""
    drift = float(np.max(np.linalg.norm(end - start, axis=1)))
    return {"max_drift_m": round(drift, 4), "stands_2cm": drift < 0.02, "stands_10cm": drift < 0.1}


def columns_scene(count, settle_seconds, budget_s):
    """`count` boxes standing in columns of two, exactly on each other (scenes.resting_columns):
    every engine gets settle_seconds to put them to sleep (its own sleep timer), then one second
    is timed. PyBullet and MuJoCo are left out: on thousands of boxes in contact each would spend
    its whole CPU budget before sleeping."""
    rows = []
    boxes = scenes.resting_columns(count // 2)
    for engine in engines(boxes, python_peers=False):
        timing = Timing()
        complete = timing.run(engine, settle_seconds + 1.0, budget_s)
        row = timing.row(f"{count} in columns of two", count, engine, complete, settle_seconds + 1.0,
                         rtf_from=-RATE)
        row["resting"] = timing.phase(-RATE, None)
        row.update(drift_figures(np.array([position for _, position, _, _ in boxes]), engine.positions()))
        row["at_rest"] = engine.resting_count()
        rows.append(row)
    return progress(rows)


def stack_scene(label, boxes, seconds, budget_s):
    rows = []
    for engine in engines(boxes, sleep=False, cg=False):
        start = engine.positions().copy()
        timing = Timing()
        complete = timing.run(engine, seconds, budget_s)
        row = timing.row(label, len(boxes), engine, complete, seconds)
        row["resting"] = timing.phase(0, None)
        row.update(drift_figures(start, engine.positions()))
        rows.append(row)
    return progress(rows)


def car_scene(seconds, budget_s):
    from vplayground_ros.resources import find_shared
    from vplayground_ros.scene import load_world

    class Car(Ours):
        def __init__(self):
            self.world = load_world(find_shared("config/default_scene.yaml"))
            self.world.drive("car", 4.0, 0.4, timeout=1e5)  # never times out in this run

    car = Car()
    car.step()  # warm-up: the first step with a playground and a car loads their kernels
    timing = Timing()
    complete = timing.run(car, seconds, budget_s)
    row = timing.row("default scene, car circling", len(car.world.body_names()), car, complete, seconds)
    row["resting"] = timing.phase(0, None)
    return progress([row])


def stage_breakdown(count, seconds):
    """Where our step's CPU time goes on the falling pile (per-stage timers inside the compiled
    step): {stage: [ms per step, % of the step]}."""
    world = world_of(scenes.loose_pile(count), solver_threads=SOLVER_THREADS)
    world.profiling = True
    steps = int(seconds * RATE)
    world.step(steps)
    stages = world.stage_seconds()
    total = sum(stages.values())
    return {stage: [round(1e3 * s / steps, 3), round(100 * s / total, 1)] for stage, s in stages.items()}


def node_overhead(seconds):
    script = Path(__file__).with_name("node_overhead.py")
    try:
        result = subprocess.run([sys.executable, str(script), "--seconds", str(seconds)], capture_output=True,
                                text=True, timeout=300)
    except subprocess.TimeoutExpired:
        return {"error": "node_overhead.py did not finish in 300 s"}
    if result.returncode != 0:
        return {"error": result.stderr[-500:]}
    return json.loads(result.stdout.strip().splitlines()[-1])


def ratios(rows):
    """Our CPU-time real-time factor over each peer's, per scene (peers whose run stopped early
    are compared on the part they ran, which flatters them: the hardest part comes first)."""
    ours = {row["scene"]: row["rtf"] for row in rows if row["engine"] == Ours.name}
    for row in rows:
        if row["engine"] != Ours.name and row["scene"] in ours:
            row["ours_x"] = round(ours[row["scene"]] / row["rtf"], 2)


def stability(row):
    if "max_drift_m" in row:
        verdict = "stands" if row["stands_2cm"] else ("stands at 10 cm" if row["stands_10cm"] else "falls")
        text = f"max drift {row['max_drift_m']:.3f} m, {verdict}"
    elif "stable" in row:
        text = "stable" if row["stable"] else "UNSTABLE (box below the ground)"
    else:
        text = ""
    if row.get("at_rest") is not None:
        text += f"{', ' if text else ''}{row['at_rest']}/{row['bodies']} frozen or asleep"
    if row["note"]:
        text += f"{'; ' if text else ''}{row['note']}"
    return text


def print_table(rows):
    print("ms/step are this thread's CPU time (median/p95/max of the phase; max ms: the run's longest step); "
          "RTF = simulated s per CPU s, 'wall' per wall-clock s; 'ours x' = our RTF / the engine's (CPU)")
    print(f"{'scene':<28} {'bodies':>6} {'engine':<14} {'sim s':>5} {'falling ms':>18} {'resting ms':>18} "
          f"{'max ms':>7} {'RTF':>7} {'wall':>7} {'ours x':>7}  stability")
    for row in rows:
        ratio = f"{row['ours_x']:.{2 if row['ours_x'] < 100 else 0}f}" if "ours_x" in row else ""
        print(f"{row['scene']:<28} {row['bodies']:>6} {row['engine']:<14} {row['simulated_s']:>5.1f} "
              f"{medians(row.get('falling')):>18} {medians(row.get('resting')):>18} {row['max_ms']:>7.4g} "
              f"{row['rtf']:>7.2f} {row['rtf_wall']:>7.2f} {ratio:>7}  {stability(row)}")


def medians(phase_figures):
    if not phase_figures:
        return ""
    median, p95, longest = phase_figures["median_ms"], phase_figures["p95_ms"], phase_figures["max_ms"]
    digits = 4 if median < 0.01 else (3 if median < 1 else (2 if median < 100 else 0))
    return f"{median:.{digits}f}/{p95:.{digits}f}/{longest:.{digits}f}"


def plot(curves, count, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for name, ms in curves.items():
        ax.plot(np.arange(len(ms)) / RATE, ms, label=name, linewidth=0.8)
    ax.set_xlabel("simulated time, s")
    ax.set_ylabel("CPU ms per step")
    ax.set_yscale("log")
    ax.axhline(1e3 / RATE, color="grey", linestyle="--", linewidth=0.8, label="real time (7.8 ms)")
    ax.axvline(FALLING_SECONDS, color="grey", linestyle=":", linewidth=0.8)
    ax.set_title(f"Loose pile of {count} boxes falling and settling, 128 steps/s (falling phase left of the dotted line)")
    ax.legend(loc="center right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def first_step_seconds(cache_dir=None):
    """Wall seconds from a fresh interpreter to its first step: Numba's compile with an empty
    cache directory, its cache load with the engine's own (warm) one."""
    env = dict(os.environ, **({"VPLAYGROUND_JIT_CACHE": str(cache_dir)} if cache_dir else {}))
    code = ("import time; started = time.perf_counter(); from vplayground_ros.physics import World; "
            "w = World(); w.add_body({'size': [1, 1, 1], 'position': [0, 0, 1]}); w.step(1); "
            "print(time.perf_counter() - started)")
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    return round(float(result.stdout.split()[-1]), 2) if result.returncode == 0 else None


def compile_times(cold):
    """{"warm_s": cache load, "cold_s": compile from nothing (only when asked: about a minute)}."""
    first_step_seconds()  # fills the engine's cache if this source has not been compiled yet
    times = {"warm_s": first_step_seconds()}
    if cold:
        with tempfile.TemporaryDirectory() as empty:
            times["cold_s"] = first_step_seconds(empty)
    return times


SCENES = ("pile", "columns", "resting", "stacks", "car", "overhead")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small scenes, a few seconds in all")
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=SCENES,
                        help="run only these (default: all; the pile always runs, for the plot and the stage split)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--budget", type=float, default=50.0,
                        help="CPU seconds one engine may spend on one scene before its run stops (default 50)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    print(rust_peers_status(), flush=True)
    compile_s = compile_times(cold=not args.quick)
    Ours(scenes.tower(2)).step()  # this process's own cache load, before any timing

    if args.quick:
        pile_count, pile_seconds, columns, stacks = 150, 3.0, 300, (2.0, [10])
        resting = {"count": 300, "settle_seconds": 3.0, "rest_seconds": 1.0, "peers": False}
        breakdown_s = 1.0
    else:
        pile_count, pile_seconds, columns, stacks = 1000, 10.0, 5000, (20.0, [10, 20])
        resting = {"count": 5000, "settle_seconds": 20.0, "rest_seconds": 2.0, "peers": True}
        breakdown_s = FALLING_SECONDS
    rows, curves = pile_scene(pile_count, pile_seconds, args.budget)
    if "columns" in args.scenes:
        rows += columns_scene(columns, 3.0, args.budget)
    if "resting" in args.scenes:
        rows += resting_scene(budget_s=args.budget, **resting)
    if "stacks" in args.scenes:
        stack_seconds, towers = stacks
        for count in towers:
            rows += stack_scene(f"{count}-box tower", scenes.tower(count), stack_seconds, args.budget)
        if not args.quick:
            rows += stack_scene("55-box brick wall", scenes.brick_wall(), stack_seconds, args.budget)
    if "car" in args.scenes and not args.quick:
        rows += car_scene(10.0, args.budget)
    breakdown = stage_breakdown(pile_count, breakdown_s)
    overhead = node_overhead(20.0) if "overhead" in args.scenes and not args.quick else None
    ratios(rows)
    print("Numba, fresh interpreter to its first step (not in the figures): cache load (warm) "
          f"{compile_s['warm_s']} s" + (f", compile (empty cache) {compile_s['cold_s']} s" if "cold_s" in compile_s else ""))
    print_table(rows)
    print(f"our step on the falling loose pile of {pile_count} (first {breakdown_s:g} s), CPU ms per step and share: "
          + ", ".join(f"{stage} {ms:.3f} ({pct}%)" for stage, (ms, pct) in breakdown.items()))
    if overhead:
        print(f"node overhead (1,000 bodies, 30 Hz, bag on, every topic subscribed): {overhead}")
    name = "compare_quick" if args.quick else "compare"
    result = {"quick": args.quick, "scenes": list(args.scenes), "first_step_s": compile_s, "rows": rows,
              "stages_ms_percent": breakdown, "node_overhead": overhead,
              "plot": plot(curves, pile_count, args.out / f"{name}.png"),
              "bench_wall_s": round(time.perf_counter() - started, 1)}
    path = args.out / f"{name}.json"
    path.write_text(json.dumps(result, indent=2))
    print(f"results: {path} (the whole bench took {result['bench_wall_s']:.0f} s)")


if __name__ == "__main__":
    main()
