"""Side by side, in one process: this engine, PyBullet (DIRECT, fixed step 1/128, one substep)
and MuJoCo (timestep 1/128, boxes on free joints; with and without its sleeping), on the same
box lists (bench/scenes.py). Each engine is timed after its warm-up (our Numba compile is timed
separately). Prints one table and writes JSON and a PNG of ms/step over simulated time.

    python bench/compare.py            # the full suite (minutes)
    python bench/compare.py --quick    # a few seconds: small scenes, for the regression guard

PyBullet, MuJoCo and matplotlib come from `pip install .[bench]`; missing ones are skipped.
"""
import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import scenes  # noqa: E402
from pile import world_of  # noqa: E402

RATE = 128
DT = 1.0 / RATE


class Ours:
    name = "vplayground"

    def __init__(self, boxes, freezing=True):
        self.world = world_of(boxes)
        if not freezing:
            self.world.update_settings({"freezing": {"enabled": False}})

    def step(self):
        self.world.step(1)

    def positions(self):
        return self.world.state()["positions"]


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


class MuJoCo:
    def __init__(self, boxes, sleeping=False):
        import mujoco
        self.name = "mujoco+sleep" if sleeping else "mujoco"
        bodies = "".join(
            f'<body pos="{p[0]} {p[1]} {p[2]}" quat="{q[3]} {q[0]} {q[1]} {q[2]}"><freejoint/>'
            f'<geom type="box" size="{s[0] / 2} {s[1] / 2} {s[2] / 2}" mass="{m}"/></body>'
            for s, p, q, m in boxes)
        flags = '<flag sleep="enable"/>' if sleeping else ""
        # MuJoCo sizes its arena from the model: thousands of boxes in contact need more.
        memory = max(64, len(boxes) // 4)
        xml = (f'<mujoco><option timestep="{DT}">{flags}</option><size memory="{memory}M"/>'
               f'<worldbody><geom type="plane" size="0 0 1"/>{bodies}</worldbody></mujoco>')
        self.mujoco = mujoco
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)

    def step(self):
        self.mujoco.mj_step(self.model, self.data)

    def positions(self):
        return self.data.xpos[1:].copy()


def engines(boxes, include_sleep=True, include_pybullet=True):
    """Every engine that is installed, built on the same boxes."""
    out = [Ours(boxes)]
    for make in (lambda: PyBullet(boxes) if include_pybullet else None, lambda: MuJoCo(boxes),
                 lambda: MuJoCo(boxes, sleeping=True) if include_sleep else None):
        try:
            engine = make()
        except ImportError:
            continue
        if engine is not None:
            out.append(engine)
    return out


def run(engine, seconds):
    steps = int(round(seconds * RATE))
    ms = np.empty(steps)
    for k in range(steps):
        t0 = time.perf_counter()
        engine.step()
        ms[k] = (time.perf_counter() - t0) * 1e3
    return ms


def phase(ms, first, last):
    part = ms[first:last]
    return {"median_ms": round(float(np.median(part)), 3), "p95_ms": round(float(np.percentile(part, 95)), 3),
            "max_ms": round(float(part.max()), 2)}


def pile_scene(count, seconds):
    rows, curves = [], {}
    boxes = scenes.pile(count)
    for engine in engines(boxes):
        ms = run(engine, seconds)
        p = engine.positions()
        rows.append({"scene": f"pile of {count}", "bodies": count, "engine": engine.name,
                     "falling": phase(ms, 0, 2 * RATE), "resting": phase(ms, len(ms) - RATE, len(ms)),
                     "rtf": round(seconds / (ms.sum() / 1e3), 2),
                     "stable": bool(np.all(np.isfinite(p)) and p[:, 2].min() > 0.1)})
        curves[engine.name] = ms.tolist()
    return rows, curves


def resting_scene(count, settle_seconds, include_peers):
    """A settled pile: each engine settles it, then 128 steps are timed."""
    rows = []
    boxes = scenes.pile(count)
    # PyBullet would take many minutes to settle thousands of boxes: not run.
    candidates = engines(boxes, include_pybullet=False) if include_peers else [Ours(boxes)]
    for engine in candidates:
        run(engine, settle_seconds)
        ms = run(engine, 1.0)
        rows.append({"scene": f"{count} at rest", "bodies": count, "engine": engine.name,
                     "resting": phase(ms, 0, len(ms)), "rtf": round(1.0 / (ms.sum() / 1e3), 2)})
    return rows


def stack_scene(label, boxes, seconds):
    rows = []
    for engine in engines(boxes, include_sleep=False):
        start = engine.positions().copy()
        ms = run(engine, seconds)
        drift = float(np.max(np.linalg.norm(engine.positions() - start, axis=1)))
        rows.append({"scene": label, "bodies": len(boxes), "engine": engine.name,
                     "resting": phase(ms, 0, len(ms)), "rtf": round(seconds / (ms.sum() / 1e3), 2),
                     "max_drift_m": round(drift, 4), "stands_2cm": drift < 0.02, "stands_10cm": drift < 0.1})
    return rows


def car_scene(seconds):
    from vplayground_ros.resources import find_shared
    from vplayground_ros.scene import load_world
    world = load_world(find_shared("config/default_scene.yaml"))
    world.drive("car", 4.0, 0.4, timeout=1e9)
    world.profiling = True
    ms = np.empty(int(seconds * RATE))
    for k in range(len(ms)):
        t0 = time.perf_counter()
        world.step(1)
        ms[k] = (time.perf_counter() - t0) * 1e3
    return [{"scene": "default scene, car circling", "bodies": len(world.body_names()), "engine": "vplayground",
             "resting": phase(ms, 0, len(ms)), "rtf": round(seconds / (ms.sum() / 1e3), 2)}]


def stage_breakdown(count, seconds):
    """Where our step's time goes on the falling pile (per-stage timers inside the compiled step)."""
    world = world_of(scenes.pile(count))
    world.profiling = True
    world.step(int(seconds * RATE))
    total = sum(world.stage_seconds().values())
    return {stage: round(100 * s / total, 1) for stage, s in world.stage_seconds().items()}


def node_overhead(seconds):
    script = Path(__file__).with_name("node_overhead.py")
    result = subprocess.run([sys.executable, str(script), "--seconds", str(seconds)], capture_output=True,
                            text=True, timeout=600)
    return json.loads(result.stdout.strip().splitlines()[-1]) if result.returncode == 0 else {"error": result.stderr[-500:]}


def print_table(rows):
    ratios = {}
    for row in rows:
        ratios.setdefault(row["scene"], {})[row["engine"]] = row["rtf"]
    print(f"{'scene':<30} {'bodies':>6} {'engine':<13} {'falling med/p95 ms':>19} {'resting med/p95 ms':>19} "
          f"{'RTF':>7} {'ours x':>7}  stability")
    for row in rows:
        falling = row.get("falling")
        resting = row.get("resting")
        ours = ratios[row["scene"]].get("vplayground")
        ratio = f"{ours / row['rtf']:.2f}" if ours and row["engine"] != "vplayground" else ""
        stability = ("max drift %.3f m, %s" % (row["max_drift_m"], "stands" if row["stands_2cm"] else
                                               ("stands at 10 cm" if row["stands_10cm"] else "falls"))
                     if "max_drift_m" in row else ("stable" if row.get("stable", True) else "UNSTABLE"))
        print(f"{row['scene']:<30} {row['bodies']:>6} {row['engine']:<13} {medians(falling, 2):>19} "
              f"{medians(resting, 3):>19} {row['rtf']:>7.2f} {ratio:>7}  {stability}")


def medians(phase_figures, digits):
    if not phase_figures:
        return ""
    return f"{phase_figures['median_ms']:.{digits}f}/{phase_figures['p95_ms']:.{digits}f}"


def plot(curves, path):
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
    ax.set_ylabel("ms per step")
    ax.set_yscale("log")
    ax.axhline(1e3 / RATE, color="grey", linestyle="--", linewidth=0.8, label="real time (7.8 ms)")
    ax.set_title("Pile of boxes falling and settling, 128 steps/s")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small scenes, a few seconds in all")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--no-peers-at-rest", action="store_true",
                        help="settle the 5,000 boxes in this engine only (MuJoCo takes many minutes)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    ours = Ours(scenes.tower(2))
    ours.step()
    compile_s = time.perf_counter() - started

    if args.quick:
        pile_rows, curves = pile_scene(150, 3.0)
        rows = pile_rows + resting_scene(300, 4.0, include_peers=False)
        rows += stack_scene("10-box tower", scenes.tower(10), 2.0)
        breakdown = stage_breakdown(150, 1.0)
        overhead = None
    else:
        pile_rows, curves = pile_scene(1000, 10.0)
        rows = pile_rows + resting_scene(5000, 8.0, include_peers=not args.no_peers_at_rest)
        for label, boxes in (("10-box tower", scenes.tower(10)), ("20-box tower", scenes.tower(20)),
                             ("55-box brick wall", scenes.brick_wall())):
            rows += stack_scene(label, boxes, 20.0)
        rows += car_scene(10.0)
        breakdown = stage_breakdown(1000, 2.0)
        overhead = node_overhead(20.0)
    print(f"Numba compile/cache load: {compile_s:.1f} s (not in the figures)")
    print_table(rows)
    print("our step, falling pile, share of time per stage: " + ", ".join(f"{k} {v}%" for k, v in breakdown.items()))
    if overhead:
        print(f"node overhead (1,000 bodies, 30 Hz, bag on, every topic subscribed): {overhead}")
    result = {"quick": args.quick, "compile_s": round(compile_s, 2), "rows": rows, "stages_percent": breakdown,
              "node_overhead": overhead, "plot": str(plot(curves, args.out / ("compare_quick.png" if args.quick else "compare.png")))}
    path = args.out / ("compare_quick.json" if args.quick else "compare.json")
    path.write_text(json.dumps(result, indent=2))
    print(f"results: {path}")


if __name__ == "__main__":
    main()
