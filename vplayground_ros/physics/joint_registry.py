"""The World's joints: their validated specs by name and their rows in the arrays the joint
kernels (joints.py) solve, kept packed in the order they were made (the solver's sweep order).
The bodies they hold are the World's; this registry knows them by slot, and the World removes a
body's joints with it, so no joint ever holds a slot another body has since taken."""
from collections import Counter

import numpy as np

from .joints import (ANCHOR, BODY_A, BODY_B, COLLIDE_CONNECTED, EFFORT, FEED_FORWARD, FRAME,
                     IMPULSE, KIND, KINDS, LOWER, MAX_EFFORT, MAX_SPEED, MOTORS, MOTOR_MODE,
                     MOTOR_TARGET, PER_JOINT, POSITION, SPEED, UPPER, WORLD_SIDE, WRAPPED_ANGLE,
                     allocate_joints, island_floats, pair_key)


class JointRegistry:
    def __init__(self):
        self.arrays = allocate_joints(4)  # what the kernels take
        self._names = []  # row order
        self._specs = {}  # name -> validated spec (parent and child by name)
        self._apart = []  # sets of body slots that do not collide with each other

    def __contains__(self, name):
        return name in self._specs

    def __len__(self):
        return len(self._names)

    def names(self):
        return list(self._names)

    def spec(self, name):
        """The joint's spec, its motor's target as it stands (a position motor's moves at its
        velocity)."""
        row = self.row(name)  # KeyError naming it
        spec = self._specs[name]
        spec["motor"]["target"] = float(self.arrays.values[row, MOTOR_TARGET])
        return spec

    def row(self, name):
        try:
            return self._names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r}") from None

    def add(self, name, joint, slots, anchors, frames):
        """Appends a validated joint between body slots (parent, child; WORLD_SIDE for the
        world), with its anchor and frame (x: the axis) in each side's body frame, at its
        `position` (0 unless the spec gives one)."""
        count = len(self._names)
        if count == len(self.arrays.links):
            self._grow(2 * count)
        a = self.arrays
        a.links[count, KIND] = KINDS[joint["type"]]
        a.links[count, BODY_A], a.links[count, BODY_B] = slots
        for side in range(2):
            a.frames[count, side, ANCHOR:ANCHOR + 3] = anchors[side]
            a.frames[count, side, FRAME:FRAME + 4] = frames[side]
        position = joint.get("position", 0.0)
        a.values[count, POSITION] = position
        a.values[count, WRAPPED_ANGLE] = (position + np.pi) % (2 * np.pi) - np.pi
        a.values[count, SPEED] = a.values[count, EFFORT] = 0.0
        a.row_values[count, :, IMPULSE] = 0.0
        a.count[0] = count + 1
        self._names.append(name)
        self._specs[name] = {**joint, "name": name, "motor": dict(joint["motor"])}
        self.edit(name, joint)

    def edit(self, name, fields):
        """Applies validated limits, motor and collide_connected."""
        row, a = self.row(name), self.arrays
        spec = self._specs[name]
        spec.update(fields)
        a.values[row, LOWER], a.values[row, UPPER] = spec["lower"], spec["upper"]
        motor = spec["motor"]
        a.links[row, MOTOR_MODE] = MOTORS[motor["mode"]]
        a.values[row, MOTOR_TARGET], a.values[row, FEED_FORWARD] = motor["target"], motor["velocity"]
        a.values[row, MAX_EFFORT], a.values[row, MAX_SPEED] = motor["max_effort"], motor["max_speed"]
        a.links[row, COLLIDE_CONNECTED] = spec["collide_connected"]

    def remove(self, names):
        """Drops joints, keeping the others packed in their order."""
        gone = {self.row(name) for name in names}
        if not gone:
            return
        keep = np.array([row for row in range(len(self._names)) if row not in gone], np.int64)
        a = self.arrays
        for field in PER_JOINT:
            values = getattr(a, field)
            values[:len(keep)] = values[keep]
        a.count[0] = len(keep)
        for row in sorted(gone, reverse=True):
            del self._specs[self._names.pop(row)]

    def shift_anchors(self, slot, offset):
        """Moves the anchors on body `slot` by `offset` (its axes): they are kept from its centre
        of mass, which an edit of a compound's parts moves on its frame."""
        a = self.arrays
        for row in range(len(self._names)):
            for side, end in ((0, BODY_A), (1, BODY_B)):
                if a.links[row, end] == slot:
                    a.frames[row, side, ANCHOR:ANCHOR + 3] += offset

    def holding(self, slots):
        """The joints that hold any of the body slots."""
        slots = set(int(slot) for slot in slots)
        a = self.arrays
        return [name for row, name in enumerate(self._names)
                if int(a.links[row, BODY_A]) in slots or int(a.links[row, BODY_B]) in slots]

    def slots(self, name):
        row = self.row(name)
        return int(self.arrays.links[row, BODY_A]), int(self.arrays.links[row, BODY_B])

    def keep_apart(self, slots):
        """Bodies that do not collide with each other (a robot's links), jointed or not."""
        self._apart.append(set(int(slot) for slot in slots))

    def forget(self, slots):
        """Drops removed bodies from the sets kept apart."""
        gone = set(int(slot) for slot in slots)
        self._apart = [kept for kept in (group - gone for group in self._apart) if len(kept) > 1]

    def update_bodies(self, jointed):
        """Marks the jointed bodies in `jointed` (the bodies' flag array), lists the pairs that
        must not collide (jointed without collide_connected, or kept apart), sorted, for the
        broad phase, and sizes the islands' solver storage for the groups the joints make."""
        a, count = self.arrays, len(self._names)
        jointed[:] = False
        excluded = [pair_key(x, y) for group in self._apart for x in group for y in group if x < y]
        group_of = {}  # body slot -> a body of its group (union-find)

        def root(slot):
            while group_of.setdefault(slot, slot) != slot:
                group_of[slot] = group_of[group_of[slot]]  # halves the path
                slot = group_of[slot]
            return slot

        for row in range(count):
            pair = [int(a.links[row, BODY_A]), int(a.links[row, BODY_B])]
            for slot in pair:
                if slot != WORLD_SIDE:
                    jointed[slot] = True
            held = [slot for slot in pair if slot != WORLD_SIDE]
            if len(held) == 2:
                group_of[root(held[0])] = root(held[1])
            if WORLD_SIDE not in pair and not a.links[row, COLLIDE_CONNECTED]:
                excluded.append(pair_key(*pair))
        sizes = Counter(root(int(a.links[row, BODY_B] if a.links[row, BODY_A] == WORLD_SIDE else a.links[row, BODY_A]))
                        for row in range(count))
        floats = island_floats(sizes.values())
        solver = a.island_solver if len(a.island_solver) >= floats else np.zeros(floats)
        self.arrays = a._replace(excluded_pairs=np.array(sorted(set(excluded)), np.int64), island_solver=solver)

    def _grow(self, capacity):
        grown = allocate_joints(capacity)
        old = self.arrays
        n = len(old.links)
        for field in PER_JOINT:
            getattr(grown, field)[:n] = getattr(old, field)
        self.arrays = grown._replace(count=old.count, excluded_pairs=old.excluded_pairs,
                                     island_solver=old.island_solver)
