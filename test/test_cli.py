"""The `vplayground` entry point (cli.py): options refused with a reason, a thread that dies
ending the run with a failure status, and the ROS thread surviving a failing callback."""
import logging
import threading

import pytest

from vplayground_ros import cli
from vplayground_ros.runtime import Runtime
from vplayground_ros.scene import load_world
from vplayground_ros.simulation import Simulation
from helpers import wait_for

SCENE = {"version": 1, "bodies": [{"name": "box", "position": [0, 0, 0.5]}]}


@pytest.mark.parametrize("option", ["--duration", "--real-time-factor"])
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "NaN"])
def test_a_non_finite_duration_or_speed_is_refused(capsys, option, value):
    # NaN passed the `<= 0` checks and inf reached the physics thread, which died of it.
    with pytest.raises(SystemExit) as refused:
        cli.parse_args([f"{option}={value}", "--no-record"])  # "=": "-inf" alone reads as an option
    assert refused.value.code == 2
    assert f"argument {option}: must be a finite number" in capsys.readouterr().err


def test_a_value_that_is_no_number_is_refused_in_words(capsys):
    """argparse named the internal function: 'invalid finite_float value'."""
    with pytest.raises(SystemExit) as refused:
        cli.parse_args(["--real-time-factor", "abc", "--no-record"])
    assert refused.value.code == 2
    assert "argument --real-time-factor: expected a number, got 'abc'" in capsys.readouterr().err


def test_finite_values_still_pass():
    options = cli.parse_args(["--duration", "2.5", "--real-time-factor", "0", "--no-record"])
    assert (options.duration, options.real_time_factor) == (2.5, 0.0)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_a_simulation_thread_that_dies_ends_the_run_with_a_failure_status(caplog, monkeypatch):
    # The loop used to take the physics thread's end for a finished --duration: exit 0.
    sim = Simulation(load_world(SCENE), real_time_factor=0.0)

    def die():
        raise OverflowError("cannot convert float infinity to integer")
    monkeypatch.setattr(sim, "_loop", die)
    hook = threading.excepthook
    with caplog.at_level(logging.INFO):
        status = cli.run(sim, cli.parse_args(["--no-record", "--no-ros"]), None, None, threading.Event())
    assert status == 1
    assert any(record.levelno == logging.ERROR and "vplayground-physics (OverflowError: cannot convert" in
               record.getMessage() for record in caplog.records), caplog.text
    assert threading.excepthook is hook  # the run's watch on its threads ended with it


class WaitWatch(threading.Event):
    """A stop event that notes the threads waiting on it."""

    def __init__(self):
        super().__init__()
        self.waiters = set()

    def wait(self, timeout=None):
        self.waiters.add(threading.current_thread().name)
        return super().wait(timeout)


def test_the_main_thread_never_waits_on_the_event_its_signal_handler_sets():
    """SIGTERM's handler sets the stop event on the main thread; a signal that lands while the
    main thread is inside Event.wait (holding its Lock, which is not reentrant) deadlocked the
    handler against it: a node that ignored SIGTERM for good (seen once in make test)."""
    stop = WaitWatch()
    sim = Simulation(load_world(SCENE), real_time_factor=0.0, duration=0.5)
    assert cli.run(sim, cli.parse_args(["--no-record", "--no-ros"]), None, None, stop) == 0
    assert threading.main_thread().name not in stop.waiters


class FlakyExecutor:
    """An executor whose spin() raises each of `errors` in turn (a callback failing), then
    returns (shut down)."""

    def __init__(self, *errors):
        self.errors = list(errors)
        self.spins = 0

    def spin(self):
        self.spins += 1
        if self.errors:
            raise self.errors.pop(0)


def test_a_failing_ros_callback_is_logged_once_counted_and_spun_past(caplog):
    pytest.importorskip("rclpy")
    sim = Simulation(load_world(SCENE))
    executor = FlakyExecutor(RuntimeError("bad request"), RuntimeError("bad request"), KeyError("reply"))
    stop = threading.Event()
    with caplog.at_level(logging.ERROR):
        cli.spin(executor, stop, sim.fault)
    assert executor.spins == 4  # spun on after each failure, until it returned
    assert sim.fault_count == 3  # on /diagnostics
    assert sim.faults == ["ROS callback: RuntimeError: bad request", "ROS callback: KeyError: 'reply'"]
    logged = [record for record in caplog.records if record.levelno == logging.ERROR]
    assert len(logged) == 2 and all(record.exc_info for record in logged)  # each once, with its traceback
    assert stop.is_set()  # the executor was shut down: so is the run


def test_the_ros_thread_ends_when_ros_shuts_down():
    executors = pytest.importorskip("rclpy.executors")
    faults, stop = [], threading.Event()
    executor = FlakyExecutor(executors.ExternalShutdownException())  # the context was shut down
    cli.spin(executor, stop, lambda where, error: faults.append(error))
    assert executor.spins == 1 and faults == [] and stop.is_set()  # no fault, no second spin


def test_a_real_node_answers_after_a_callback_failed():
    """Through rclpy: a service callback raises out of the executor's spin; the next request
    is answered, and shutting the executor down still ends the thread."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    context = Context()
    rclpy.init(context=context)
    server = rclpy.create_node("flaky_server", context=context)
    client = rclpy.create_node("flaky_client", context=context)
    requests = []

    def answer(request, response):
        requests.append(request)
        if len(requests) == 1:
            raise RuntimeError("handler bug")
        response.success, response.message = True, "fine"
        return response
    server.create_service(Trigger, "flaky", answer)
    server_executor, client_executor = SingleThreadedExecutor(context=context), SingleThreadedExecutor(context=context)
    server_executor.add_node(server)
    client_executor.add_node(client)
    faults, stop = [], threading.Event()
    spinner = threading.Thread(target=cli.spin, args=(server_executor, stop, lambda where, error: faults.append(
        f"{where}: {error}")), daemon=True)
    spinner.start()
    try:
        service = client.create_client(Trigger, "flaky")
        assert service.wait_for_service(timeout_sec=30.0)
        service.call_async(Trigger.Request())  # never answered: its callback raised
        wait_for(lambda: faults, explain=lambda: (requests, spinner.is_alive()))
        assert faults == ["ROS callback: handler bug"] and spinner.is_alive() and not stop.is_set()
        future = service.call_async(Trigger.Request())
        client_executor.spin_until_future_complete(future, timeout_sec=30.0)
        assert future.done() and future.result().message == "fine"
    finally:
        server_executor.shutdown(timeout_sec=5.0)
        spinner.join(10.0)
        client_executor.shutdown()
        server.destroy_node()
        client.destroy_node()
        rclpy.try_shutdown(context=context)
    assert not spinner.is_alive() and stop.is_set()


def test_ros_arguments_without_a_node_are_said_to_be_ignored(tmp_path):
    """--ros-args with --no-ros (or without rclpy) did nothing and said nothing: an override of
    the duration left the run going on."""
    import subprocess
    import sys
    scene = tmp_path / "scene.yaml"
    scene.write_text("version: 1\n")
    done = subprocess.run([sys.executable, "-m", "vplayground_ros.cli", "--no-ros", "--no-record", "--scene",
                           str(scene), "--duration", "0.1", "--ros-args", "-p", "duration:=5.0"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "--ros-args -p duration:=5.0: ignored, no ROS node runs here (--no-ros)" in done.stderr


def test_a_duration_beyond_a_countable_run_is_refused(capsys):
    """1e308 s passed the finite-number check and ended the physics thread: its step count
    (duration x steps per second) overflowed. The option and the parameter's override alike."""
    with pytest.raises(SystemExit) as refused:
        cli.parse_args(["--duration", "1e308", "--no-record"])
    assert refused.value.code == 2
    assert "--duration must be > 0 and at most 1e+09 s" in capsys.readouterr().err
    options = cli.parse_args(["--no-record"])
    runtime = Runtime(Simulation(load_world(SCENE), real_time_factor=0.0), options, logging.getLogger("test_cli"))
    for value in (1e308, -5.0):
        with pytest.raises(ValueError, match="duration"):
            runtime.parameters.override({"duration": value})
    assert runtime.parameters["duration"] == 0.0


@pytest.mark.parametrize("option, value, reason", [
    ("--real-time-factor", "5000", "--real-time-factor must be >= 0 and at most 1000"),
    ("--record-split-size", str(1 << 51), "--record-split-size must be at most 1125899906842624 bytes")])
def test_an_option_beyond_its_parameters_range_is_refused_as_the_option(capsys, option, value, reason):
    """Every option is also a parameter: one past the parameter's range had passed here, then
    stopped the ROS node's start with a refused `--ros-args -p` override nobody had given (and
    ran unchecked without ROS)."""
    with pytest.raises(SystemExit) as refused:
        cli.parse_args([option, value, "--no-record"])
    assert refused.value.code == 2
    assert reason in capsys.readouterr().err
    edge = "1000" if option == "--real-time-factor" else str(1 << 50)  # the range's end still passes
    assert str(getattr(cli.parse_args([option, edge, "--no-record"]), option[2:].replace("-", "_"))).startswith(edge)


@pytest.mark.parametrize("size", ["-1", "1", "65535"])
def test_a_split_size_below_a_chunk_is_refused(capsys, size):
    """1 byte had written a bag file per chunk, thousands in two simulated seconds."""
    with pytest.raises(SystemExit) as refused:
        cli.parse_args(["--record-split-size", size])
    assert refused.value.code == 2
    assert "--record-split-size must be 0 (one file) or at least 65536 bytes" in capsys.readouterr().err
    assert cli.parse_args(["--record-split-size", "65536"]).record_split_size == 65536
