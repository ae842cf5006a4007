"""The Broadcaster's bookkeeping over long runs."""
from unittest.mock import MagicMock

from vplayground_ros.broadcast import Broadcaster


class Parameters(dict):
    def listen(self, fn):
        pass


def test_marker_ids_stay_stable_and_bounded():
    parameters = Parameters({"publish_rate": 30.0, "marker_rate": 30.0, "world_frame": "world",
                             "odom_frame": "odom", "base_frame": "base_link"})
    broadcaster = Broadcaster(MagicMock(), parameters, MagicMock())
    keeper = broadcaster.marker_id("keeper")
    for k in range(1000):  # a body spawned and removed every time, under a new name
        names = ["keeper", f"temporary_{k}"]
        broadcaster.forget_removed(names)
        broadcaster.marker_id(names[1])
    assert broadcaster.marker_id("keeper") == keeper
    assert len(broadcaster.marker_ids) <= 2 * 2 + 64 + 1
    assert len(set(broadcaster.marker_ids.values())) == len(broadcaster.marker_ids)  # ids never reused
