"""The World: owns the body arrays, maps names to slots, and steps the compiled pipeline.

Everything here is Python bookkeeping between steps (adding, editing, removing bodies, growing
buffers); the physics runs inside `pipeline.step_world`, many steps per call.
"""
import heapq
import time
from collections import namedtuple

import numba
import numpy as np

from . import specs
from . import shapes
from .bodies import allocate_bodies, grow_bodies
from .broad_phase import allocate_broad_phase
from .constants import CONTACT_MARGIN
from .contact import index_manifolds
from .freezing import wake_body
from .jit_cache import compile_once, usable_cores
from .joint_registry import JointRegistry
from .joints import ANCHOR, EFFORT, FRAME, POSITION, SPEED, WORLD_SIDE, measure_joints
from .math3d import (axis_rotation, matrix_to_quaternion, quat_to_matrix, quaternions_to_matrices,
                     rpy_to_quat)
from .pipeline import (DONE, GROW_CONTACTS, GROW_INDEX, GROW_PAIRS, STAGES, STAT_FROZEN,
                       STAT_PAIRS, STAT_POINTS, STAT_TRIANGLES, STAT_WOKEN, resting_steps,
                       step_world)
from .playground import EMPTY_PLAYGROUND_ARGS, index_playground, make_playground
from .queries import WorldQueries
from .step_context import StepContext, allocate_contact_buffers, kernel_settings, newest_contacts
from .thread_choice import SecondThreadChoice, would_share
from .vehicle_registry import DEFAULT_COMMAND_TIMEOUT, VehicleRegistry
from .warm_up import SHARES, warm_up

# Bodies farther than this from the world's centre (the playground's middle, else the origin)
# have left the world (they fell off the edge or were flung away) and are removed, as are bodies
# whose state went non-finite. The centre must not follow the bodies: the octree root refits
# around every body, so one body placed far away would put all the others "outside".
WORLD_RADIUS = 2000.0

# The root cube reaches this far past the bodies it was fitted to, and is at least this large.
ROOT_PADDING = 4.0
MIN_ROOT_SIZE = 16.0


# Which bodies there are, in row order, and what depends only on that: rebuilt when
# World.layout_version changes, not every batch. slots: (N,) the rows' slots; rows: what selects
# them from a body array (a slice when they are 0..N-1, the common case, so gathers are copies);
# names, vehicle_names: tuples; row_of_slot: (capacity,) each slot's row (-1 for free slots);
# compound_rows (K,) the rows of compound bodies and compound_centres (K, 3) their centres of
# mass in their frames (what turns the engine's positions into the frames' poses).
Layout = namedtuple("Layout", "version slots rows names vehicle_names row_of_slot compound_rows compound_centres")

# A body id is its slot in the low bits and the slot's generation (how many bodies it held
# before) above them, as Box2D's generational ids: a removal cannot make one name another body.
SLOT_BITS = 32

BodyShape = namedtuple("BodyShape", "name module dimensions fields")


def body_bounds(b, slots):
    """World AABBs (min, max), (N, 3) each, of the bodies in `slots`."""
    return shapes.bounds(b.shape[slots], b.dimensions[slots], b.position[slots], b.orientation[slots])


def prepare_body(spec, path="body"):
    """A SPEC 3 body spec checked whole before any world is touched: (validated spec, its
    shapes.Solid, its specs.MassProperties). Errors name the key from `path`."""
    body = specs.validate_body(spec, path)
    density = body.get("density", specs.DEFAULT_DENSITY)
    solid = shapes.solid(body["shape"], body, path, density)
    if "mass" in body:  # a compound's parts keep their shares of it
        mass = body["mass"]
    else:
        mass = solid.compound.mass if solid.compound is not None else density * solid.volume
    return body, solid, specs.mass_properties(solid, mass, mass_key(body, path))


def mass_key(body, path):
    """The key a body's mass comes from, for messages: `mass`, `density`, else its size."""
    key = next((key for key in ("mass", "density") if key in body), None)
    return specs.child(path, key or shapes.SHAPES[body["shape"]].module.SPEC_KEYS[0])


def default_solver_threads():
    """2 where the process may run on two cores and Numba has two threads, else 1."""
    return 2 if min(usable_cores(), numba.config.NUMBA_NUM_THREADS) >= 2 else 1


class World(WorldQueries):
    """A world of bodies on an optional ground plane, with an optional playground mesh and
    vehicles: bodies by name, their arrays, step(). See SPEC 4 for the contract; what it can
    be asked is in queries.py."""

    def __init__(self, settings=None, ground=specs.DEFAULT_GROUND, capacity=64, solver_threads=None):
        compile_once(warm_up, SHARES)  # minutes on a first run; nothing once the kernels are cached
        self.settings = specs.validate_settings(settings)
        # Threads the contact solve may use (solver_threads below); not a scene setting: how
        # many cores to give is the host's choice, not the world's.
        self._solver_threads = None
        self.solver_threads = default_solver_threads() if solver_threads is None else solver_threads
        self.measure_threads = True
        self._sharing = False  # whether the last call's steps were large enough to share work
        self.threads_in_use = self.solver_threads  # the thread count the last call ran with
        self._clock = time.perf_counter_ns  # what measure_threads times calls by
        self.ground = specs.validate_ground(ground)
        self.time = 0.0
        self.step_count = 0
        # Where the time is counted from (_count_steps): (time, step_count, steps_per_second)
        # when the rate last changed or the time was set, and the (time, step_count) it left.
        self._timeline = (0.0, 0, self.settings["steps_per_second"], (0.0, 0))
        self._bodies = allocate_bodies(capacity)
        self._names = [None] * capacity
        self._solids = [None] * capacity  # (shape name, shapes.Solid) per slot
        self._pack_shapes()  # self._hulls (convex bodies' by slot, then parts'), self._parts
        self._slots = {}
        self._generations = np.zeros(capacity, np.int64)  # bodies each slot has released
        self._free = list(range(capacity))
        self._generated = 0
        # Bumped by every change to which bodies exist, their names, or their properties (add,
        # remove, edit, a vehicle's registration): readers of state() rows may keep whatever
        # depends only on those while it stays the same.
        self.layout_version = 0
        self.scenery_version = 0  # bumped by every change of the playground (the ground is fixed)
        self._layout = None
        # Slots whose state may have changed since remove_escaped last checked them (frozen and
        # immovable bodies do not move).
        self._unchecked = np.ones(capacity, dtype=bool)
        # Slots whose body was removed since the newest contacts were made: those contacts are
        # the removed body's, not its slot's next body's (contacts() leaves them out).
        self._departed = np.zeros(capacity, dtype=bool)
        self._vehicles = VehicleRegistry()  # the chassis of each is the body of its name
        self._joints = JointRegistry()
        self._generated_joints = 0
        self._broad = allocate_broad_phase(capacity, 4 * capacity)
        self._contacts = allocate_contact_buffers(16 * capacity, 4 * capacity)
        self._root = None  # (min corner, edge length) of the octree root cube; fitted lazily
        self._playground = make_playground(*EMPTY_PLAYGROUND_ARGS)[0]
        self.playground_spec = None  # how the scene described the playground, for saving
        # The scene's validated `sensors` entries: not physics (vplayground_ros.sensors samples
        # them through cast_rays), but part of the scene, kept and saved with it.
        self.sensor_specs = []
        # The URDF robots (vplayground_ros.urdf_robots), likewise: each entry as validated, with
        # its namespace, the bodies and joints it made ("bodies", "joints_held") and its root's
        # body_id ("id": which robot of that name it is, for whoever keeps its state); replaced,
        # never changed in place, so that whoever follows it sees it change. A robot losing a
        # body or a joint leaves it.
        self.robot_specs = []
        # The scene this world was built from (vplayground_ros.scene.SceneRecipe), or None: what
        # a full reset builds again.
        self.recipe = None
        self._centre = np.zeros(3)  # world_centre(), kept with the playground
        self.stats = {"woken": 0, "frozen": 0, "pairs": 0, "points": 0, "triangles": 0}
        self.profiling = False  # time every stage of the step (bench/), at ~6 us a step
        # A call that finds every body in the static index and no car steps in Python
        # (pipeline.resting_steps), skipping the ~30 us of handing the arrays to compiled code;
        # off, such steps run compiled (for timing the compiled step, and for tests that the
        # two agree).
        self.resting_shortcut = True
        # CPU seconds of the calling thread inside the compiled step (Numba's argument unboxing
        # included): what the engine itself costs, against which a host's overhead is measured.
        self.engine_cpu_seconds = 0.0
        self._stage_ns = np.zeros(len(STAGES), np.int64)

    @property
    def solver_threads(self):
        """Threads the contact solve may use: 1 solves every pass on the stepping thread; 2 lets
        a second one share passes with enough points (contact_solver.PARALLEL_MIN_POINTS), while
        it measures that the second pays (measure_threads). The results are bit-identical from
        run to run and with 1 or 2, whether or not the second thread gets a core."""
        return self._solver_threads

    @solver_threads.setter
    def solver_threads(self, threads):
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or not 1 <= threads <= 2:
            raise ValueError(f"solver_threads: must be 1 or 2, got {threads!r}")
        if threads != self._solver_threads:
            self._thread_choice = SecondThreadChoice()  # what a trial found was for the other count
        self._solver_threads = int(threads)

    @property
    def measure_threads(self):
        """With solver_threads 2, whether a call uses the second thread is measured on the calls
        that share work (thread_choice): the same bytes either way, so only the time changes.
        Off, every call uses solver_threads (for comparing one thread with two)."""
        return self._measure_threads

    @measure_threads.setter
    def measure_threads(self, measure):
        if not isinstance(measure, (bool, np.bool_)):
            raise ValueError(f"measure_threads: must be true or false, got {measure!r}")
        self._measure_threads = bool(measure)

    @property
    def second_thread_speedup(self):
        """One thread's time over two threads' on this world's last trial (measure_threads),
        or None before one ended."""
        return self._thread_choice.speedup

    # ----------------------------------------------------------------- bodies
    def body_names(self):
        """Every body (vehicle chassis included), in the row order of state()."""
        return list(self._current_layout().names)

    def body_id(self, name):
        """The body's id: what names this body and no other for as long as the World lives (a
        name is free again once its body is removed, an id never is). KeyError if none."""
        slot = self._slot(name)
        return int(self._generations[slot]) << SLOT_BITS | slot

    def body_name(self, body_id):
        """The name of the body with that id, or None once it is gone (whatever now sits in its
        slot or carries its name)."""
        slot, generation = int(body_id) & ((1 << SLOT_BITS) - 1), int(body_id) >> SLOT_BITS
        if slot >= len(self._names) or self._generations[slot] != generation:
            return None
        return self._names[slot]

    def add_body(self, spec, path="body"):
        """Adds a box from a SPEC 3 body spec; returns its (given or generated) unique name.
        Errors name the key from `path` (a scene's `bodies[3]`)."""
        body, solid, mass = prepare_body(spec, path)  # everything refusable, before any change
        self.check_inside(body["position"], f"{path}.position")
        name = body.get("name")
        if name is None:
            name = self._generate_name("box")
        elif name in self._slots:
            raise ValueError(f"{path}.name: a body named {name!r} already exists")
        if not self._free:
            self._grow(2 * len(self._names))
        slot = heapq.heappop(self._free)
        b = self._bodies
        b.active[slot] = True
        b.orientation[slot] = body["quaternion"] if "quaternion" in body else rpy_to_quat(body.get("rpy", (0, 0, 0)))
        b.shape[slot] = shapes.SHAPES[body["shape"]].code
        self._set_solid(slot, body["shape"], solid)
        b.position[slot] = self._centre_of_mass(slot, body["position"])
        self._set_fields(slot, body, mass)
        b.velocity[slot, :3] = self._centre_velocity(slot, b.velocity[slot, :3])
        self._names[slot] = name
        self._slots[name] = slot
        self.layout_version += 1
        self._check_root(slot)
        return name

    def add_vehicle(self, spec, path="vehicle"):
        """Adds a vehicle from a SPEC 3 `vehicles` entry; returns its unique name. Its chassis is
        an ordinary body of that name (it collides, can be pushed, edited, removed) that weighs
        as much as the chassis and wheels together; the wheels are data of the vehicle. Errors
        name the key from `path` (a scene's `vehicles[0]`)."""
        vehicle = specs.validate_vehicle(spec, path)
        name = vehicle.get("name") or self._generate_name("car")
        if name in self._slots:
            raise ValueError(f"{path}.name: a body named {name!r} already exists")
        # Its ROS namespace (vplayground_ros.robots), fixed now so that no later change moves its
        # topics: the first robot stands in the root namespace, each other in its name's (with
        # '_' for the '.' and '-' a name may have and a namespace may not).
        taken = self.robot_namespaces()
        vehicle.setdefault("namespace", specs.name_token(name) if "" in taken else "")
        if vehicle["namespace"] in taken:
            raise specs.SpecError(f"{path}.namespace", f"{vehicle['namespace']!r} is the namespace of "
                                                       f"{taken[vehicle['namespace']]} already")
        wheels = vehicle["wheels"]
        chassis = {**vehicle["chassis"], "name": name, "position": vehicle["position"],
                   "mass": vehicle["chassis"]["mass"] + sum(w["mass"] for w in wheels)}
        for key in ("rpy", "quaternion", "linear_velocity", "angular_velocity"):
            if key in vehicle:
                chassis[key] = vehicle[key]
        self._vehicles.add(name, vehicle, self._slots[self.add_body(chassis, path)])
        self.layout_version += 1
        return name

    def edit_vehicle(self, name, /, **fields):
        """Changes only the given vehicle keys: engine_power, brake_power, max_steer, max_steer_rate, and wheels
        as {index: {wheel keys}} (0-3: front-left, front-right, rear-left, rear-right). The
        chassis is edited as a body (edit_body)."""
        edit = specs.validate_vehicle_edit(fields, name)
        wheels = self._vehicles.spec(name)["wheels"]
        wheels_after = sum(edit.get("wheels", {}).get(k, {}).get("mass", wheel["mass"]) for k, wheel in enumerate(wheels))
        # The chassis body weighs the chassis and its wheels (add_vehicle).
        slot = self._slots[name]
        mass = specs.mass_properties(self._solids[slot][1], self._bodies.mass[slot] + wheels_after
                                      - self._wheels_mass(name), f"{name}.vehicle.wheels")
        self._vehicles.edit(name, edit)
        self._set_fields(slot, {}, mass)
        self.layout_version += 1  # its wheels
        self._wake(self._slots[name])

    def _wheels_mass(self, name):
        return sum(wheel["mass"] for wheel in self._vehicles.spec(name)["wheels"])

    def drive(self, name, speed, yaw_rate, timeout=DEFAULT_COMMAND_TIMEOUT):
        """Twist command for vehicle `name`: wanted forward speed (m/s, negative reverses) and
        yaw rate (rad/s, counter-clockwise positive). After `timeout` seconds of simulated time
        without a new command the car brakes to a stop."""
        if self._vehicles.drive(name, speed, yaw_rate, timeout):
            self._wake(self._slots[name])

    def restart_vehicle(self, name):
        """Puts vehicle `name`'s command, controller and wheels back as they were when it was
        added (no command, the steering straight, the speed and yaw loops' memory cleared); its
        pose and velocities are edit_body's."""
        self._vehicles.restart(name)

    def vehicle_state(self, name):
        """What the car is doing: applied controls and per-wheel state (arrays of 4, wheels
        front-left, front-right, rear-left, rear-right)."""
        return self._vehicles.state(name)

    def vehicle_names(self):
        return list(self._current_layout().vehicle_names)

    def vehicle(self, name):
        """The vehicle's spec with its chassis body as it is now (what a scene file holds): pose,
        velocities, size, material and flags, and the chassis' own mass (the body's less the
        wheels')."""
        # The chassis' state last, in this order, wherever the spec had it: a spec loaded from a
        # saved scene holds it, and the save after that had written it in another order.
        state = ("position", "quaternion", "linear_velocity", "angular_velocity")
        spec = {k: v for k, v in self._vehicles.spec(name).items() if k not in ("rpy", *state)}
        body = self.body(name)
        chassis = {"size": body["size"], "mass": body["mass"] - self._wheels_mass(name),
                   **{key: body[key] for key in specs.CHASSIS_BODY_KEYS}}
        return {**spec, "chassis": chassis, **{key: body[key] for key in state}}

    def edit_body(self, name, /, **fields):
        """Changes only the given SPEC 3 body keys (not name or shape). Size changes keep the
        mass unless mass or density is given too. A compound's frame keeps its position and
        velocity unless they are given (new parts or a turn move its centre of mass about it).
        Wakes the body and whatever touches it, unless the edit freezes it (`frozen=True`)."""
        slot = self._slot(name)
        body = specs.validate_body_fields(fields, name, specs.BODY_KEYS - {"name", "shape"})
        shape = self._shape(slot)
        specs.check_dimension_keys(shape.name, {**shape.fields, **body}, name)
        if "position" in body:
            self.check_inside(body["position"], f"{name}.position")
        resized = sorted(shape.fields.keys() & body.keys())
        solid = (shapes.solid(shape.name, {**shape.fields, **body}, name, body.get("density", specs.DEFAULT_DENSITY))
                 if resized else self._solids[slot][1])
        b = self._bodies
        if "inertial" in body:  # a compound's mass properties as given, its mass with them
            mass = specs.mass_properties(solid, body["inertial"]["mass"], specs.child(name, "inertial"))
        elif "mass" in body or "density" in body:
            mass = body["mass"] if "mass" in body else body["density"] * solid.volume
            if name in self._vehicles and mass <= self._wheels_mass(name):
                raise ValueError(f"{name}.mass: a car weighs its chassis and its wheels "
                                 f"({self._wheels_mass(name):g} kg): {mass:g} kg is not more")
            mass = specs.mass_properties(solid, mass, mass_key(body, name))
        else:  # the mass stays; a new size changes the inertia
            mass = specs.mass_properties(solid, float(b.mass[slot]), specs.child(name, (resized or ["mass"])[0]))
        self._wake_touching([slot])
        self._forget_contacts([slot])
        frame = body["position"] if "position" in body else self._frame_position(slot)
        frame_velocity = body["linear_velocity"] if "linear_velocity" in body else self._frame_velocity(slot)
        if "rpy" in body:
            b.orientation[slot] = rpy_to_quat(body["rpy"])
        if "quaternion" in body:
            b.orientation[slot] = body["quaternion"]
        if resized:
            old = self._solids[slot][1].compound
            self._set_solid(slot, shape.name, solid)
            if old is not None:  # the joints' anchors stay where they were on the body's frame
                self._joints.shift_anchors(slot, np.asarray(old.centre) - np.asarray(solid.compound.centre))
        if "position" in body or solid.compound is not None:
            b.position[slot] = self._centre_of_mass(slot, frame)
        self._set_fields(slot, body, mass)
        if solid.compound is not None and not (b.immovable[slot] or b.frozen[slot]):
            b.velocity[slot, :3] = self._centre_velocity(slot, frame_velocity)
        self.layout_version += 1  # sizes, masses, flags
        if not body.get("frozen", False):
            self._wake(slot)
        self._check_root(slot)

    def remove_body(self, name):
        self.remove_bodies([name])

    def robot_namespaces(self):
        """{ROS namespace: robot} of the vehicles and the URDF robots (robot_specs)."""
        taken = {self._vehicles.spec(other)["namespace"]: other for other in self.vehicle_names()}
        taken.update({robot["namespace"]: robot["name"] for robot in self.robot_specs})
        return taken

    def remove_bodies(self, names):
        """Removes many bodies at once; a KeyError for an unknown name removes none. What they
        touch is woken and their contacts dropped in one pass: one by one, each removal scans
        every frozen body and contact, and removing 10,000 resting boxes took ~9 s."""
        names = list(dict.fromkeys(names))
        slots = np.array([self._slot(name) for name in names], dtype=np.int64)
        if len(slots) == 0:
            return
        self._remove_joints(self._joints.holding(slots))
        self._joints.forget(slots)
        self._joints.update_bodies(self._bodies.jointed)
        self._wake_touching(slots)
        self._forget_contacts(slots)
        for name, slot in zip(names, slots):
            self._release(name, int(slot))
        self._forget_robots_without(names)

    def _forget_robots_without(self, removed):
        """A robot missing a link or a joint (`removed`: body or joint names) is no longer one:
        what is left of it stays as bodies and joints."""
        gone = set(removed)
        if any(gone.intersection(robot["bodies"]) or gone.intersection(robot["joints_held"])
               for robot in self.robot_specs):
            self.robot_specs = [robot for robot in self.robot_specs
                                if not (gone.intersection(robot["bodies"]) or gone.intersection(robot["joints_held"]))]
            self.layout_version += 1  # what follows the layout follows the robots

    def _release(self, name, slot):
        """Frees a body's slot and name (what it touched already woken)."""
        b = self._bodies
        if b.static_indexed[slot]:
            self._broad.stale[0] += 1
        # The freezing time too: a body taking the slot starts its rest afresh.
        for field, default in (("active", False), ("frozen", False), ("static_indexed", False),
                               ("awake", False), ("immovable", False), ("collides", True),
                               ("freeze_timer", 0.0)):
            getattr(b, field)[slot] = default
        b.velocity[slot] = 0.0
        b.external_impulse[slot] = 0.0
        b.external_angular_impulse[slot] = 0.0
        del self._slots[name]
        self._vehicles.remove(name)
        self._names[slot] = None
        self._generations[slot] += 1
        self._departed[slot] = True
        packed = self._solids[slot][1].hull is not None or self._solids[slot][1].compound is not None
        self._solids[slot] = None
        if packed:
            self._pack_shapes()
        self.layout_version += 1
        heapq.heappush(self._free, slot)

    # ----------------------------------------------------------------- joints
    def add_joint(self, spec, path="joint"):
        """Adds a joint from a spec (specs.validate_joint) between two bodies, or a body and the
        world (no `parent`), as they stand now: its anchor and axis are fixed to each body here,
        and its coordinate is 0 in this pose. Returns its (given or generated) unique name.
        Jointed bodies do not collide with each other unless `collide_connected`."""
        joint = specs.validate_joint(spec, path)
        name = joint.get("name")
        if name is None:
            name = self._generate_joint_name()
        elif name in self._joints:
            raise ValueError(f"{path}.name: a joint named {name!r} already exists")
        sides = []
        for key in ("parent", "child"):
            if key not in joint:
                sides.append(WORLD_SIDE)
            elif joint[key] not in self._slots:
                raise specs.SpecError(f"{path}.{key}", f"no body named {joint[key]!r}")
            else:
                sides.append(self._slots[joint[key]])
        b = self._bodies
        anchor = np.array(joint.get("anchor", b.position[sides[1]]), dtype=np.float64)
        axis = np.asarray(joint["axis"])
        frame = joint_frame(axis)
        # The parent's frame and anchor sit `position` back along the axis from the child's.
        moved = joint.get("position", 0.0)
        if joint["type"] == "prismatic":
            placed = ((anchor - moved * axis, frame), (anchor, frame))
        else:
            placed = ((anchor, axis_rotation(axis, -moved) @ frame), (anchor, frame))
        anchors, frames = [], []
        for slot, (point, orientation) in zip(sides, placed):
            centre, rotation = self._pose(slot)
            anchors.append(rotation.T @ (point - centre))
            frames.append(matrix_to_quaternion(rotation.T @ orientation))
        self._joints.add(name, joint, sides, anchors, frames)
        self._joints.update_bodies(b.jointed)
        self._forget_contacts([slot for slot in sides if slot != WORLD_SIDE])
        for slot in sides:
            if slot != WORLD_SIDE:
                self._wake(slot)
        return name

    def disable_collisions(self, names):
        """The named bodies stop colliding with each other (a robot's links, which simulators of
        URDF robots leave apart unless asked); with everything else they collide as before."""
        slots = [self._slot(name) for name in names]
        self._joints.keep_apart(slots)
        self._joints.update_bodies(self._bodies.jointed)
        self._forget_contacts(slots)

    def joint_names(self):
        """Every joint, in the order they were made (the order the solver sweeps them)."""
        return self._joints.names()

    def joint(self, name):
        """The joint as it is now: its spec with `anchor` (the child's anchor) and `axis` (the
        parent's) in the world now, `position` (rad, turns counted, or m; what the spec gave
        where it was made), `velocity` (rad/s or m/s) and `effort` (N m or N its motor and
        limits applied along the axis in the last step). Its spec keys (without velocity and
        effort, and position for a fixed joint) make the same joint again between the same
        bodies as they are."""
        row = self._joints.row(name)
        arrays = self._joints.arrays
        measure_joints(self._bodies, arrays)
        parent, child = self._joints.slots(name)
        parent_centre, parent_rotation = self._pose(parent)
        child_centre, child_rotation = self._pose(child)
        frames, values = arrays.frames[row], arrays.values[row]
        axis = parent_rotation @ quaternions_to_matrices(frames[0, FRAME:FRAME + 4][None])[0][:, 0]
        spec = self._joints.spec(name)
        return {**spec, "motor": dict(spec["motor"]),
                "anchor": (child_centre + child_rotation @ frames[1, ANCHOR:ANCHOR + 3]).tolist(),
                "axis": axis.tolist(), "position": float(values[POSITION]),
                "velocity": float(values[SPEED]), "effort": float(values[EFFORT])}

    def joint_states(self, names):
        """(positions, velocities, efforts) arrays of the joints `names`, as joint() has them."""
        arrays = self._joints.arrays
        measure_joints(self._bodies, arrays)
        rows = [self._joints.row(name) for name in names]
        values = arrays.values[rows]
        return values[:, POSITION].copy(), values[:, SPEED].copy(), values[:, EFFORT].copy()

    def drive_joints(self, motors):
        """{joint: partial motor mapping} (edit_joint's `motor`), all checked before any is
        set; the bodies they hold woken. For controllers: one call per command."""
        edits = {name: specs.validate_joint_edit({"motor": motor}, name, self._joints.spec(name)["type"],
                                                 self._joints.spec(name))
                 for name, motor in motors.items()}
        for name, edit in edits.items():
            self._joints.edit(name, edit)
            for slot in self._joints.slots(name):
                if slot != WORLD_SIDE:
                    self._wake(slot)

    def _pose(self, slot):
        """(centre of mass, rotation matrix) of a body, or the world's (WORLD_SIDE)."""
        if slot == WORLD_SIDE:
            return np.zeros(3), np.eye(3)
        return self._bodies.position[slot].copy(), quaternions_to_matrices(self._bodies.orientation[slot][None])[0]

    def edit_joint(self, name, /, **fields):
        """Changes only the given keys: lower, upper, motor (a partial mapping: mode, target,
        max_effort, max_speed) and collide_connected. Wakes the bodies it holds."""
        spec = self._joints.spec(name)
        edit = specs.validate_joint_edit(fields, name, spec["type"], spec)
        lower, upper = edit.get("lower", spec["lower"]), edit.get("upper", spec["upper"])
        position = self.joint(name)["position"]
        if ("lower" in edit or "upper" in edit) and not specs.within_limits(position, lower, upper):
            raise specs.SpecError(f"{name}.{'lower' if position < lower else 'upper'}",
                                  f"the joint is at {position:g}, outside the limits [{lower:g}, {upper:g}]")
        self._joints.edit(name, edit)
        self._joints.update_bodies(self._bodies.jointed)
        for slot in self._joints.slots(name):
            if slot != WORLD_SIDE:
                self._wake(slot)

    def remove_joint(self, name):
        self._joints.row(name)  # KeyError for an unknown name
        self._remove_joints([name])

    def _remove_joints(self, names):
        if not names:
            return
        held = {slot for name in names for slot in self._joints.slots(name) if slot != WORLD_SIDE}
        self._joints.remove(names)
        self._forget_robots_without(names)
        self._joints.update_bodies(self._bodies.jointed)
        for slot in held:
            if self._bodies.active[slot]:
                self._wake(slot)

    def _generate_joint_name(self):
        while True:
            self._generated_joints += 1
            name = f"joint_{self._generated_joints}"
            if name not in self._joints:
                return name

    def apply_impulse(self, name, impulse=(0.0, 0.0, 0.0), angular_impulse=(0.0, 0.0, 0.0)):
        """Queues an impulse (N s) and an angular impulse (N m s, world) for the next step: the
        2008 mouse push/pull. Wakes the body."""
        slot = self._slot(name)
        imp = specs.vector(list(impulse), "impulse", 3, -1e9, 1e9)
        ang = specs.vector(list(angular_impulse), "angular_impulse", 3, -1e9, 1e9)
        if self._bodies.immovable[slot]:
            return
        self._wake(slot)
        self._bodies.external_impulse[slot] += imp
        self._bodies.external_angular_impulse[slot] += ang

    def world_centre(self):
        """The centre of the world's bounds (WORLD_RADIUS around it): the middle of the
        playground's bounds, else the origin."""
        return self._centre.copy()

    def check_inside(self, position, path="position"):
        """Raises SpecError (a ValueError) when a position lies outside the world's bounds,
        where the body would be removed at the next step."""
        centre = self.world_centre()
        distance = float(np.linalg.norm(np.asarray(position, dtype=np.float64) - centre))
        if not distance <= WORLD_RADIUS:
            raise specs.SpecError(path, f"{list(position)} is outside the world: {distance:.6g} m from "
                                        f"its centre {centre.tolist()}, farther than {WORLD_RADIUS:g} m")

    def remove_escaped(self):
        """Removes bodies whose state is not finite or that left the world (WORLD_RADIUS from
        world_centre(), or that far below the ground). Returns their names. Only bodies that may
        have moved since the last call are looked at: the others were inside then."""
        b = self._bodies
        self._unchecked |= ~(b.frozen | b.immovable)  # moving now (woken between steps, say)
        slots = np.nonzero(b.active & self._unchecked)[0]
        self._unchecked[:] = False
        if len(slots) == 0:
            return []
        position = b.position.take(slots, axis=0)
        state = np.concatenate([position, b.orientation.take(slots, axis=0), b.velocity.take(slots, axis=0)], axis=1)
        bad = ~np.all(np.isfinite(state), axis=1)
        centre = self.world_centre()
        with np.errstate(over="ignore"):  # an infinite coordinate is just "far", and bad already
            bad |= np.linalg.norm(np.nan_to_num(position - centre), axis=1) > WORLD_RADIUS
        if self.ground is not None:
            bad |= position[:, 2] < self.ground["height"] - WORLD_RADIUS
        names = [self._names[slot] for slot in slots[bad]]
        self.remove_bodies(names)
        return names

    def wake_all(self):
        for slot in self._active_slots():
            self._wake(slot)

    def update_settings(self, settings):
        """Changes the given settings (a partial SPEC 3 `settings` mapping) on the running world,
        the 2008 "Physics values" panel. Everything wakes: gravity or thresholds may have changed
        under bodies at rest."""
        merged = {**self.settings, **settings}
        if isinstance(settings.get("freezing"), dict):
            merged["freezing"] = {**self.settings["freezing"], **settings["freezing"]}
        new_settings = specs.validate_settings(merged)
        if new_settings["octree_depth"] != self.settings["octree_depth"]:
            self._root = None  # refit, which rebuilds the static index at the new depth
        self.settings = new_settings
        self.wake_all()

    def set_playground(self, vertices, faces, spec=None):
        """Makes the static triangle mesh (world-space vertices (V, 3), counter-clockwise
        triangles (T, 3) facing outwards) the world's playground, replacing any other. `spec` is
        kept for saving. Returns how many degenerate triangles were dropped; raises ValueError
        for non-finite vertices or indices out of range, leaving the old playground."""
        playground, dropped = make_playground(vertices, faces)
        self._playground = playground
        self._centre = (0.5 * (playground.aabb_min.min(axis=0) + playground.aabb_max.max(axis=0))
                        if len(playground.triangles) else np.zeros(3))
        self.playground_spec = spec
        self.scenery_version += 1
        self._unchecked[:] = True  # the world's bounds moved with its centre
        self._root = None  # refit around the mesh, which indexes it
        self.wake_all()
        return dropped

    # ------------------------------------------------------------------ stepping
    def step(self, n=1):
        """Runs n whole steps of 1/steps_per_second inside compiled code."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"step: n must be a non-negative integer, got {n!r}")
        if self._root is None:
            self._fit_root()
        rate = self.settings["steps_per_second"]
        dt = 1.0 / rate
        freezing = self.settings["freezing"]
        # Long enough for a frozen body to be woken, move and freeze again unseen?
        refreeze = freezing["enabled"] and (n + 1) * dt >= freezing["time"]
        # Frozen bodies do not move; checking every body once a simulated second anyway bounds
        # how long a state the engine should never write (a fault) goes unnoticed.
        new_second = (self.step_count + n) // rate != self.step_count // rate
        if refreeze or new_second:
            self._unchecked[:] = True
        if n > 0 and self.resting_shortcut and not self.profiling:  # (stage timers: compiled)
            started = time.thread_time()
            if resting_steps(self._bodies, self._broad, self._vehicles.arrays, self._contacts, n):
                self.engine_cpu_seconds += time.thread_time() - started
                self._count_steps(n)
                return  # every body frozen or immovable: this call moved none
        if not (refreeze or new_second):
            b = self._bodies
            self._unchecked |= ~(b.frozen | b.immovable)  # the bodies this call moves
        counters = np.zeros(5, np.int64)
        sharing = self._sharing
        threads = self._solver_threads
        if self.measure_threads:
            threads = self._thread_choice.threads(threads, sharing)
        self.threads_in_use = threads
        done = 0
        wall = self._clock()
        while done < n:
            ctx = self.step_context(counters, threads)
            started = time.thread_time()
            steps, status = step_world(n - done, ctx)
            self.engine_cpu_seconds += time.thread_time() - started
            done += steps
            self._count_steps(steps)
            if status == GROW_PAIRS:
                self._grow_pairs()
            elif status == GROW_CONTACTS:
                self._grow_contacts()
            elif status == GROW_INDEX:
                # Indexes hold 8 cells per body slot, the most a body can touch.
                raise RuntimeError("octree index overflow: an index is smaller than 8 x bodies")
            else:
                assert status == DONE
        if done:
            self._departed[:] = False  # the newest contacts are these steps'
        wall = self._clock() - wall
        pairs = int(counters[STAT_PAIRS] + counters[STAT_TRIANGLES])
        self._sharing = would_share(n, int(counters[STAT_POINTS]), pairs)
        if self.measure_threads and self._solver_threads == 2 and sharing and self._sharing:
            self._thread_choice.record(threads, wall, int(counters[STAT_POINTS]) + pairs)
        for key, index in (("woken", STAT_WOKEN), ("frozen", STAT_FROZEN), ("pairs", STAT_PAIRS),
                           ("points", STAT_POINTS), ("triangles", STAT_TRIANGLES)):
            self.stats[key] += int(counters[index])

    def _count_steps(self, steps):
        """Advances step_count and time by `steps`. The time is the steps since the rate last
        changed (or the time was set) over the rate, not a sum batch by batch: 1/100 s is no
        binary fraction, and the sum's rounding had followed the batches (stepping in real time
        or as fast as possible gave other times and IMU readings)."""
        rate = self.settings["steps_per_second"]
        start_time, start_step, start_rate, left = self._timeline
        if rate != start_rate or left != (self.time, self.step_count):
            start_time, start_step = self.time, self.step_count  # another rate, or the time set
        self.step_count += steps
        self.time = start_time + (self.step_count - start_step) / rate
        self._timeline = (start_time, start_step, rate, (self.time, self.step_count))

    def step_context(self, counters, threads=None):
        """What step_world takes: this world's arrays and settings, `counters` for its
        statistics, `threads` for the contact solve (solver_threads when None; the octree's
        root fitted: step)."""
        return StepContext(self._bodies, self._hulls, self._parts, self._playground, self._vehicles.arrays,
                           self._broad, self._contacts, self._joints.arrays,
                           kernel_settings(self.settings, self.ground, specs.DEFAULT_GROUND,
                                           self._root, threads or self._solver_threads),
                           counters, self._stage_ns, self.profiling)

    # ------------------------------------------------------------------ internals
    def _active_slots(self):
        return self._current_layout().slots

    def _current_layout(self):
        if self._layout is None or self._layout.version != self.layout_version:
            active = self._bodies.active
            slots = np.nonzero(active)[0]
            rows = slice(0, len(slots)) if len(slots) == 0 or slots[-1] == len(slots) - 1 else slots
            names = tuple(self._names[s] for s in slots.tolist())
            row_of_slot = np.cumsum(active) - 1
            row_of_slot[~active] = -1
            compound_rows = np.nonzero(self._bodies.shape[slots] == shapes.COMPOUND)[0]
            centres = np.array([self._solids[slot][1].compound.centre for slot in slots[compound_rows].tolist()],
                               float).reshape(-1, 3)
            for array in (slots, row_of_slot, compound_rows, centres):
                array.flags.writeable = False  # shared by every caller until the next change
            self._layout = Layout(self.layout_version, slots, rows, names,
                                  tuple(name for name in names if name in self._vehicles), row_of_slot,
                                  compound_rows, centres)
        return self._layout

    def _slot(self, name):
        try:
            return self._slots[name]
        except (KeyError, TypeError):
            raise KeyError(f"no body named {name!r}") from None

    def _generate_name(self, prefix):
        while True:
            self._generated += 1
            name = f"{prefix}_{self._generated}"
            if name not in self._slots:
                return name

    def _set_fields(self, slot, body, mass):
        """Material, flags and velocities from a validated (partial) spec, and the mass arrays
        from `mass` (specs.MassProperties, computed for the body's current solid)."""
        b = self._bodies
        for key in ("elasticity", "static_friction", "dynamic_friction", "immovable",
                    "allow_freezing", "collides"):
            if key in body:
                getattr(b, key)[slot] = body[key]
        if "linear_velocity" in body:
            b.velocity[slot, :3] = body["linear_velocity"]
        if "angular_velocity" in body:
            b.velocity[slot, 3:] = body["angular_velocity"]
        b.mass[slot], b.inv_mass[slot], b.inv_inertia[slot] = mass
        if b.immovable[slot]:
            b.velocity[slot] = 0.0
        if body.get("frozen", False) and not b.immovable[slot]:
            b.frozen[slot] = True
            b.velocity[slot] = 0.0
        if b.static_indexed[slot]:
            # Whatever changed, its static-index entry may no longer match.
            b.static_indexed[slot] = False
            self._broad.stale[0] += 1

    def _set_solid(self, slot, name, solid):
        """The body's shape from a shapes.Solid (the hull and parts tables follow a convex or
        compound body's)."""
        b = self._bodies
        old = self._solids[slot][1] if self._solids[slot] is not None else None
        self._solids[slot] = (name, solid)
        b.dimensions[slot] = solid.dimensions
        b.half_extents[slot] = shapes.half_extents(int(b.shape[slot]), solid.dimensions)
        if (old is not None and (old.hull is not None or old.compound is not None)
                or solid.hull is not None or solid.compound is not None):
            self._pack_shapes()

    def _pack_shapes(self):
        """The hull table (each convex body's at its slot, then the convex parts') and the parts
        table of the compound bodies, from the solids."""
        solids = [entry[1] if entry is not None else None for entry in self._solids]
        self._parts, part_hulls = shapes.compound.pack_parts(
            [s.compound if s is not None else None for s in solids], len(solids))
        self._hulls = shapes.convex.pack_hulls([s.hull if s is not None else None for s in solids] + part_hulls)

    def _frame_to_centre(self, slot):
        """The world vector from the body's frame to its centre of mass, which a compound's parts
        put off its frame's origin; None for the other shapes (their frames are their centres)."""
        compound = self._solids[slot][1].compound
        if compound is None:
            return None
        r = np.empty((3, 3))
        quat_to_matrix(self._bodies.orientation[slot], r)
        return r @ compound.centre

    def _centre_of_mass(self, slot, frame_position):
        """Where the body's centre of mass is with its frame at `frame_position` (world)."""
        offset = self._frame_to_centre(slot)
        return frame_position if offset is None else np.asarray(frame_position, float) + offset

    def _frame_position(self, slot):
        """Where the body's frame is (world)."""
        offset = self._frame_to_centre(slot)
        position = self._bodies.position[slot]
        return position.copy() if offset is None else position - offset

    def _centre_velocity(self, slot, frame_velocity):
        """The velocity of the body's centre of mass when its frame's origin moves at
        `frame_velocity` (the body turning at its angular velocity)."""
        offset = self._frame_to_centre(slot)
        return frame_velocity if offset is None else frame_velocity + np.cross(self._bodies.velocity[slot, 3:], offset)

    def _frame_velocity(self, slot):
        """The velocity of the body's frame's origin (world)."""
        offset = self._frame_to_centre(slot)
        velocity = self._bodies.velocity[slot, :3]
        return velocity.copy() if offset is None else velocity - np.cross(self._bodies.velocity[slot, 3:], offset)

    def _shape(self, slot):
        """The body's shape: name, module, dimensions and their spec keys (`size: [...]`)."""
        name, solid = self._solids[slot]
        return BodyShape(name, shapes.SHAPES[name].module, solid.dimensions, solid.fields)

    def _forget_contacts(self, slots):
        """Drops the warm-start impulses of the newest contacts of slots that are edited or
        removed: they belong to geometry that no longer exists."""
        b = self._bodies
        changed = np.zeros(len(b.active), dtype=bool)
        changed[slots] = True
        c = newest_contacts(self._contacts)
        n = int(c.count[0])
        body_b = c.body_b[:n]
        involved = changed[c.body_a[:n]] | ((body_b >= 0) & changed[np.maximum(body_b, 0)])
        # Every impulse the warm start carries over (contact.warm_start_from), the shock
        # propagation's too: left, a body in a removed one's slot started from its support.
        for impulses in (c.impulse, c.friction_world, c.support_impulse, c.support_friction_world):
            impulses[:n][involved] = 0.0

    def _wake(self, slot):
        self._broad.stale[0] += wake_body(self._bodies, slot)

    def _wake_touching(self, slots):
        """Wakes the frozen bodies (other than `slots`) whose bounds touch those of `slots`
        (what rests on them or leans on them), before they move, change or go."""
        b = self._bodies
        changed = np.zeros(len(b.active), dtype=bool)
        changed[slots] = True
        sleepers = np.nonzero(b.active & b.frozen & ~changed)[0]
        if len(sleepers) == 0:
            return
        lo, hi = body_bounds(b, slots)
        s_lo, s_hi = body_bounds(b, sleepers)
        touched = np.zeros(len(sleepers), dtype=bool)
        rows = max(1, 4_000_000 // len(sleepers))  # pair tests per pass, bounding the memory
        for k in range(0, len(slots), rows):
            overlap = np.all((s_lo[None] <= hi[k:k + rows, None] + CONTACT_MARGIN)
                             & (lo[k:k + rows, None] - CONTACT_MARGIN <= s_hi[None]), axis=2)
            touched |= overlap.any(axis=0)
        for other in sleepers[touched]:
            self._wake(other)

    def _check_root(self, slot):
        if self._root is None:
            return
        b = self._bodies
        lo, hi = body_bounds(b, [slot])
        root_min, size = self._root
        if np.any(lo < root_min) or np.any(hi > root_min + size):
            self._root = None

    def _fit_root(self):
        """Fits the octree's root cube around the bodies and the playground (clamping keeps
        bodies that later leave it correct, only less pruned), indexes the playground in it and
        has the static index rebuilt in it."""
        slots = self._active_slots()
        b, mesh = self._bodies, self._playground
        lows, highs = [np.zeros((1, 3))], [np.zeros((1, 3))]
        if len(slots):
            lo, hi = body_bounds(b, slots)
            lows.append(lo)
            highs.append(hi)
        if len(mesh.triangles):
            lows.append(mesh.aabb_min)
            highs.append(mesh.aabb_max)
        lo, hi = np.concatenate(lows).min(axis=0), np.concatenate(highs).max(axis=0)
        size = max(float(np.max(hi - lo)) + 2.0 * ROOT_PADDING, MIN_ROOT_SIZE)
        self._root = (0.5 * (lo + hi) - 0.5 * size, size)
        if not index_playground(mesh, self._root[0], size, self.settings["octree_depth"]):
            raise RuntimeError("octree index overflow: the playground index is too small")
        self._broad.force_rebuild[0] = True

    def _grow(self, capacity):
        old = len(self._names)
        self._bodies = grow_bodies(self._bodies, capacity)
        self._names.extend([None] * (capacity - old))
        self._generations = np.concatenate([self._generations, np.zeros(capacity - old, np.int64)])
        self._solids.extend([None] * (capacity - old))
        self._unchecked = np.concatenate([self._unchecked, np.ones(capacity - old, dtype=bool)])
        self._departed = np.concatenate([self._departed, np.zeros(capacity - old, dtype=bool)])
        self.layout_version += 1  # row_of_slot covers every slot
        for slot in range(old, capacity):
            heapq.heappush(self._free, slot)
        self._broad = allocate_broad_phase(capacity, max(len(self._broad.pair_a), 4 * capacity))
        self._bodies.static_indexed[:] = False  # the new static index starts empty

    def _grow_pairs(self):
        """Doubles both pair buffers (body pairs and playground pairs); either may have filled."""
        size = 2 * len(self._broad.pair_a)
        self._broad = self._broad._replace(
            pair_a=np.zeros(size, np.int64), pair_b=np.zeros(size, np.int64),
            playground_body=np.zeros(size, np.int64), playground_triangle=np.zeros(size, np.int64))

    def _grow_contacts(self):
        newest = newest_contacts(self._contacts)
        points, manifolds = 2 * len(newest.body_a), 2 * len(newest.manifold_start)
        grown = allocate_contact_buffers(points, manifolds)
        kept = newest_contacts(grown)  # the warm start's source
        for field in newest._fields:
            if field.startswith("table_"):
                continue
            old, new = getattr(newest, field), getattr(kept, field)
            new[:len(old)] = old
        index_manifolds(kept)
        self._contacts = grown


def joint_frame(axis):
    """A rotation whose x column is the unit `axis` (the other two: any right-handed pair across
    it, chosen from the world axis least along it)."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    across = np.cross(axis, helper)
    across /= np.linalg.norm(across)
    return np.column_stack([axis, across, np.cross(axis, across)])
