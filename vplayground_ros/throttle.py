"""Warnings that anyone on the network can cause (a refused input, a client's garbage): a few
of each kind in a while, then a count of those held back. One per message had let a client
flood the log with thousands of lines, and a Foxglove client's garbage flood every other
client's status queue until the sdk dropped them."""
import re
import threading
import time

PERIOD = 10.0      # s: the window each kind's warnings are counted in
BURST = 5          # warnings of one kind that go out in a window
MAX_KINDS = 1024   # kinds remembered (their names are ours, but a bound costs nothing)


class Throttle:
    def __init__(self, period=PERIOD, burst=BURST, clock=time.monotonic):
        self.period, self.burst, self.clock = period, burst, clock
        self._windows = {}  # kind -> [window start, warnings sent in it, held back since the last sent]
        self._lock = threading.Lock()

    def admit(self, kind):
        """How many warnings of `kind` were held back since the last that went out (0 or more)
        when this one may go out, else None (it is counted as held back)."""
        now = self.clock()
        with self._lock:
            window = self._windows.get(kind)
            if window is None or now - window[0] >= self.period:
                if window is None and len(self._windows) >= MAX_KINDS:
                    self._windows.clear()
                held = window[2] if window is not None else 0
                self._windows[kind] = [now, 1, 0]
                return held
            if window[1] < self.burst:
                window[1] += 1
                held, window[2] = window[2], 0
                return held
            window[2] += 1
            return None


    def passes(self, kind, text):
        """`text` when a warning of `kind` may go out now, with the count of those held back
        since the last one; else None."""
        held = self.admit(kind)
        return None if held is None else text + held_note(held, self.period)


def held_note(held, period=PERIOD):
    return f" ({held} more like it in the {period:g} s before were not logged)" if held else ""


class ThrottledLog:
    """A logger whose warnings go through a Throttle, their kind the first word (the input's
    name: `cmd_vel`, `clicked_point`, a robot's command topic); everything else passes on."""

    def __init__(self, log, throttle=None):
        self._log = log
        self._throttle = throttle or Throttle()

    def warning(self, text):
        text = self._throttle.passes(re.match(r"\S*", text).group(0)[:80], text)
        if text is not None:
            self._log.warning(text)

    def __getattr__(self, name):
        return getattr(self._log, name)
