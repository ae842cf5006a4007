import os
import sys

sys.path.insert(0, os.path.dirname(__file__))


def session_domain():
    """Each test session on a DDS domain of its own, so that parallel runs never see each
    other's nodes: a random one from 100, and with pytest-xdist's workers (make test) the run's
    random base plus the worker's number, so that its workers do not either."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if not worker.startswith("gw") or not run:
        return int.from_bytes(os.urandom(1), "little") % 100 + 100
    return int(run, 16) % 60 + 100 + int(worker[2:]) % 32


os.environ["ROS_DOMAIN_ID"] = str(session_domain())
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # discovery kept on this machine
