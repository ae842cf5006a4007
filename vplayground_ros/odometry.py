"""Odometry that drifts like a robot's: the true base pose plus a seeded error model, with the
covariances that model implies. ROS-free (numpy): the node turns the result into `odom`
(nav_msgs/Odometry) and the odom -> base_link transform; the ground truth keeps its own topic.

The model acts in the horizontal plane, where wheel odometry integrates. Each update takes the
truth's horizontal displacement since the last one (its chord, d metres) and the time since it
(t seconds), and corrupts them with
  - a distance scale error s: the odometry reads (1 + s) times the distance. s starts
    N(0, scale_error^2) and is a random walk over distance: Var(s) grows by scale_walk^2 a metre;
  - white slip along and across the heading: Var grows by slip_along^2 (slip_across^2) a metre;
  - a yaw-rate bias b, as a gyro's: b starts N(0, yaw_bias^2) and is a random walk in time:
    Var(b) grows by yaw_drift^2 a second (the yaw drifts at rest too);
  - white yaw noise over distance: Var grows by yaw_noise^2 a metre.
Height, roll and pitch stay the truth's (a tilt sensor's gravity reference; 2D consumers drop
them). Along a straight line of length D driven at speed v in time T = D / v the errors are
  along-track  Var = scale_error^2 D^2 + scale_walk^2 D^3 / 3 + slip_along^2 D
  yaw          Var = yaw_bias^2 T^2 + yaw_drift^2 T^3 / 3 + yaw_noise^2 D
  cross-track  Var = slip_across^2 D + yaw_noise^2 D^3 / 3
                     + v^2 (yaw_bias^2 T^4 / 4 + yaw_drift^2 T^5 / 20)
whatever the update spacing: each random walk's change and integral over an interval are drawn
jointly with their exact covariance, so 7 Hz and 30 Hz updates differ only at second order in
the spacing (the heading error's growth within an interval, taken at its midpoint; chords
shorter than arcs on curves).

The odom frame is the world frame at reset (as with perfect odometry); each update composes the
measured increment onto the odometry pose along the odometry's own heading. The pose is kept as
the truth plus an error (a horizontal offset, a yaw about the vertical) so that what the model
leaves exact accumulates no rounding, and with every noise key 0 the odometry is the truth bit
for bit.
"""
import math
import zlib

import numpy as np

from .messages import EXACT_VARIANCE
from .physics import specs

# The error model's keys: unit and meaning. All default to 0 (no noise).
DESCRIPTIONS = {
    "scale_error": "1: standard deviation of the distance scale's error at start "
                   "(the wheel radius off by this fraction)",
    "scale_walk": "1/sqrt(m): random walk of the distance scale over distance "
                  "(its standard deviation after d metres: scale_walk sqrt(d))",
    "slip_along": "sqrt(m): white slip along the heading "
                  "(the position's standard deviation after d metres: slip_along sqrt(d))",
    "slip_across": "sqrt(m): white slip across the heading "
                   "(the position's standard deviation after d metres: slip_across sqrt(d))",
    "yaw_bias": "rad/s: standard deviation of the yaw-rate bias at start",
    "yaw_drift": "rad/s/sqrt(s): random walk of the yaw-rate bias in time "
                 "(its standard deviation after t seconds: yaw_drift sqrt(t))",
    "yaw_noise": "rad/sqrt(m): white yaw noise over distance "
                 "(the yaw's standard deviation after d metres: yaw_noise sqrt(d))",
    "seed": "seed of the odometry's noise, with the robot's name: the same scene drifts the same way",
}
DEFAULTS = {**{key: 0.0 for key in DESCRIPTIONS if key != "seed"}, "seed": 0}
KEYS = frozenset(DEFAULTS)
# The inclusive range of each key: validate checks it and the node's parameters advertise it.
RANGES = {**{key: (0.0, 1.0e3) for key in DEFAULTS if key != "seed"}, "seed": (0, 2**63 - 1)}
NOISE_KEYS = tuple(key for key in DEFAULTS if key != "seed")

# Pose covariance entries (nav_msgs rows: x y z roll pitch yaw) of the modelled x, y and yaw.
_PLANAR = np.ix_([0, 1, 5], [0, 1, 5])
_EXACT = np.eye(6) * EXACT_VARIANCE  # what the model leaves exact, as perfect odometry reports it


def validate(raw, path="odometry"):
    """The error model merged over DEFAULTS (None: all defaults), keys checked by name."""
    raw = {} if raw is None else raw
    specs.mapping(raw, path, KEYS)
    out = dict(DEFAULTS)
    for key in NOISE_KEYS:
        if key in raw:
            out[key] = specs.number(raw[key], specs.child(path, key), *RANGES[key])
    if "seed" in raw:
        out["seed"] = specs.integer(raw["seed"], specs.child(path, "seed"), *RANGES["seed"])
    return out


def _yaw(q):
    """Yaw of an xyzw quaternion (REP-103 fixed-axis roll, pitch, yaw)."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _walk(normals, sigma, length):
    """(change, integral) over `length` of a random walk of diffusion sigma^2 starting at 0, drawn
    jointly from two standard normals with the covariance _walk_covariance gives."""
    step = math.sqrt(length) * normals[0]
    return sigma * step, sigma * (0.5 * length * step + math.sqrt(length ** 3 / 12.0) * normals[1])


def _walk_covariance(sigma, length):
    """(Var change, Cov(change, integral), Var integral) of that walk: exact for any length,
    which is what makes the odometry's statistics independent of the update spacing."""
    v = sigma * sigma
    return v * length, v * length ** 2 / 2, v * length ** 3 / 3


def _heading_to_base(q, ch, sh):
    """The rotation from the heading frame (yaw ch, sh) to base_link, R^T Rz(yaw): the tilt
    undone; the identity on level ground."""
    x, y, z, w = q.tolist()
    r0 = (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w))  # R's rows
    r1 = (2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w))
    r2 = (2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y))
    return np.array([[ch * a + sh * b, ch * b - sh * a, c] for a, b, c in zip(r0, r1, r2)])


class OdometryTracker:
    """One robot's odometry: reset() at its true pose, then update() with each later true pose.

    After each update, `pose_covariance` (6x6, rows x y z roll pitch yaw, odom frame),
    `twist_covariance` and `twist_error` (6x6 and (6,), rows vx vy vz wx wy wz in base_link) are
    those of the odometry; the twist ones describe the mean velocity over the last interval, and
    the node adds twist_error to the true twist. The covariances are propagated linearised about
    the truth, so they depend on the path and the model, never on the draws; z, roll and pitch
    (and the twist's vz, wx, wy on level ground) keep EXACT_VARIANCE. With every noise key 0
    (`noiseless`) everything stays exact: the covariances at EXACT_VARIANCE, the error 0.
    """

    def __init__(self, name, spec=None, path="odometry"):
        """`name` keys the noise stream (with the spec's seed); `spec` is the model, raw or
        validated; `path` names it in errors."""
        self.name = name
        self.model = validate(spec, path)
        self.noiseless = not any(self.model[key] for key in NOISE_KEYS)
        self.time = None
        self.pose_covariance, self.twist_covariance, self.twist_error = _EXACT.copy(), _EXACT.copy(), np.zeros(6)

    def reset(self, position, quaternion, seconds):
        """Starts the odometry at the true pose (odom = world) and restarts its noise, so a reset
        scene drifts as it did the first time."""
        m = self.model
        self.rng = np.random.Generator(np.random.PCG64([m["seed"], zlib.crc32(f"odometry/{self.name}".encode())]))
        self.position, self.quaternion = np.array(position, float), np.array(quaternion, float)
        self.time = float(seconds)
        self.offset_x = self.offset_y = 0.0  # odometry - truth, horizontal, odom axes (m)
        self.yaw_error = 0.0                 # odometry's yaw - truth's, about the vertical (rad)
        start = self.rng.standard_normal(2)
        self.scale = m["scale_error"] * float(start[0])  # distance read / distance travelled - 1
        self.bias = m["yaw_bias"] * float(start[1])      # of the yaw rate (rad/s)
        # Covariance of the state (offset x, offset y, yaw error, scale, bias): the pose starts exact.
        self.covariance = np.diag([0.0, 0.0, 0.0, m["scale_error"] ** 2, m["yaw_bias"] ** 2])
        self.pose_covariance, self.twist_covariance, self.twist_error = _EXACT.copy(), _EXACT.copy(), np.zeros(6)

    def update(self, position, quaternion, seconds):
        """The odometry's pose, new arrays (position (3,), quaternion xyzw (4,)) in the odom
        frame, for the true base_link pose at a later (or the same) simulated time; the twist's
        error and covariance change only when time has passed."""
        if self.time is None:
            raise RuntimeError("OdometryTracker.update before reset")
        seconds = float(seconds)
        if seconds < self.time:
            raise ValueError(f"time went back from {self.time:g} to {seconds:g} s: reset the odometry")
        position, quaternion = np.array(position, float), np.array(quaternion, float)
        if self.noiseless:  # the truth itself: composing its increments would add rounding
            return position, quaternion
        self._integrate(position - self.position, quaternion, seconds - self.time)
        self.position, self.quaternion, self.time = position, quaternion, seconds
        half = 0.5 * self.yaw_error
        sz, cz = math.sin(half), math.cos(half)
        x, y, z, w = quaternion  # Rz(yaw_error) on the left: a turn about the odom frame's vertical
        return (np.array([position[0] + self.offset_x, position[1] + self.offset_y, position[2]]),
                np.array([cz * x - sz * y, cz * y + sz * x, cz * z + sz * w, cz * w - sz * z]))

    def _integrate(self, displacement, quaternion, dt):
        """Draws one interval's errors, composes the measured increment onto the odometry and
        propagates the covariances through it."""
        m = self.model
        # The truth's heading at mid-interval: a turning car slips along and across it.
        start = _yaw(self.quaternion)
        heading = start + 0.5 * math.remainder(_yaw(quaternion) - start, math.tau)
        ch, sh = math.cos(heading), math.sin(heading)
        dx, dy = float(displacement[0]), float(displacement[1])
        distance = math.hypot(dx, dy)
        # The unit direction travelled, heading frame (x forward, y left; reversing: -x);
        # standing, any will do: nothing is scaled.
        ax, ay = 1.0, 0.0
        if distance > 0.0:
            ax, ay = (ch * dx + sh * dy) / distance, (ch * dy - sh * dx) / distance
        xi = self.rng.standard_normal(7).tolist()
        scale_step, scale_integral = _walk(xi[0:2], m["scale_walk"], distance)
        bias_step, bias_integral = _walk(xi[2:4], m["yaw_drift"], dt)
        root = math.sqrt(distance)
        distance_error = self.scale * distance + scale_integral
        # The increment's error, heading frame.
        ex = distance_error * ax + m["slip_along"] * root * xi[5]
        ey = distance_error * ay + m["slip_across"] * root * xi[6]
        yaw_step = self.bias * dt + bias_integral + m["yaw_noise"] * root * xi[4]
        if dt > 0.0:
            self._twist(ex, ey, yaw_step, distance, ax, ay, dt, quaternion, ch, sh)
        self._propagate(dx, dy, distance, ax, ay, dt, ch, sh)
        # The odometry moves along its own heading, taken at mid-interval: its error grows
        # through the interval, and the midpoint keeps 7 Hz and 30 Hz updates alike.
        turn = self.yaw_error + 0.5 * yaw_step
        ct, st = math.cos(turn), math.sin(turn)
        mx, my = dx + ch * ex - sh * ey, dy + sh * ex + ch * ey  # the measured increment, odom axes
        self.offset_x += ct * mx - st * my - dx
        self.offset_y += st * mx + ct * my - dy
        self.yaw_error += yaw_step
        self.scale += scale_step
        self.bias += bias_step

    def _propagate(self, dx, dy, distance, ax, ay, dt, ch, sh):
        """P <- F P F^T + G Q G^T for the state (offset x, offset y, yaw error, scale, bias) and
        the noise (scale walk's change and integral, bias walk's change and integral, white yaw,
        slip along, slip across), linearised about the truth."""
        m = self.model
        lx, ly = -dy, dx  # how a heading error moves the increment's end
        hx, hy = 0.5 * lx, 0.5 * ly  # the same for a heading error grown through the interval
        ux, uy = ch * ax - sh * ay, sh * ax + ch * ay  # the direction travelled, odom axes
        f = np.array([[1.0, 0.0, lx, dx, hx * dt],  # scale stretches the increment, bias turns it
                      [0.0, 1.0, ly, dy, hy * dt],
                      [0.0, 0.0, 1.0, 0.0, dt],
                      [0.0, 0.0, 0.0, 1.0, 0.0],
                      [0.0, 0.0, 0.0, 0.0, 1.0]])
        g = np.array([[0.0, ux, 0.0, hx, hx, ch, -sh],
                      [0.0, uy, 0.0, hy, hy, sh, ch],
                      [0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0],
                      [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                      [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]])
        s0, s1, s2 = _walk_covariance(m["scale_walk"], distance)
        b0, b1, b2 = _walk_covariance(m["yaw_drift"], dt)
        q = np.diag([s0, s2, b0, b2, m["yaw_noise"] ** 2 * distance,
                     m["slip_along"] ** 2 * distance, m["slip_across"] ** 2 * distance])
        q[0, 1] = q[1, 0] = s1
        q[2, 3] = q[3, 2] = b1
        self.covariance = f @ self.covariance @ f.T + g @ q @ g.T
        self.pose_covariance = _EXACT.copy()
        self.pose_covariance[_PLANAR] += self.covariance[:3, :3]

    def _twist(self, ex, ey, yaw_step, distance, ax, ay, dt, quaternion, ch, sh):
        """This interval's mean velocity error and its covariance, in base_link at its end (the
        pose they are published with); called before _propagate, while the state's covariance
        is the interval's start's."""
        m, p = self.model, self.covariance
        rotate = _heading_to_base(quaternion, ch, sh)
        self.twist_error = np.concatenate([rotate @ (ex, ey, 0.0), rotate[:, 2] * yaw_step]) / dt
        distance_var = p[3, 3] * distance ** 2 + _walk_covariance(m["scale_walk"], distance)[2]
        planar = np.array([[distance_var * ax * ax + m["slip_along"] ** 2 * distance, distance_var * ax * ay],
                           [distance_var * ax * ay, distance_var * ay * ay + m["slip_across"] ** 2 * distance]])
        yaw_var = p[4, 4] * dt ** 2 + _walk_covariance(m["yaw_drift"], dt)[2] + m["yaw_noise"] ** 2 * distance
        self.twist_covariance = _EXACT.copy()
        self.twist_covariance[:3, :3] += rotate[:, :2] @ planar @ rotate[:, :2].T / dt ** 2
        self.twist_covariance[3:, 3:] += yaw_var / dt ** 2 * np.outer(rotate[:, 2], rotate[:, 2])
