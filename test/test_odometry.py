"""Drifting odometry (vplayground_ros.odometry) against its error model's analytic statistics.

The statistical checks run the same path for SEEDS seeds and compare the errors' mean squares
with the model's variance. For N zero-mean normal samples of variance v, N * mean square / v is
chi-square with N degrees of freedom; each check accepts the central 1 - ALPHA of that law
(0.80 to 1.22 times v), so a correct model fails one with probability ALPHA for a fresh set of
seeds (the seeds are fixed: the suite is deterministic), while a wrong factor such as T^3/2 for
T^3/3 falls far outside.
"""
import math

import numpy as np
import pytest
from scipy import stats

from vplayground_ros import odometry
from vplayground_ros.messages import EXACT_VARIANCE
from vplayground_ros.odometry import OdometryTracker
from vplayground_ros.physics.math3d import rpy_to_quat
from vplayground_ros.physics.specs import SpecError

SEEDS = 500
ALPHA = 1e-3
CHI2 = stats.chi2.ppf([ALPHA / 2, 1 - ALPHA / 2], SEEDS) / SEEDS  # about [0.80, 1.22]
EXACT = np.eye(6) * EXACT_VARIANCE


def yaw_of(q):
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def roll_pitch_of(q):
    x, y, z, w = q
    return (math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)),
            math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x)))))


def straight(length, duration, updates, heading=0.6):
    """[(position, quaternion, seconds)]: a level straight line at constant speed."""
    q = rpy_to_quat((0.0, 0.0, heading))
    direction = np.array([math.cos(heading), math.sin(heading), 0.0])
    return [(np.array([1.0, -2.0, 0.3]) + length * k / updates * direction, q, duration * k / updates)
            for k in range(updates + 1)]


def arc(rate, duration=1.0, speed=5.0, turn_rate=0.5):
    """A level circular arc from the origin heading +x, sampled at `rate` Hz."""
    radius = speed / turn_rate
    path = []
    for k in range(round(rate * duration) + 1):
        t = k / rate
        a = turn_rate * t
        path.append((np.array([radius * math.sin(a), radius * (1.0 - math.cos(a)), 0.0]),
                     rpy_to_quat((0.0, 0.0, a)), t))
    return path


def drive(spec, path, seed, name="car"):
    """The tracker after driving `path`, and its last odometry pose."""
    tracker = OdometryTracker(name, {**spec, "seed": seed})
    tracker.reset(*path[0])
    for pose in path[1:]:
        out = tracker.update(*pose)
    return tracker, out


def errors(spec, path):
    """Per seed: the final (x, y, yaw) error, odometry - truth, and the tracker."""
    position, quaternion, _ = path[-1]
    rows, trackers = [], []
    for seed in range(SEEDS):
        tracker, (p, q) = drive(spec, path, seed)
        yaw = math.remainder(yaw_of(q) - yaw_of(quaternion), math.tau)
        rows.append((p[0] - position[0], p[1] - position[1], yaw))
        trackers.append(tracker)
    return np.array(rows), trackers


def assert_variance(samples, variance):
    """The samples' mean square is `variance` within the chi-square bounds."""
    ratio = np.mean(np.square(samples)) / variance
    assert CHI2[0] < ratio < CHI2[1], f"mean square / model = {ratio:.3f}, bounds {CHI2.round(3)}"


def test_noise_off_returns_the_truth_bit_for_bit_on_a_curved_3d_path():
    # A minute at 30 Hz of a path that climbs, rolls, pitches and turns: composing its
    # increments would drift by rounding; the odometry must be the truth itself.
    for spec in (None, {}, {"seed": 7}, dict(odometry.DEFAULTS)):
        tracker = OdometryTracker("car", spec)
        for k in range(1801):
            t = k / 30.0
            position = np.array([30.0 * math.sin(0.1 * t), 20.0 * math.sin(0.05 * t),
                                 2.0 * math.sin(0.3 * t) + 1e-3 * t])
            quaternion = rpy_to_quat((0.2 * math.sin(0.7 * t), 0.3 * math.cos(0.4 * t), 0.1 * t + 3.0))
            if k == 0:
                tracker.reset(position, quaternion, t)
                continue
            p, q = tracker.update(position, quaternion, t)
            assert p.tobytes() == position.tobytes() and q.tobytes() == quaternion.tobytes()
        assert np.array_equal(tracker.pose_covariance, EXACT)
        assert np.array_equal(tracker.twist_covariance, EXACT)
        assert not tracker.twist_error.any()


def test_the_same_seed_drifts_the_same_way_and_another_seed_or_robot_does_not():
    spec = {"scale_error": 0.01, "scale_walk": 0.003, "slip_along": 0.01, "slip_across": 0.02,
            "yaw_bias": 0.002, "yaw_drift": 0.001, "yaw_noise": 0.003}
    path = arc(30.0, duration=2.0)

    def outputs(seed, name="car"):
        tracker = OdometryTracker(name, {**spec, "seed": seed})
        tracker.reset(*path[0])
        return np.concatenate([np.concatenate(tracker.update(*pose)) for pose in path[1:]])

    first = outputs(3)
    assert np.array_equal(first, outputs(3))
    assert not np.array_equal(first, outputs(4))
    assert not np.array_equal(first, outputs(3, name="other_car"))
    # A reset replays the same drift: a reloaded scene drifts as it did the first time.
    tracker = OdometryTracker("car", {**spec, "seed": 3})
    for _ in range(2):
        tracker.reset(*path[0])
        again = np.concatenate([np.concatenate(tracker.update(*pose)) for pose in path[1:]])
        assert np.array_equal(first, again)


def test_scale_error_and_its_walk_give_the_along_track_variance_of_an_integrated_walk():
    # Along-track error = integral over distance of the scale s(u) = s0 + walk: Var = sigma0^2 D^2
    # + sigma^2 D^3 / 3. The walk is drawn exactly per interval, so 10 updates are enough.
    spec = {"scale_error": 0.005, "scale_walk": 0.005}  # the walk 87 % of the variance
    length, duration, heading = 20.0, 2.0, 0.6
    e, trackers = errors(spec, straight(length, duration, 10, heading))
    along = e[:, 0] * math.cos(heading) + e[:, 1] * math.sin(heading)
    across = -e[:, 0] * math.sin(heading) + e[:, 1] * math.cos(heading)
    variance = 0.005 ** 2 * length ** 2 + 0.005 ** 2 * length ** 3 / 3
    assert_variance(along, variance)
    assert np.abs(across).max() < 1e-12 and not e[:, 2].any()  # a scale error only stretches
    reported = trackers[0].pose_covariance
    assert reported[0, 0] + reported[1, 1] == pytest.approx(variance + 2 * EXACT_VARIANCE, rel=1e-9)
    # The last interval's mean velocity error (base_link x here) and its reported variance.
    assert_variance([t.twist_error[0] for t in trackers], trackers[0].twist_covariance[0, 0])


def test_yaw_drift_at_rest_gives_the_yaw_variance_of_an_integrated_bias_walk():
    # A gyro-like bias b(t) = b0 + walk, integrated: Var = yaw_bias^2 T^2 + yaw_drift^2 T^3 / 3,
    # at rest too. The truth is tilted: roll, pitch and position must stay the truth's.
    spec = {"yaw_bias": 0.003, "yaw_drift": 0.01}  # the walk 97 % of the variance
    duration = 10.0
    position, quaternion = np.array([3.0, 4.0, 0.5]), rpy_to_quat((0.1, -0.2, 2.0))
    path = [(position, quaternion, duration * k / 10) for k in range(11)]
    e, _ = errors(spec, path)
    assert_variance(e[:, 2], 0.003 ** 2 * duration ** 2 + 0.01 ** 2 * duration ** 3 / 3)
    assert not e[:, :2].any()
    _, (p, q) = drive(spec, path, seed=1)
    assert p.tobytes() == position.tobytes()
    assert roll_pitch_of(q) == pytest.approx(roll_pitch_of(quaternion), abs=1e-12)


def test_yaw_drift_while_driving_bends_the_track_by_its_double_integral():
    # Cross-track = v x the yaw error integrated in time: Var = v^2 (yaw_bias^2 T^4 / 4 +
    # yaw_drift^2 T^5 / 20), the variances of a line's and of a twice-integrated walk's integral.
    spec = {"yaw_bias": 0.003, "yaw_drift": 0.01}  # the walk 90 % of the variance
    length, duration, heading = 20.0, 4.0, 1.2
    e, _ = errors(spec, straight(length, duration, 20, heading))
    across = -e[:, 0] * math.sin(heading) + e[:, 1] * math.cos(heading)
    speed = length / duration
    assert_variance(across, speed ** 2 * (0.003 ** 2 * duration ** 4 / 4 + 0.01 ** 2 * duration ** 5 / 20))


def test_slip_and_yaw_noise_grow_with_distance():
    # White slip: Var = slip^2 D along and across the heading; white yaw noise: Var(yaw) =
    # yaw_noise^2 D, and its random walk in distance carried along the line adds
    # yaw_noise^2 D^3 / 3 across (trapezoidal per interval: 1 - 1/(4 n^2) of it, n = 20).
    spec = {"slip_along": 0.01, "slip_across": 0.02, "yaw_noise": 0.002}
    length, heading = 20.0, -2.5
    e, _ = errors(spec, straight(length, 4.0, 20, heading))
    along = e[:, 0] * math.cos(heading) + e[:, 1] * math.sin(heading)
    across = -e[:, 0] * math.sin(heading) + e[:, 1] * math.cos(heading)
    assert_variance(along, 0.01 ** 2 * length)
    assert_variance(across, 0.02 ** 2 * length + 0.002 ** 2 * length ** 3 / 3)
    assert_variance(e[:, 2], 0.002 ** 2 * length)


FULL = {"scale_error": 0.005, "scale_walk": 0.01, "slip_along": 0.01, "slip_across": 0.01,
        "yaw_bias": 0.01, "yaw_drift": 0.05, "yaw_noise": 0.005}


@pytest.mark.parametrize("rate", [30.0, 7.0])
def test_update_spacing_does_not_change_the_drift(rate):
    # Every error on along a straight line: the module's analytic variances (its docstring) at
    # 30 Hz and at 7 Hz. The walks are exact per interval; the heading error's growth within
    # one is trapezoidal, missing 1 / (4 n^2) of a white walk's share (0.5 % at n = 7).
    length, duration, heading = 10.0, 1.0, 0.6
    m, speed = FULL, length / duration
    model = {
        "along": m["scale_error"] ** 2 * length ** 2 + m["scale_walk"] ** 2 * length ** 3 / 3
                 + m["slip_along"] ** 2 * length,
        "across": m["slip_across"] ** 2 * length + m["yaw_noise"] ** 2 * length ** 3 / 3
                  + speed ** 2 * m["yaw_bias"] ** 2 * duration ** 4 / 4
                  + speed ** 2 * m["yaw_drift"] ** 2 * duration ** 5 / 20,
        "yaw": m["yaw_bias"] ** 2 * duration ** 2 + m["yaw_drift"] ** 2 * duration ** 3 / 3
               + m["yaw_noise"] ** 2 * length,
    }
    e, trackers = errors(FULL, straight(length, duration, round(rate * duration), heading))
    c, s = math.cos(heading), math.sin(heading)
    drift = {"along": e[:, 0] * c + e[:, 1] * s, "across": -e[:, 0] * s + e[:, 1] * c, "yaw": e[:, 2]}
    covariance = trackers[0].pose_covariance  # linearised about the truth: the same for every seed
    axes = np.array([[c, -s], [s, c]])
    planar = axes.T @ covariance[:2, :2] @ axes
    reported = {"along": planar[0, 0], "across": planar[1, 1], "yaw": covariance[5, 5]}
    for key, variance in model.items():
        assert_variance(drift[key], variance)
        assert reported[key] == pytest.approx(variance, rel=0.01), key


def test_the_reported_covariance_matches_the_drift_on_a_turn():
    path = arc(30.0)
    e, trackers = errors(FULL, path)
    covariance = trackers[0].pose_covariance
    assert all(np.array_equal(t.pose_covariance, covariance) for t in trackers)
    for k, row in enumerate((0, 1, 5)):  # x, y, yaw
        assert_variance(e[:, k], covariance[row, row])
    # The correlations a turn makes between x, y and yaw: Fisher's z of a correlation over N
    # samples has standard error 1 / sqrt(N - 3).
    bound = stats.norm.ppf(1 - ALPHA / 2) / math.sqrt(SEEDS - 3)
    for a, b, row, column in ((0, 2, 0, 5), (1, 2, 1, 5), (0, 1, 0, 1)):
        model = covariance[row, column] / math.sqrt(covariance[row, row] * covariance[column, column])
        empirical = np.mean(e[:, a] * e[:, b]) / math.sqrt(np.mean(e[:, a] ** 2) * np.mean(e[:, b] ** 2))
        assert abs(math.atanh(empirical) - math.atanh(model)) < bound
    # At 7 Hz the same covariance, but for second-order terms in the spacing: every entry
    # within 1 % of its row's and column's standard deviations.
    slow, _ = drive(FULL, arc(7.0), seed=0)
    planar = np.ix_([0, 1, 5], [0, 1, 5])
    scale = np.sqrt(np.diag(covariance[planar]))
    assert np.all(np.abs(slow.pose_covariance[planar] - covariance[planar]) < 0.01 * np.outer(scale, scale))


def test_height_roll_and_pitch_stay_the_truths_on_a_hill():
    tracker = OdometryTracker("car", {**FULL, "seed": 5})
    for k in range(301):
        t = k / 30.0
        position = np.array([5.0 * t, 0.2 * t * t, 0.5 * t])
        quaternion = rpy_to_quat((0.1 * math.sin(t), -0.1, 0.04 * t))
        if k == 0:
            tracker.reset(position, quaternion, t)
            continue
        p, q = tracker.update(position, quaternion, t)
        assert p[2] == position[2]
        assert roll_pitch_of(q) == pytest.approx(roll_pitch_of(quaternion), abs=1e-9)
    assert np.linalg.norm(p[:2] - position[:2]) > 1e-3  # while x, y and yaw did drift
    covariance = tracker.pose_covariance
    assert np.all(np.linalg.eigvalsh(covariance) > 0.0)
    assert np.diag(covariance)[2:5].tolist() == [EXACT_VARIANCE] * 3


def test_time_must_not_go_back_and_reset_comes_first():
    tracker = OdometryTracker("car", {"yaw_drift": 0.01})
    with pytest.raises(RuntimeError, match="before reset"):
        tracker.update([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], 1.0)
    tracker.reset([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], 2.0)
    with pytest.raises(ValueError, match="time went back from 2 to 1 s"):
        tracker.update([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], 1.0)


def test_the_spec_is_validated_over_its_defaults():
    assert odometry.validate(None) == odometry.DEFAULTS
    assert set(odometry.DEFAULTS) == odometry.KEYS == set(odometry.DESCRIPTIONS) == set(odometry.RANGES)
    assert odometry.validate({"yaw_drift": 1, "seed": 2.0}) == {**odometry.DEFAULTS, "yaw_drift": 1.0, "seed": 2}


@pytest.mark.parametrize("raw, message", [
    ({"yaw_drift": -1}, "vehicles[0].odometry.yaw_drift: must be >= 0, got -1"),
    ({"scale_walk": "x"}, "vehicles[0].odometry.scale_walk: expected a number, got str 'x'"),
    ({"slip_along": True}, "vehicles[0].odometry.slip_along: expected a number, got bool True"),
    ({"slip_across": math.inf}, "vehicles[0].odometry.slip_across: must be finite, got inf"),
    ({"yaw_noise": 1e4}, "vehicles[0].odometry.yaw_noise: must be <= 1000, got 10000"),
    ({"seed": 1.5}, "vehicles[0].odometry.seed: expected an integer, got float 1.5"),
    ({"seed": -1}, "vehicles[0].odometry.seed: must be between 0 and"),
    ({"slip": 0.1}, "vehicles[0].odometry.slip: unknown key (allowed: scale_error,"),
    ([0.1], "vehicles[0].odometry: expected a mapping, got list"),
])
def test_bad_specs_are_refused_naming_the_key(raw, message):
    with pytest.raises(SpecError) as caught:
        OdometryTracker("car", raw, path="vehicles[0].odometry")
    assert str(caught.value).startswith(message)
