"""The public port of the built-in Foxglove server: a thin WebSocket relay in front of foxglove-sdk.

foxglove-sdk 0.30 (the newest release) accepts only the `foxglove.sdk.v1` subprotocol and sends
no server metadata. Viewers released before December 2025 (Lichtblick up to at least 1.10.8,
older Foxglove) ask for `foxglove.websocket.v1`, which carries the same messages, and are refused
with HTTP 400; and viewers offer the 3D panel's publish tools (clicked_point, initialpose) only
to a data source whose serverInfo metadata names a `ROS_DISTRO`. The relay accepts either
subprotocol, passes every frame through unchanged to the sdk server on a loopback port, and adds
the metadata to the one serverInfo message. It runs its own asyncio loop on one thread.
"""
import asyncio
import json
import logging
import threading

from websockets.asyncio.client import connect
from websockets.asyncio.server import serve
from websockets.exceptions import ConnectionClosed, InvalidHandshake

SDK_SUBPROTOCOL = "foxglove.sdk.v1"
# Preferred first: a viewer offering both gets the sdk's own name.
SUBPROTOCOLS = [SDK_SUBPROTOCOL, "foxglove.websocket.v1"]
# websockets logs every connection and the server's start and stop at INFO; the simulator's log
# keeps its warnings and errors only.
LOG = logging.getLogger("vplayground.foxglove_front")
LOG.setLevel(logging.WARNING)


def with_metadata(message, metadata):
    """The sdk's serverInfo message with `metadata` merged into its own (other messages as they are)."""
    if not isinstance(message, str):
        return message
    info = json.loads(message)
    if info.get("op") != "serverInfo":
        return message
    info["metadata"] = {**info.get("metadata", {}), **metadata}
    return json.dumps(info, separators=(",", ":"))


class ProtocolFront:
    def __init__(self, upstream_url, host, port, metadata, log):
        """Listens on host:port (0: any free port) at once; raises OSError if it cannot. `log`
        (the simulator's logger) hears of each viewer coming and going."""
        self.upstream_url = upstream_url
        self.metadata = dict(metadata)
        self.log = log
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name="foxglove-front", daemon=True)
        self.thread.start()
        try:
            self.server = self._run(self._listen(host, port))
        except BaseException:
            self._stop_loop()
            raise
        self.port = self.server.sockets[0].getsockname()[1]

    def stop(self):
        self.server.close()  # and the viewers' connections, whose relays then close theirs upstream
        self._run(self.server.wait_closed())
        self._stop_loop()

    def _run(self, coroutine):
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result()

    def _stop_loop(self):
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join()
        self.loop.close()

    async def _listen(self, host, port):
        # No compression (it would cost more CPU than the relay), no keepalive pings (the sdk
        # server sends none either), no message size limit (a scenery mesh is megabytes).
        return await serve(self._relay, host, port, subprotocols=SUBPROTOCOLS, compression=None,
                           ping_interval=None, max_size=None, logger=LOG)

    async def _relay(self, viewer):
        peer = "{}:{}".format(*viewer.remote_address[:2])
        self.log.info(f"foxglove: viewer {peer} connected ({viewer.subprotocol})")
        try:
            async with connect(self.upstream_url, subprotocols=[SDK_SUBPROTOCOL], compression=None,
                               ping_interval=None, max_size=None, logger=LOG) as sdk:
                directions = [asyncio.create_task(self._downstream(sdk, viewer)),
                              asyncio.create_task(self._upstream(viewer, sdk))]
                # Whichever side closes first ends both.
                _, pending = await asyncio.wait(directions, return_when=asyncio.FIRST_COMPLETED)
                for task in pending:
                    task.cancel()
        except (OSError, InvalidHandshake) as error:  # the sdk server is stopping
            await viewer.close(1011, f"the Foxglove server is not available: {error}"[:120])
        finally:
            self.log.info(f"foxglove: viewer {peer} left")

    async def _downstream(self, sdk, viewer):
        try:
            await viewer.send(with_metadata(await sdk.recv(), self.metadata))  # the sdk's first: serverInfo
            async for message in sdk:
                await viewer.send(message)
        except ConnectionClosed:
            pass

    async def _upstream(self, viewer, sdk):
        try:
            async for message in viewer:
                await sdk.send(message)
        except ConnectionClosed:
            pass
