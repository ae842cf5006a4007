"""A Foxglove viewer in a process of its own for node_overhead.py: connects to URL, subscribes
to every channel once CHANNELS are advertised, prints `subscribed`, then reads frames (keeping a
few per topic) until its stdin closes, and prints how many it received. In the bench's own
process it shared one GIL with the bench's ROS subscriptions: it fell behind (the server drops
frames for a slow client) and so did they (the node's middleware then sent more again).

    python bench/foxglove_viewer.py URL CHANNELS
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent.parent / "test"))
from foxglove_client import watching_everything  # noqa: E402

if __name__ == "__main__":
    client = watching_everything(sys.argv[1], int(sys.argv[2]))
    print("subscribed", flush=True)
    sys.stdin.read()
    print(client.received, flush=True)
    client.close()
