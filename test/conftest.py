import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

# Each test session on its own DDS domain, discovery kept on this machine: parallel runs
# never see each other's nodes.
os.environ["ROS_DOMAIN_ID"] = str(int.from_bytes(os.urandom(1), "little") % 100 + 100)
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
