"""Vehicles (SPEC 5): a chassis body on four spring-damper wheels that touch the world by ray
casts, driven by a Twist controller, all inside the compiled step.

Per wheel and step: a ray along the chassis' down axis from the mount, spring_length + radius
long. A hit compresses the spring: force stiffness x compression + damper x compression rate,
along the chassis' up axis at the mount (the chassis sways on it). The tyre's force, in the plane
perpendicular to the spring, goes straight to the chassis at the contact point:
- drive engine_power x power_gain x throttle along the wheel's heading, brake up to brake_power
  against the rolling direction, and whatever stops sideways slip;
- limited by a friction circle: up to static_friction x load the tyre grips; asked for more, it
  slides with dynamic_friction x load, each the geometric mean of the tyre's and the surface's
  (the ground's and playground's material, or the body's it stands on), as for any pair.
The tyre's slip is the wheel's speed over the ground, from the chassis' translation and yaw;
its pitch and roll on the springs sway the body over the wheels (tyre_velocity).
What is hit (a box) gets the opposite force. Wheels roll at v / r and keep a spin angle.

The car's mass is the chassis' plus its wheels' (one rigid body); every force above acts on it.
The Twist controller turns a wanted forward speed and yaw rate into throttle, brake and steering:
a proportional loop on speed with the throttles that hold the car against gravity along its
heading and against its resistance (what the throttle failed to add to the speed) fed forward
(braking as well while it moves against the wanted direction, and to stop), the bicycle
model tan(steer) = yaw_rate x wheelbase / speed plus yaw-rate feedback, `max_steer` limiting
that centre-line angle, and Ackermann angles per steered wheel from the mounts (the inner wheel
turns further, towards the same centre); a command older than its timeout means stop. A car
with a command to follow is kept from freezing.
"""
from collections import namedtuple

import numpy as np
from numba import njit

from .ids import wheel_query
from .raycast import NO_HIT, cast_ray

WHEELS = 4

VehicleArrays = namedtuple("VehicleArrays", [
    "active", "chassis",          # (V,) bool, body slot of the chassis
    "engine_power", "brake_power", "max_steer", "max_steer_rate",  # (V,) N, N per wheel, rad, rad/s
    "wheelbase", "rear_axle",     # (V,) m along the chassis x axis (from the mounts)
    # Wheels (V, 4): mount (V, 4, 3) in the chassis frame, then the SPEC 3 wheel properties.
    "mount", "radius", "power_gain", "steered", "stiffness", "damper", "spring_length",
    "static_friction", "dynamic_friction",
    # Command (Twist) and controller state (V,).
    "command_speed", "command_yaw_rate", "command_age", "command_timeout",
    "resistance",      # (V,) throttle: what the car meets beyond gravity, as the throttle it takes
    "previous_speed",  # (V,) m/s: the forward speed the last step started with
    "tyres_held",      # (V,) bool: last step every driven wheel stood on something, no tyre slid
    "steer_correction",  # (V,) rad: the yaw-rate loop's steer beyond the bicycle model's
    "throttle", "brake", "steer",  # (V,) applied: throttle -1..1, brake 0..1, steer rad
    # Wheel state (V, 4), for the node's joint states and markers.
    "steer_angle", "steer_rate", "spin_angle", "spin_rate", "compression", "compression_rate",
    "in_contact", "contact_point", "contact_normal",  # (V, 4, 3)
])

# The speed loop is proportional, with what gravity and the car's resistance take fed forward
# (control). Its gain sets how fast a command is reached: 1.3 throttle per m/s gives the default
# car (its engine 4.7 m/s^2 at full throttle) the rise the PI loop it replaces had (10-90 % of a
# 0.5-1 m/s step in 0.36 s), without the overshoot.
SPEED_GAIN = 1.3
RESISTANCE_RATE = 4.0     # 1/s: how fast the resistance estimate follows what the car lacks
# The yaw-rate loop's share of its error taken out in a step. The yaw rate answers the steer
# within a step (the tyres cancel side slip in one), by speed / wheelbase per radian, so the
# loop's steer per rad/s of error is this x wheelbase / speed: a fixed 0.5 rad per rad/s had
# passed the whole error back and more above 5.2 m/s, and the steer flipped sign every step.
YAW_LOOP_SHARE = 0.5
YAW_LOOP_SPEED = 0.5      # m/s: slower than this the loop rests (the bicycle model is exact there)
STOP_SPEED = 0.05         # m/s: slower than this the car counts as standing (may reverse)
TYRE_SWEEPS = 4           # passes over the four tyres a step (drive_vehicles)


def allocate_vehicles(capacity):
    f = lambda *shape: np.zeros((capacity,) + shape)  # noqa: E731
    return VehicleArrays(
        active=np.zeros(capacity, np.bool_), chassis=np.zeros(capacity, np.int64),
        engine_power=f(), brake_power=f(), max_steer=f(), max_steer_rate=f(), wheelbase=f(), rear_axle=f(),
        mount=f(WHEELS, 3), radius=f(WHEELS), power_gain=f(WHEELS),
        steered=np.zeros((capacity, WHEELS), np.bool_), stiffness=f(WHEELS), damper=f(WHEELS),
        spring_length=f(WHEELS), static_friction=f(WHEELS), dynamic_friction=f(WHEELS),
        command_speed=f(), command_yaw_rate=f(), command_age=f(), command_timeout=f(),
        resistance=f(), previous_speed=f(), tyres_held=np.zeros(capacity, np.bool_), steer_correction=f(),
        throttle=f(), brake=f(), steer=f(), steer_angle=f(WHEELS), steer_rate=f(WHEELS), spin_angle=f(WHEELS), spin_rate=f(WHEELS), compression=f(WHEELS),
        compression_rate=f(WHEELS), in_contact=np.zeros((capacity, WHEELS), np.bool_), contact_point=f(WHEELS, 3),
        contact_normal=f(WHEELS, 3))


def grow_vehicles(vehicles, capacity):
    grown = allocate_vehicles(capacity)
    n = len(vehicles.active)
    for field, old in zip(VehicleArrays._fields, vehicles):
        getattr(grown, field)[:n] = old
    return grown


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def control(vehicles, v, speed, yaw_rate, hold, downhill, full_throttle, dt):
    """The Twist controller of vehicle v: sets throttle, brake and steer from its command.
    `hold` is the throttle that balances gravity along the car's heading (fed forward: on a
    1:4 ramp half the engine, which a PI loop alone found only after the car rolled back),
    `downhill` the speed gravity adds along it this step, `full_throttle` the acceleration
    (m/s^2) full throttle gives through the driven wheels."""
    vehicles.command_age[v] += dt
    if vehicles.command_age[v] > vehicles.command_timeout[v]:
        vehicles.command_speed[v] = 0.0
        vehicles.command_yaw_rate[v] = 0.0
    target = vehicles.command_speed[v]
    # The resistance (the tyres' scrub in a turn, a pile pushed) is what the last step's throttle
    # and gravity should have added to the speed and did not, read while the tyres held (every
    # driven wheel on something, none sliding: more throttle does not help a tyre that slides)
    # and no brake acted (its force is the tyres' to find), and fed forward as the hold is. It
    # replaces the speed loop's integral, which on flat ground, with nothing to hold, had to give
    # back all it gathered while the car sped up: 7-9 % over a 0.5-1 m/s step, 2-3 % over 3 m/s,
    # 3.6 s to settle. A step's reading counts for at most the whole engine: a speed set by hand
    # (~/edit) or a crash's jolt moves it by a few per cent.
    if full_throttle > 0.0 and vehicles.brake[v] == 0.0 and vehicles.tyres_held[v]:
        expected = full_throttle * vehicles.throttle[v] * dt + downhill
        lacking = (expected - (speed - vehicles.previous_speed[v])) / (full_throttle * dt)
        vehicles.resistance[v] += RESISTANCE_RATE * dt * (min(max(lacking, -1.0), 1.0) - vehicles.resistance[v])
    vehicles.previous_speed[v] = speed
    throttle, brake = 0.0, 0.0
    if target == 0.0:  # told to stop: full brakes (limited by the tyres' grip)
        brake = 1.0
        vehicles.resistance[v] = 0.0  # the next start meets its own
    else:
        wanted = hold + vehicles.resistance[v] + SPEED_GAIN * (target - speed)
        throttle = min(max(wanted, -1.0), 1.0)  # negative: the engine holds the car back
        if target * speed < 0.0 and abs(speed) > STOP_SPEED:
            # Going the wrong way (a reversed command, rolling back down a slope): brakes too,
            # with the throttle already pulling towards the target (braking alone, the car
            # stopped, let go and rolled back again, and a slow command never climbed a ramp).
            brake = 1.0
    # The command's curvature (yaw rate per metre) is what the car follows, at whatever speed it
    # has: a planner's path is its shape. (The speed the car had, held at 0.5 m/s or more, had
    # turned a 0.25 m/s command for a 5 m circle round one of 10 m.) Told to turn without
    # moving, the wheels steer to their limit that way: a turn in place an Ackermann car cannot.
    wanted_yaw, wheelbase, limit = vehicles.command_yaw_rate[v], vehicles.wheelbase[v], vehicles.max_steer[v]
    if target != 0.0:
        curvature = wanted_yaw / target
        model = np.arctan(curvature * wheelbase)
    else:
        curvature, model = 0.0, (limit if wanted_yaw > 0.0 else (-limit if wanted_yaw < 0.0 else 0.0))
    # The yaw-rate loop adds what the tyres' slip takes off, YAW_LOOP_SHARE of the error a step
    # (integrating: no error left in a steady turn). The steering turns at most max_steer_rate
    # (an actuator: it had snapped to any angle within a step) within its reach; the loop keeps
    # only what the steering could follow (no wind-up while it turns).
    yaw_loop_runs = abs(speed) > YAW_LOOP_SPEED and target != 0.0
    correction = 0.0
    if yaw_loop_runs:
        error = curvature * speed - yaw_rate
        correction = vehicles.steer_correction[v] + YAW_LOOP_SHARE * error * wheelbase / speed
    reach = vehicles.max_steer_rate[v] * dt
    previous = vehicles.steer[v]
    # The rate first, then the reach: a max_steer lowered mid-turn holds at once, left or right
    # alike (the other order had held a left turn and let a right one unwind at the rate).
    steer = min(max(min(max(model + correction, previous - reach), previous + reach), -limit), limit)
    vehicles.steer_correction[v] = steer - model if yaw_loop_runs else 0.0
    vehicles.throttle[v] = throttle
    vehicles.brake[v] = brake
    vehicles.steer[v] = steer


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def ackermann(vehicles, v, w):
    """Steer angle of wheel w: every steered wheel points square to the line from it to one
    turning centre, on the rear axle line at wheelbase / tan(steer) to the left (REP-103)."""
    steer = vehicles.steer[v]
    if not vehicles.steered[v, w]:
        return 0.0
    if abs(steer) < 1e-6:
        return steer
    # max_steer limits the centre-line angle (control): the turning radius a planner takes,
    # wheelbase / tan(max_steer). Clamping the inner wheel as well pointed the two front wheels
    # at different centres and turned 13 % short of a command within reach.
    centre = vehicles.wheelbase[v] / np.tan(steer)
    return np.arctan((vehicles.mount[v, w, 0] - vehicles.rear_axle[v]) / (centre - vehicles.mount[v, w, 1]))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def drive_vehicles(vehicles, bodies, hulls, parts, broad, playground, settings):
    """Controller, wheel ray casts, suspension and tyre forces of every vehicle for one step,
    applied as impulses to the chassis (and the opposite to any box a wheel stands on). The four
    springs are evaluated on the same state, then applied; the tyres follow one by one, each
    seeing what the others already did (so four wheels never cancel the same slip four times),
    TYRE_SWEEPS times over. They hold against this step's gravity too (tyre_velocity's `fall`),
    which is added after them: braked tyres that saw only the velocity before it let a car on a
    slope creep downhill at g sin(slope) dt (0.013 m/s at 0.15 rad and 128 steps/s)."""
    dt = settings.dt
    fall = (settings.gravity[0] * dt, settings.gravity[1] * dt, settings.gravity[2] * dt)
    if not np.any(vehicles.active):
        return  # nothing to drive: no per-body work (a world at rest costs next to nothing)
    position, velocity = bodies.position, bodies.velocity
    broad.stamp[:] = -1  # the rays' query ids repeat every step
    for v in range(len(vehicles.active)):
        if not vehicles.active[v]:
            continue
        c = vehicles.chassis[v]
        if not np.isfinite(bodies.speculative_reach[c]) or not np.isfinite(position[c, 0] + position[c, 1] + position[c, 2]):
            continue  # quarantined until the World removes it
        r = bodies.rotation[c]
        forward, left, up = (r[0, 0], r[1, 0], r[2, 0]), (r[0, 1], r[1, 1], r[2, 1]), (r[0, 2], r[1, 2], r[2, 2])
        down = (-up[0], -up[1], -up[2])
        speed = velocity[c, 0] * forward[0] + velocity[c, 1] * forward[1] + velocity[c, 2] * forward[2]
        yaw_rate = velocity[c, 3] * up[0] + velocity[c, 4] * up[1] + velocity[c, 5] * up[2]
        downhill = fall[0] * forward[0] + fall[1] * forward[1] + fall[2] * forward[2]  # m/s this step
        # What full throttle adds to the speed through the driven wheels (m/s^2), and the
        # throttle that holds the car against gravity (with power gains not summing to 1, a
        # four-wheel drive's, a hold from engine_power alone was off by their sum: +21 % at 1 m/s
        # up a 1:4 ramp, which the resistance, read against the throttle applied, cannot see).
        full_throttle = vehicles.engine_power[v] * vehicles.power_gain[v].sum() / bodies.mass[c]
        hold = -downhill / (dt * full_throttle) if full_throttle > 0.0 else 0.0
        control(vehicles, v, speed, yaw_rate, hold, downhill, full_throttle, dt)
        if vehicles.command_speed[v] != 0.0 or vehicles.command_yaw_rate[v] != 0.0:
            bodies.freeze_timer[c] = 0.0  # a car with a command to follow does not freeze
        loads = np.zeros(WHEELS)
        mounts = np.zeros((WHEELS, 3))  # in the world
        hits = np.zeros(WHEELS, np.int64)  # what each wheel stands on (slot, GROUND, PLAYGROUND)
        for w in range(WHEELS):  # suspension: ray casts and spring loads on the step's state
            angle = ackermann(vehicles, v, w)
            vehicles.steer_rate[v, w] = (angle - vehicles.steer_angle[v, w]) / dt
            vehicles.steer_angle[v, w] = angle
            m = vehicles.mount[v, w]
            mount = (position[c, 0] + r[0, 0] * m[0] + r[0, 1] * m[1] + r[0, 2] * m[2],
                     position[c, 1] + r[1, 0] * m[0] + r[1, 1] * m[1] + r[1, 2] * m[2],
                     position[c, 2] + r[2, 0] * m[0] + r[2, 1] * m[1] + r[2, 2] * m[2])
            reach = vehicles.spring_length[v, w] + vehicles.radius[v, w]
            t, hit, normal = cast_ray(mount, down, reach, c, wheel_query(v, w, WHEELS),
                                     bodies, hulls, parts, broad, playground, settings)
            vehicles.in_contact[v, w] = t != NO_HIT
            if t == NO_HIT:
                vehicles.compression[v, w] = vehicles.compression_rate[v, w] = 0.0
                continue
            hits[w] = hit
            for e in range(3):
                vehicles.contact_point[v, w, e] = mount[e] + t * down[e]
                vehicles.contact_normal[v, w, e] = normal[e]
            compression = min(reach - t, vehicles.spring_length[v, w])
            vehicles.compression[v, w] = compression
            rel = contact_velocity(bodies, c, hit, vehicles.contact_point[v, w])
            compression_rate = -(rel[0] * up[0] + rel[1] * up[1] + rel[2] * up[2])
            vehicles.compression_rate[v, w] = compression_rate
            for e in range(3):
                mounts[w, e] = mount[e]
        # The springs and dampers act explicitly, on this step's compressions and rates, which
        # holds while stiffness dt^2 and damper dt stay small against 1 / lambda, lambda the
        # largest response of the wheels' mounts together to their pushes (each push moves the
        # other mounts too). Beyond it a light car (20 kg on the default damper) or a stiff
        # spring (1e7 N/m) bounced itself tens of metres high: there they act only as stiff as
        # the step integrates (MAX_DAMPING, MAX_SPRING).
        springy = largest_response(bodies, c, hits, mounts, vehicles.contact_point[v], vehicles.in_contact[v], up)
        for w in range(WHEELS):
            if not vehicles.in_contact[v, w]:
                continue
            stiffness, damper = vehicles.stiffness[v, w], vehicles.damper[v, w]
            if springy > 0.0:
                damper = min(damper, MAX_DAMPING / (springy * dt))
                stiffness = min(stiffness, MAX_SPRING / (springy * dt * dt))
            loads[w] = max(stiffness * vehicles.compression[v, w] + damper * vehicles.compression_rate[v, w], 0.0)
        for w in range(WHEELS):  # the springs push the chassis at the mounts, what is hit back
            if not vehicles.in_contact[v, w]:
                continue
            m = vehicles.mount[v, w]
            mount = (position[c, 0] + r[0, 0] * m[0] + r[0, 1] * m[1] + r[0, 2] * m[2],
                     position[c, 1] + r[1, 0] * m[0] + r[1, 1] * m[1] + r[1, 2] * m[2],
                     position[c, 2] + r[2, 0] * m[0] + r[2, 1] * m[1] + r[2, 2] * m[2])
            spring = loads[w] * dt
            push(bodies, c, mount, (spring * up[0], spring * up[1], spring * up[2]))
            if hits[w] >= 0:
                push(bodies, hits[w], vehicles.contact_point[v, w], (-spring * up[0], -spring * up[1], -spring * up[2]))
        # Tyres, in the plane perpendicular to the spring: each wheel's impulse is the total of
        # TYRE_SWEEPS sweeps over the four, each cancelling the slip the others left (a single
        # sweep left a fifth of a slope's pull: a braked car crept at 0.0026 m/s on 0.15 rad).
        applied = np.zeros((WHEELS, 2))  # (along the heading, sideways) so far
        grip = np.zeros((WHEELS, 2))  # static and dynamic friction of tyre and surface
        for w in range(WHEELS):
            surface_static, surface_dynamic = settings.ground_material[1], settings.ground_material[2]
            if hits[w] >= 0:
                surface_static, surface_dynamic = bodies.static_friction[hits[w]], bodies.dynamic_friction[hits[w]]
            grip[w, 0] = np.sqrt(vehicles.static_friction[v, w] * surface_static)
            grip[w, 1] = np.sqrt(vehicles.dynamic_friction[v, w] * surface_dynamic)
        frame = np.zeros((WHEELS, 2, 3))  # heading, side
        response = np.zeros((WHEELS, 2))
        held = True  # tyres_held: the drive went where control's reading of the resistance puts it
        for w in range(WHEELS):
            if not vehicles.in_contact[v, w]:
                vehicles.spin_angle[v, w] += vehicles.spin_rate[v, w] * dt
                held = held and vehicles.power_gain[v, w] == 0.0
                continue
            ca, sa = np.cos(vehicles.steer_angle[v, w]), np.sin(vehicles.steer_angle[v, w])
            heading = (ca * forward[0] + sa * left[0], ca * forward[1] + sa * left[1], ca * forward[2] + sa * left[2])
            side = (up[1] * heading[2] - up[2] * heading[1], up[2] * heading[0] - up[0] * heading[2],
                    up[0] * heading[1] - up[1] * heading[0])
            point = vehicles.contact_point[v, w]
            for e in range(3):
                frame[w, 0, e], frame[w, 1, e] = heading[e], side[e]
            response[w, 0] = tyre_response(bodies, c, point, heading, up) + point_response(bodies, hits[w], point, heading)
            response[w, 1] = tyre_response(bodies, c, point, side, up) + point_response(bodies, hits[w], point, side)
        for sweep in range(TYRE_SWEEPS):
            for w in range(WHEELS):
                if not vehicles.in_contact[v, w]:
                    continue
                k_long, k_side = response[w, 0], response[w, 1]
                if k_long <= 0.0 or k_side <= 0.0:
                    continue  # a frozen chassis on something static: nothing moves
                hit, point = hits[w], vehicles.contact_point[v, w]
                heading, side = frame[w, 0], frame[w, 1]
                rel = tyre_velocity(bodies, c, hit, point, up, fall)
                v_long = rel[0] * heading[0] + rel[1] * heading[1] + rel[2] * heading[2]
                v_side = rel[0] * side[0] + rel[1] * side[1] + rel[2] * side[2]
                if sweep == 0:
                    vehicles.spin_rate[v, w] = v_long / vehicles.radius[v, w]
                    vehicles.spin_angle[v, w] += vehicles.spin_rate[v, w] * dt
                drive = vehicles.engine_power[v] * vehicles.power_gain[v, w] * vehicles.throttle[v] * dt
                # The brake stops the rolling at most, never reverses it.
                brake = vehicles.brake_power[v] * vehicles.brake[v] * dt
                impulse_long = drive + min(max(applied[w, 0] - drive - v_long / k_long, -brake), brake)
                impulse_side = applied[w, 1] - v_side / k_side
                # Friction circle: the tyre grips up to static friction x load, and slides with
                # dynamic friction x load when more is asked of it; the tyre's and the surface's
                # coefficients combine as any pair's (SPEC 4: the geometric mean), so ice is ice.
                magnitude = np.sqrt(impulse_long ** 2 + impulse_side ** 2)
                if magnitude > grip[w, 0] * loads[w] * dt:
                    # (an earlier sweep may ask one tyre for what all four then share)
                    held = held and sweep < TYRE_SWEEPS - 1
                    scale = grip[w, 1] * loads[w] * dt / magnitude
                    impulse_long *= scale
                    impulse_side *= scale
                d_long, d_side = impulse_long - applied[w, 0], impulse_side - applied[w, 1]
                applied[w, 0], applied[w, 1] = impulse_long, impulse_side
                p = (d_long * heading[0] + d_side * side[0], d_long * heading[1] + d_side * side[1],
                     d_long * heading[2] + d_side * side[2])
                push(bodies, c, point, p)
                if hit >= 0:
                    push(bodies, hit, point, (-p[0], -p[1], -p[2]))
        vehicles.tyres_held[v] = held


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def contact_velocity(bodies, body, other, point):
    """Velocity of `body` at a world point relative to `other` (a slot, or static if < 0)."""
    vel, pos = bodies.velocity, bodies.position
    arm = (point[0] - pos[body, 0], point[1] - pos[body, 1], point[2] - pos[body, 2])
    vx = vel[body, 0] + vel[body, 4] * arm[2] - vel[body, 5] * arm[1]
    vy = vel[body, 1] + vel[body, 5] * arm[0] - vel[body, 3] * arm[2]
    vz = vel[body, 2] + vel[body, 3] * arm[1] - vel[body, 4] * arm[0]
    if other >= 0:
        arm = (point[0] - pos[other, 0], point[1] - pos[other, 1], point[2] - pos[other, 2])
        vx -= vel[other, 0] + vel[other, 4] * arm[2] - vel[other, 5] * arm[1]
        vy -= vel[other, 1] + vel[other, 5] * arm[0] - vel[other, 3] * arm[2]
        vz -= vel[other, 2] + vel[other, 3] * arm[1] - vel[other, 4] * arm[0]
    return vx, vy, vz


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def tyre_velocity(bodies, chassis, other, point, up, fall):
    """Velocity of a tyre over what it stands on, at its contact point: the chassis' translation
    and yaw (about `up`), relative to `other`, and what `fall` (gravity x dt, which the step adds
    to every awake body after the tyres) will add to it. The chassis' pitch and roll
    on its springs move the body over its wheels, not the wheels over the ground; counted as
    slip, they let the brakes hold the contact patches while the body swung back on them after a
    hard stop, and the car's centre rolled backwards at the pitch rate times its height (-0.2 m/s
    from 3 m/s)."""
    vx, vy, vz = contact_velocity(bodies, chassis, other, point)
    falls = (1.0 if bodies.awake[chassis] else 0.0) - (1.0 if other >= 0 and bodies.awake[other] else 0.0)
    vx, vy, vz = vx + falls * fall[0], vy + falls * fall[1], vz + falls * fall[2]
    w, pos = bodies.velocity[chassis], bodies.position[chassis]
    yaw = w[3] * up[0] + w[4] * up[1] + w[5] * up[2]
    sway = (w[3] - yaw * up[0], w[4] - yaw * up[1], w[5] - yaw * up[2])  # pitch and roll
    arm = (point[0] - pos[0], point[1] - pos[1], point[2] - pos[2])
    return (vx - (sway[1] * arm[2] - sway[2] * arm[1]), vy - (sway[2] * arm[0] - sway[0] * arm[2]),
            vz - (sway[0] * arm[1] - sway[1] * arm[0]))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def tyre_response(bodies, chassis, point, d, up):
    """1 / effective mass of the chassis for tyre_velocity along unit d at a world point: its
    mass, and its yaw (0 if it does not move)."""
    if not bodies.awake[chassis]:
        return 0.0
    inv_i, x = bodies.inv_inertia_world[chassis], bodies.position[chassis]
    arm = (point[0] - x[0], point[1] - x[1], point[2] - x[2])
    cx, cy, cz = arm[1] * d[2] - arm[2] * d[1], arm[2] * d[0] - arm[0] * d[2], arm[0] * d[1] - arm[1] * d[0]
    # The yaw rate an impulse along d gives, times the tyre velocity a yaw rate gives along d.
    yaw = (up[0] * (inv_i[0, 0] * cx + inv_i[0, 1] * cy + inv_i[0, 2] * cz)
           + up[1] * (inv_i[1, 0] * cx + inv_i[1, 1] * cy + inv_i[1, 2] * cz)
           + up[2] * (inv_i[2, 0] * cx + inv_i[2, 1] * cy + inv_i[2, 2] * cz))
    return bodies.solver_inv_mass[chassis] + yaw * (up[0] * cx + up[1] * cy + up[2] * cz)


# The explicit suspension's bounds (see drive_vehicles), in units of the step: damper dt lambda
# at most 1 (its impulse then at most stops the compression rate: the most a damper does, where
# more had reversed it, and a light car bounced higher each step), stiffness dt^2 lambda at most
# 1 (the one-wheel limit is 4 less twice the damper's, but four wheels on one chassis, 1e7 N/m
# on a 1,200 kg car, still rose without end at 2.9).
MAX_DAMPING = 1.0
MAX_SPRING = 1.0


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def largest_response(bodies, chassis, hits, mounts, points, touching, up):
    """The largest eigenvalue of the wheels' response matrix along `up`: entry (i, j) the
    velocity an impulse at wheel j's spring gives wheel i's (the chassis at the mounts, and a
    body that two wheels stand on at their contact points); power iteration on the 4 x 4."""
    response = np.zeros((WHEELS, WHEELS))
    for i in range(WHEELS):
        for j in range(WHEELS):
            if touching[i] and touching[j]:
                response[i, j] = (pair_response(bodies, chassis, mounts[i], mounts[j], up)
                                  + (pair_response(bodies, hits[i], points[i], points[j], up) if hits[i] == hits[j] else 0.0))
    vector = np.ones(WHEELS)
    value = 0.0
    for _ in range(16):
        product = response @ vector
        value = np.sqrt(product @ product)
        if value == 0.0:
            return 0.0
        vector = product / value
    return value


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def pair_response(bodies, body, at, pushed, d):
    """Velocity along unit d at world point `at` of `body` per unit impulse along d at world
    point `pushed` (0 if it does not move)."""
    if body < 0 or not bodies.awake[body]:
        return 0.0
    inv_i, x = bodies.inv_inertia_world[body], bodies.position[body]
    a = (at[0] - x[0], at[1] - x[1], at[2] - x[2])
    p = (pushed[0] - x[0], pushed[1] - x[1], pushed[2] - x[2])
    ax, ay, az = a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0]
    px, py, pz = p[1] * d[2] - p[2] * d[1], p[2] * d[0] - p[0] * d[2], p[0] * d[1] - p[1] * d[0]
    return bodies.solver_inv_mass[body] + (
        ax * (inv_i[0, 0] * px + inv_i[0, 1] * py + inv_i[0, 2] * pz)
        + ay * (inv_i[1, 0] * px + inv_i[1, 1] * py + inv_i[1, 2] * pz)
        + az * (inv_i[2, 0] * px + inv_i[2, 1] * py + inv_i[2, 2] * pz))


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def point_response(bodies, body, point, d):
    """1 / effective mass of `body` at a world point along unit d (0 if it does not move)."""
    return pair_response(bodies, body, point, point, d)


@njit(cache=True, nogil=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def push(bodies, body, point, p):
    """Impulse p at a world point on an awake body (others ignore it)."""
    if not bodies.awake[body]:
        return
    m, inv_i, x = bodies.solver_inv_mass[body], bodies.inv_inertia_world[body], bodies.position[body]
    arm = (point[0] - x[0], point[1] - x[1], point[2] - x[2])
    torque = (arm[1] * p[2] - arm[2] * p[1], arm[2] * p[0] - arm[0] * p[2], arm[0] * p[1] - arm[1] * p[0])
    for e in range(3):
        bodies.velocity[body, e] += p[e] * m
        bodies.velocity[body, 3 + e] += inv_i[e, 0] * torque[0] + inv_i[e, 1] * torque[1] + inv_i[e, 2] * torque[2]
