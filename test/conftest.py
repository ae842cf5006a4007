import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))

try:
    import fcntl
except ImportError:  # not POSIX: a random domain alone
    fcntl = None

# 100..199: Fast DDS takes ids up to 232, but a domain's ports are 7400 + 250 x its id and up, 2
# more for each participant in it: from 200 on, a test run's many participants near 65,535.
FIRST_DOMAIN, DOMAINS = 100, 100
_held_domain = None  # the lock file of this process's domain, held until it exits


def session_domain():
    """Each test process (a session, or one of make test's pytest-xdist workers) on a DDS domain
    of its own, so that parallel runs and workers never see each other's nodes: the first free
    one from a random start, held by a lock file that this process keeps open until it ends
    (however it ends). Without locks (or every domain taken) a random one."""
    global _held_domain
    start = int.from_bytes(os.urandom(2), "little")
    for k in range(DOMAINS if fcntl is not None else 0):
        domain = FIRST_DOMAIN + (start + k) % DOMAINS
        lock = open(os.path.join(tempfile.gettempdir(), f"vplayground_ros_test_domain_{domain}.lock"), "a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _held_domain = lock
        return domain
    return FIRST_DOMAIN + start % DOMAINS


os.environ["ROS_DOMAIN_ID"] = str(session_domain())
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # discovery kept on this machine
