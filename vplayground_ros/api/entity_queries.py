"""The entity queries of simulation_interfaces beyond ~/get_entity: every entity with its
category and world bounds (GetEntities, GetEntitiesStates and their filters), one entity's
state, category and bounds (GetEntityState, GetEntityInfo, GetEntityBounds).

Categories: a vehicle is a robot, an immovable body a static object, any other body or a
sensor an object. Bounds: the box around the entity in its own frame (descriptions.frame_box);
what the bounds filters test, in the world, is the axis-aligned box around the engine's box of
each body, centred on its pose (larger than that for a shape whose frame is not its centre).
"""
from collections import namedtuple

import numpy as np

from ..physics import specs
from ..physics.math3d import quaternions_to_matrices
from ..urdf_robots import robot_spec
from .descriptions import SENSOR_SIZE, describe, describe_robot, describe_sensor, with_wheels
from .name_filter import match_names
from .results import FAILED, FEATURE_UNSUPPORTED, NOT_FOUND, RequestError

OBJECT, ROBOT, STATIC_OBJECT = 0, 1, 5  # simulation_interfaces EntityCategory
BOUNDS_EMPTY, BOUNDS_BOX, BOUNDS_CONVEX_HULL, BOUNDS_SPHERE = 0, 1, 2, 3  # simulation_interfaces Bounds

# Every entity, in ~/get_entities' order (the bodies in the order of ~/bodies/poses, then the
# sensors): names, categories (N,), world-frame bounding boxes low and high (N, 3), positions
# and quaternions (x y z w) (N, 3) and (N, 4), linear and angular velocities (N, 3).
EntityTable = namedtuple("EntityTable", "names categories low high positions quaternions linear angular time")


def entity_table(world):
    """The EntityTable of `world` now (run on the simulation thread)."""
    state = world.state()
    names = world.body_names()
    vehicles = set(world.vehicle_names())
    vehicle_rows = [k for k, name in enumerate(names) if name in vehicles]
    categories = np.where(state["immovable"], STATIC_OBJECT, OBJECT)
    categories[vehicle_rows] = ROBOT
    half = 0.5 * state["sizes"]
    for k in vehicle_rows:  # its wheels too, as its bounds have them
        low, high = with_wheels(world.vehicle(names[k]), -half[k], half[k])
        half[k] = np.maximum(-low, high)
    rotations = quaternions_to_matrices(state["quaternions"])
    reach = np.einsum("nij,nj->ni", np.abs(rotations), half)
    positions, quaternions = state["positions"], state["quaternions"]
    linear, angular = state["linear_velocities"], state["angular_velocities"]
    present = set(names)
    sensors = [describe_sensor(world, s) for s in world.sensor_specs
               if s["parent"] == "world" or s["parent"] in present]
    if sensors:
        names = names + [s["name"] for s in sensors]
        categories = np.concatenate([categories, np.full(len(sensors), OBJECT)])
        positions = np.vstack([positions, [s["pose"]["position"] for s in sensors]])
        quaternions = np.vstack([quaternions, [s["pose"]["orientation"] for s in sensors]])
        reach = np.vstack([reach, np.full((len(sensors), 3), 0.5 * SENSOR_SIZE)])
        linear = np.vstack([linear, [s["twist"]["linear"] for s in sensors]])
        angular = np.vstack([angular, [s["twist"]["angular"] for s in sensors]])
    low, high = positions - reach, positions + reach
    if world.robot_specs:  # each URDF robot too: its root's state, the box around its links
        rows = {name: k for k, name in enumerate(names)}
        links = [[rows[body] for body in robot["bodies"]] for robot in world.robot_specs]
        roots = [link[0] for link in links]
        names = names + [robot["name"] for robot in world.robot_specs]
        categories = np.concatenate([categories, np.full(len(links), ROBOT)])
        low = np.vstack([low, [low[link].min(axis=0) for link in links]])
        high = np.vstack([high, [high[link].max(axis=0) for link in links]])
        positions, quaternions = np.vstack([positions, positions[roots]]), np.vstack([quaternions, quaternions[roots]])
        linear, angular = np.vstack([linear, linear[roots]]), np.vstack([angular, angular[roots]])
    return EntityTable(names, categories, low, high, positions, quaternions, linear, angular, world.time)


def filtered(table, pattern="", categories=(), tags=(), bounds_type=BOUNDS_EMPTY, points=()):
    """Rows of `table` that simulation_interfaces EntityFilters select: a name matching the
    regular expression `pattern` (all when empty), a category among `categories` (all when
    none), bounds overlapping the filter's (a box: two corners; a sphere: centre and radius
    as the second point's x). Tags and convex-hull bounds answer FEATURE_UNSUPPORTED."""
    if tags:
        raise RequestError(FEATURE_UNSUPPORTED, "filters.tags: entities have no tags here (ENTITY_TAGS is not "
                                                "among get_simulator_features)")
    keep = np.ones(len(table.names), bool)
    if pattern:
        if not isinstance(pattern, str) or len(pattern) > 1000:
            raise RequestError(FAILED, "filters.filter: expected a regular expression of at most 1000 characters")
        matched = set(match_names(pattern, table.names, what="filters.filter"))
        keep &= np.array([name in matched for name in table.names], bool)
    if len(categories):
        keep &= np.isin(table.categories, list(categories))
    if bounds_type != BOUNDS_EMPTY:
        keep &= overlapping(table, bounds_type, points)
    return np.nonzero(keep)[0]


def overlapping(table, bounds_type, points):
    """Which rows' world boxes overlap the filter bounds."""
    try:
        points = np.array([specs.vector(p, "filters.bounds.points", 3) for p in points], float).reshape(-1, 3)
    except specs.SpecError as error:
        raise RequestError(FAILED, str(error)) from None
    if bounds_type == BOUNDS_BOX:
        if len(points) != 2:
            raise RequestError(FAILED, f"filters.bounds: a TYPE_BOX has 2 points (opposite corners), got {len(points)}")
        low, high = points.min(axis=0), points.max(axis=0)
        return np.all((table.low <= high) & (table.high >= low), axis=1)
    if bounds_type == BOUNDS_SPHERE:
        if len(points) != 2 or points[1, 0] < 0.0:
            raise RequestError(FAILED, "filters.bounds: a TYPE_SPHERE has 2 points, the centre and then the radius "
                                       "as x (>= 0)")
        nearest = np.clip(points[0], table.low, table.high)
        return np.sum((nearest - points[0]) ** 2, axis=1) <= points[1, 0] ** 2
    if bounds_type == BOUNDS_CONVEX_HULL:
        raise RequestError(FEATURE_UNSUPPORTED, "filters.bounds: TYPE_CONVEX_HULL is not supported (ENTITY_BOUNDS_CONVEX "
                                                "is not among get_simulator_features): TYPE_BOX or TYPE_SPHERE")
    raise RequestError(FAILED, f"filters.bounds.type: {bounds_type} is none of 0 EMPTY, 1 BOX, 2 CONVEX_HULL, 3 SPHERE")


class QueryRequests:
    """Requests' entity queries (see requests.py for the state they share)."""

    def entities_filtered(self, pattern="", categories=(), tags=(), bounds_type=BOUNDS_EMPTY, points=()):
        """(EntityTable, the selected rows) of simulation_interfaces EntityFilters. The regular
        expression is matched here, off the simulation thread, bounded in time."""
        table = self.sim.call(entity_table)
        return table, filtered(table, pattern, categories, tags, bounds_type, points)

    def entity(self, name):
        """describe() of a body or vehicle, describe_sensor() of a sensor, with `time`; NOT_FOUND."""
        if not isinstance(name, str):
            raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")

        def read(world):
            sensor = next((s for s in world.sensor_specs if s["name"] == name), None)
            if sensor is not None and (sensor["parent"] == "world" or sensor["parent"] in world.body_names()):
                return {**describe_sensor(world, sensor), "time": world.time}
            robot = robot_spec(world, name)
            if robot is not None:
                return {**describe_robot(world, robot), "time": world.time}
            if name not in world.body_names():
                raise RequestError(NOT_FOUND, f"no entity named {specs.quote(name)}")
            return {**describe(world, name), "time": world.time}
        return self.sim.call(read)


def category_of(description):
    """EntityCategory of a describe() or describe_sensor() result."""
    return {"vehicle": ROBOT, "robot": ROBOT, "immovable": STATIC_OBJECT}.get(description["category"], OBJECT)
