"""The World's vehicles: their validated specs by name and their rows in the arrays the vehicle
kernels (vehicle.py) drive. A vehicle's chassis is an ordinary body of the same name, which the
World owns; this registry holds what only a vehicle has (wheels, controller, commands)."""
import numpy as np

from . import specs
from .vehicle import allocate_vehicles, grow_vehicles

DEFAULT_COMMAND_TIMEOUT = 1.2  # s: SPEC 6.4 cmd_vel_timeout
VEHICLE_NUMBERS = ("engine_power", "brake_power", "max_steer", "max_steer_rate")  # spec key = array

# Kernel state that starts at zero for a new vehicle (a reused row must not inherit any) and
# again when a reset of the state restarts it.
RESET_FIELDS = ("command_speed", "command_yaw_rate", "command_age", "resistance", "previous_speed",
                "tyres_held", "steer_correction", "throttle",
                "brake", "steer", "steer_angle", "steer_rate", "spin_angle", "spin_rate", "compression",
                "compression_rate", "in_contact", "contact_point", "contact_normal")
WHEEL_FIELDS = (("radius", "radius"), ("power_gain", "power_gain"), ("steered", "steered"),
                ("stiffness", "spring_stiffness"), ("damper", "damper"),
                ("spring_length", "spring_length"), ("static_friction", "static_friction"),
                ("dynamic_friction", "dynamic_friction"))  # (array, spec key)


class VehicleRegistry:
    def __init__(self):
        self.arrays = allocate_vehicles(2)  # what the kernels take
        self._specs = {}  # name -> validated spec
        self._rows = {}   # name -> row of `arrays`

    def __contains__(self, name):
        return name in self._specs

    def add(self, name, vehicle, chassis_slot):
        """Registers a validated vehicle spec whose chassis body is `chassis_slot`."""
        rows = self.arrays
        free = np.nonzero(~rows.active)[0]
        if len(free) == 0:
            self.arrays = rows = grow_vehicles(rows, 2 * len(rows.active))
            free = np.nonzero(~rows.active)[0]
        row = int(free[0])
        rows.active[row], rows.chassis[row] = True, chassis_slot
        for key in VEHICLE_NUMBERS:
            getattr(rows, key)[row] = vehicle[key]
        self._load_wheels(row, vehicle["wheels"])
        self._start(row)
        self._specs[name] = {**vehicle, "name": name}
        self._rows[name] = row

    def restart(self, name):
        """The vehicle's command, controller and wheels as a new vehicle's: no command, the
        steering straight, nothing accumulated (its spec stays as edited)."""
        self._start(self._row(name))

    def _start(self, row):
        rows = self.arrays
        for field in RESET_FIELDS:
            getattr(rows, field)[row] = 0
        rows.command_timeout[row] = DEFAULT_COMMAND_TIMEOUT

    def remove(self, name):
        """Forgets a vehicle (its chassis body is the World's to free); no-op for a body."""
        if self._specs.pop(name, None) is not None:
            self.arrays.active[self._rows.pop(name)] = False

    def edit(self, name, fields):
        """Changes only the given vehicle keys: engine_power, brake_power, max_steer, max_steer_rate, and wheels
        as {index: {wheel keys}} (0-3: front-left, front-right, rear-left, rear-right)."""
        row = self._row(name)
        edit = specs.validate_vehicle_edit(fields, name)
        spec = self._specs[name]
        for key in VEHICLE_NUMBERS:
            if key in edit:
                spec[key] = edit[key]
                getattr(self.arrays, key)[row] = edit[key]
        for index, wheel in edit.get("wheels", {}).items():
            spec["wheels"][index] = {**spec["wheels"][index], **wheel}
        self._load_wheels(row, spec["wheels"])

    def drive(self, name, speed, yaw_rate, timeout):
        """Sets the Twist command (validated); returns whether it asks for motion."""
        row = self._row(name)
        speed = specs.number(speed, "speed", -specs.MAX_SPEED, specs.MAX_SPEED)
        yaw_rate = specs.number(yaw_rate, "yaw_rate", -specs.MAX_SPEED, specs.MAX_SPEED)
        timeout = specs.number(timeout, "timeout", 0.0, 1.0e6, low_open=True)
        rows = self.arrays
        rows.command_speed[row], rows.command_yaw_rate[row] = speed, yaw_rate
        rows.command_age[row], rows.command_timeout[row] = 0.0, timeout
        return bool(speed or yaw_rate)

    def state(self, name):
        """Applied controls and per-wheel state (arrays of 4: front-left, front-right,
        rear-left, rear-right)."""
        row = self._row(name)
        v = self.arrays
        return {
            "command_speed": float(v.command_speed[row]),
            "command_yaw_rate": float(v.command_yaw_rate[row]),
            "command_age": float(v.command_age[row]),
            "throttle": float(v.throttle[row]), "brake": float(v.brake[row]),
            "steer": float(v.steer[row]),
            "steer_angle": v.steer_angle[row].copy(), "steer_rate": v.steer_rate[row].copy(),
            "spin_angle": v.spin_angle[row].copy(), "spin_rate": v.spin_rate[row].copy(),
            "compression": v.compression[row].copy(), "compression_rate": v.compression_rate[row].copy(),
            "in_contact": v.in_contact[row].copy(), "contact_point": v.contact_point[row].copy(),
        }

    def spec(self, name):
        """The validated spec as registered and edited (the chassis pose is the World's)."""
        if name not in self._specs:
            raise KeyError(f"no vehicle named {name!r}")
        return self._specs[name]

    def _row(self, name):
        try:
            return self._rows[name]
        except (KeyError, TypeError):
            raise KeyError(f"no vehicle named {name!r}") from None

    def _load_wheels(self, row, wheels):
        rows = self.arrays
        for w, wheel in enumerate(wheels):
            rows.mount[row, w] = wheel["mount"]
            for field, key in WHEEL_FIELDS:
                getattr(rows, field)[row, w] = wheel[key]
        # Wheels are front-left, front-right, rear-left, rear-right (SPEC 3).
        rows.rear_axle[row] = 0.5 * (wheels[2]["mount"][0] + wheels[3]["mount"][0])
        rows.wheelbase[row] = 0.5 * (wheels[0]["mount"][0] + wheels[1]["mount"][0]) - rows.rear_axle[row]
