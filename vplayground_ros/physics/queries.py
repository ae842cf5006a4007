"""What a World can be asked without changing it: its bodies' state and properties by row,
the newest contacts, one body's spec, rays, the octree's cells, the step's stage times.

A mixin of World (world.py holds the bodies, their names and step()); these read its arrays
between steps, never while it steps.
"""

import numpy as np

from .broad_phase import cell_centres
from .math3d import quaternions_to_matrices
from .pipeline import STAGES
from .ray_batch import RayScene
from .shapes.compound import frame_parts
from .step_context import newest_contacts

# contacts() of a step without any (a world at rest: frozen bodies make none), which the node
# asks for after every batch. Read-only, so sharing the arrays is safe.
NO_CONTACTS = {"points": np.zeros((0, 3)), "normals": np.zeros((0, 3)), "depths": np.zeros(0),
               "impulses": np.zeros(0), "body_a": np.zeros(0, np.int64), "body_b": np.zeros(0, np.int64)}
for _array in NO_CONTACTS.values():
    _array.flags.writeable = False


def gather(array, rows):
    """array[rows] as a new array; rows: a Layout's rows (a slice or slot indices)."""
    return array[rows].copy() if isinstance(rows, slice) else array.take(rows, axis=0)


class WorldQueries:
    def octree_cells(self):
        """The occupied octree cells of the last step, [(level, centres (K, 3), edge)], for
        drawing (the 2008 program could show its octree)."""
        if self._root is None:
            return []
        keys = [index.keys[:index.count[0]] for index in
                (self._broad.moving, self._broad.static, self._playground.index)]
        return cell_centres(np.unique(np.concatenate(keys)), self.settings["octree_depth"], *self._root)

    def ray_scene(self):
        """What rays can hit now (every body, the playground, the ground), for casting any
        number of batches at this instant: RayScene.cast(origins, directions, max_range,
        exclude). Stale once the world steps or changes."""
        return RayScene(self._bodies, self._hulls, self._parts, self._playground, self.ground, dict(self._slots))

    def cast_rays(self, origins, directions, max_range, exclude=()):
        """RayHits (distance, point, normal, body row or GROUND/PLAYGROUND/NOTHING) of a batch
        of rays (origins (R, 3) or one point for all), ignoring the bodies named in `exclude`.
        See ray_scene() for several batches."""
        return self.ray_scene().cast(origins, directions, max_range, exclude)

    def state(self):
        """One row per body, in body_names() order (copies): motion_state() and
        body_properties() together."""
        return {**self.motion_state(), **self.body_properties()}

    def motion_state(self):
        """What stepping changes, one row per body (copies): positions and linear_velocities of
        the bodies' frames (a compound's is not its centre of mass), quaternions,
        angular_velocities, frozen."""
        b, layout = self._bodies, self._current_layout()
        position, orientation, velocity, frozen = (gather(array, layout.rows) for array in
                                                   (b.position, b.orientation, b.velocity, b.frozen))
        if len(layout.compound_rows):
            turns = quaternions_to_matrices(orientation[layout.compound_rows])
            offsets = np.einsum("kij,kj->ki", turns, layout.compound_centres)
            position[layout.compound_rows] -= offsets
            velocity[layout.compound_rows, :3] -= np.cross(velocity[layout.compound_rows, 3:], offsets)
        return {"positions": position, "quaternions": orientation,
                "linear_velocities": velocity[:, :3], "angular_velocities": velocity[:, 3:], "frozen": frozen}

    def body_properties(self):
        """What only adding, removing and editing change (see layout_version), one row per
        body (copies): shapes (codes of physics.shapes), dimensions (each shape's three
        numbers), sizes (full edges of a box about the body's frame, in its axes, that holds it:
        a compound's is its centre of mass' box grown by the offset of that centre), masses,
        immovable."""
        b, layout = self._bodies, self._current_layout()
        half = gather(b.half_extents, layout.rows)
        half[layout.compound_rows] += np.abs(layout.compound_centres)
        return {"shapes": gather(b.shape, layout.rows), "dimensions": gather(b.dimensions, layout.rows),
                "sizes": 2.0 * half, "masses": gather(b.mass, layout.rows),
                "immovable": gather(b.immovable, layout.rows)}

    def compound_parts(self):
        """Each compound body's parts in its frame (shapes.compound.FrameParts: shape codes,
        dimensions, poses, hull triangles), one row per body (None for the other shapes), as a
        tuple; for drawing."""
        return tuple(frame_parts(self._solids[slot][1].compound) if self._solids[slot][1].compound is not None
                     else None for slot in self._current_layout().slots.tolist())

    def hull_triangles(self):
        """Each body's hull as triangles (T, 3, 3) in its frame, one row per body (None for the
        shapes other than convex), as a tuple; for drawing."""
        return tuple(self._solids[slot][1].hull.triangles if self._solids[slot][1].hull is not None
                     else None for slot in self._current_layout().slots.tolist())

    def contacts(self):
        """The newest step's contact points; body_a/body_b are rows of state(), -1 the ground,
        -2 the playground. Normals point from A to B; impulses are N s (collision + contact)."""
        c = newest_contacts(self._contacts)
        n = int(c.count[0])
        if n == 0:
            return dict(NO_CONTACTS)
        # Bodies removed since that step take their contacts with them, also from a body that
        # has taken the slot since.
        present = self._bodies.active & ~self._departed
        row_of_slot = self._current_layout().row_of_slot
        a, b = c.body_a[:n], c.body_b[:n]
        keep = np.nonzero(present[a] & ((b < 0) | present[np.maximum(b, 0)]))[0]
        a, b = a[keep], b[keep]
        return {
            "points": c.point[keep],
            "normals": c.normal[keep],
            "depths": c.depth[keep],
            "impulses": c.collision_impulse[keep] + c.impulse[keep] + c.support_impulse[keep],
            "body_a": row_of_slot[a],
            "body_b": np.where(b >= 0, row_of_slot[np.maximum(b, 0)], b),
        }

    def body(self, name):
        """Everything a scene file holds about one body (the SPEC 3 keys), as plain Python: the
        pose and velocity of its frame (a compound's is not its centre of mass)."""
        slot = self._slot(name)
        b = self._bodies
        shape = self._shape(slot)
        return {
            "name": name, "shape": shape.name, **shape.fields,
            "position": self._frame_position(slot).tolist(),
            "quaternion": b.orientation[slot].tolist(),
            "linear_velocity": self._frame_velocity(slot).tolist(),
            "angular_velocity": b.velocity[slot, 3:].tolist(),
            "mass": float(b.mass[slot]),
            "elasticity": float(b.elasticity[slot]),
            "static_friction": float(b.static_friction[slot]),
            "dynamic_friction": float(b.dynamic_friction[slot]),
            "immovable": bool(b.immovable[slot]),
            "allow_freezing": bool(b.allow_freezing[slot]),
            "frozen": bool(b.frozen[slot]),
            # Only where it is not the default, so that ordinary bodies save as they always did.
            **({} if b.collides[slot] else {"collides": False}),
        }

    def stage_seconds(self):
        """CPU seconds spent in each stage of the step while `profiling` was on."""
        return {stage: float(ns) * 1e-9 for stage, ns in zip(STAGES, self._stage_ns)}

    @property
    def playground_triangles(self):
        """(T, 3, 3) the playground's triangles (a copy)."""
        return self._playground.triangles.copy()
