"""A robot arm beside a pile (issue 38's performance target): the loose pile alone against the
same pile with pybullet_data's KUKA iiwa (7 revolute joints, position motors holding a pose
under gravity) standing beside it, at 128 steps/s on one solver thread, in this thread's CPU
time per step. Rounds alternate the two worlds; prints each round's median and longest step of
the falling phase (the pile's first 2 s) and their ratios, then the ratio of the medians of each
step's fastest over the rounds (the worlds are deterministic, so a step's fastest is its time
with the least of the machine's noise, as `pile.py --runs` does).

    python bench/robot_pile.py [--boxes 200] [--rounds 4]
"""
import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from pile import build_pile, timed_steps, warm_up  # noqa: E402
from vplayground_ros.urdf_import import add_robot, robot_model  # noqa: E402

POSE = [0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1]  # rad, joints 1-7


def world(boxes, with_arm):
    world = build_pile(boxes, scene="loose", solver_threads=1)
    if with_arm:
        import pybullet_data
        model = robot_model(os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf"),
                            "kuka", position=[-8.0, 0.0, 0.0])  # beside the pile, on the ground
        add_robot(world, model)
        for joint, angle in zip(world.joint_names(), POSE):
            world.edit_joint(joint, motor={"mode": "position", "target": angle})
    return world


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--boxes", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=4)
    args = parser.parse_args()
    warm_up()
    world(8, True).step(8)  # the joint kernels' first call outside the timing
    rows = {False: [], True: []}
    steps = {False: [], True: []}
    for round_ in range(args.rounds):
        for with_arm in (False, True):
            cpu, _ = timed_steps(world(args.boxes, with_arm), 2 * 128)
            rows[with_arm].append((np.median(cpu), cpu.max()))
            steps[with_arm].append(cpu)
            label = "pile + arm" if with_arm else "pile alone"
            print(f"round {round_ + 1} {label:10s}: median {np.median(cpu):.3f} ms, longest {cpu.max():.3f} ms")
    alone, arm = np.array(rows[False]), np.array(rows[True])
    print(f"{args.boxes}-box loose pile, falling phase, {args.rounds} rounds: median "
          f"{alone[:, 0].min():.3f}-{alone[:, 0].max():.3f} ms alone, {arm[:, 0].min():.3f}-{arm[:, 0].max():.3f} "
          f"with the arm (ratio of medians {np.median(arm[:, 0]) / np.median(alone[:, 0]):.2f}); longest "
          f"{alone[:, 1].min():.2f}-{alone[:, 1].max():.2f} / {arm[:, 1].min():.2f}-{arm[:, 1].max():.2f} ms")
    fastest_alone, fastest_arm = (np.median(np.min(steps[k], axis=0)) for k in (False, True))
    print(f"each step's fastest of the {args.rounds} rounds: median {fastest_alone:.3f} ms alone, "
          f"{fastest_arm:.3f} with the arm (ratio {fastest_arm / fastest_alone:.2f})")


if __name__ == "__main__":
    main()
