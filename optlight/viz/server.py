"""A meshcat server on the loopback interface only, run as a subprocess that cannot outlive us.

meshcat 0.3.2's own server binds its ZeroMQ socket to 127.0.0.1 but its web server to every
interface (tornado's ``listen(port)`` without an address), registers an ``atexit`` hook and prints
to our stdout. :class:`MeshcatServer` instead runs ``python -m optlight.viz.server``: the same
bridge, with the web server bound to 127.0.0.1, its log in a temporary file, and a watchdog that
stops it when its parent process is gone (even after a SIGKILL of the parent). The context manager
ends the subprocess on exit, on an exception and on Ctrl-C.
"""

from __future__ import annotations

import argparse
import os
import select
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable
from types import TracebackType
from typing import Any

import tornado.ioloop
import tornado.web
import zmq
from meshcat.servers.zmqserver import (
    VIEWER_HTML,
    VIEWER_ROOT,
    StaticFileHandlerNoCache,
    WebSocketHandler,
    ZMQWebSocketBridge,
)

from optlight.errors import OptlightError

#: The only interface the server listens on.
LOOPBACK = "127.0.0.1"


class _LoopbackApplication(tornado.web.Application):
    """A tornado application that listens on the loopback interface whatever it is asked."""

    def listen(self, port: int, address: str | None = None, **kwargs: Any) -> Any:
        """Listen on 127.0.0.1:``port`` (``address`` is ignored on purpose)."""
        return super().listen(port, address=LOOPBACK, **kwargs)


class LoopbackBridge(ZMQWebSocketBridge):
    """meshcat's ZeroMQ ↔ WebSocket bridge with its web server bound to 127.0.0.1."""

    def make_app(self) -> tornado.web.Application:
        """The routes of meshcat's bridge (viewer files, WebSocket) on a loopback-only application."""
        return _LoopbackApplication(
            [
                (
                    r"/static/(.*)",
                    StaticFileHandlerNoCache,
                    {"path": VIEWER_ROOT, "default_filename": VIEWER_HTML},
                ),
                (r"/", WebSocketHandler, {"bridge": self}),
            ]
        )


class MeshcatServer:
    """A loopback meshcat server subprocess: ``with MeshcatServer() as server: server.web_url``.

    :meth:`send` replays meshcat commands (``(type, path, packed)`` as meshcat's ZeroMQ protocol
    carries them) to the server, which keeps the scene and serves it to every browser that opens
    :attr:`web_url`. Nothing is printed; the server's own log goes to a temporary file that is
    quoted in the error when the server fails to start.
    """

    def __init__(self, start_timeout_s: float = 20.0, reply_timeout_s: float = 10.0) -> None:
        self.start_timeout_s = start_timeout_s
        self.reply_timeout_s = reply_timeout_s
        self.process: subprocess.Popen[bytes] | None = None
        self.zmq_url = ""
        self.web_url = ""
        self._log: Any = None

    def __enter__(self) -> MeshcatServer:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def start(self) -> None:
        """Start the subprocess and read its ZeroMQ and web URLs (bounded by ``start_timeout_s``)."""
        self._log = tempfile.TemporaryFile()
        self.process = subprocess.Popen(
            [sys.executable, "-u", "-m", "optlight.viz.server", "--parent-pid", str(os.getpid())],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._log,
        )
        try:
            urls = self._read_urls()
        except BaseException:
            self.stop()
            raise
        self.zmq_url, self.web_url = urls["zmq_url"], urls["web_url"]

    def _read_urls(self) -> dict[str, str]:
        """The ``zmq_url=…`` and ``web_url=…`` lines the subprocess prints when it is ready."""
        assert self.process is not None and self.process.stdout is not None
        fd = self.process.stdout.fileno()
        deadline = time.monotonic() + self.start_timeout_s
        out = b""
        while out.count(b"\n") < 2:
            remaining = deadline - time.monotonic()
            chunk = os.read(fd, 4096) if remaining > 0 and select.select([fd], [], [], remaining)[0] else b""
            if not chunk:
                raise OptlightError(f"the meshcat server did not start: {self._log_text() or 'no output'}")
            out += chunk
        return dict(line.split("=", 1) for line in out.decode().split())

    def _log_text(self) -> str:
        if self._log is None:
            return ""
        self._log.seek(0)
        return self._log.read().decode(errors="replace").strip()[-2000:]

    def send(self, commands: Iterable[tuple[str, str, bytes]]) -> None:
        """Send meshcat commands to the server, waiting for each acknowledgement."""
        socket: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.REQ)
        socket.setsockopt(zmq.RCVTIMEO, int(self.reply_timeout_s * 1000))
        socket.setsockopt(zmq.SNDTIMEO, int(self.reply_timeout_s * 1000))
        socket.setsockopt(zmq.LINGER, 0)
        try:
            socket.connect(self.zmq_url)
            for kind, path, packed in commands:
                socket.send_multipart([kind.encode(), path.encode(), packed])
                reply = socket.recv()
                if reply != b"ok":
                    raise OptlightError(
                        f"the meshcat server refused {kind} {path}: {reply.decode(errors='replace')}"
                    )
        except zmq.error.Again:
            raise OptlightError(f"the meshcat server at {self.zmq_url} did not answer") from None
        finally:
            socket.close()

    def stop(self) -> None:
        """End the subprocess (SIGTERM, then SIGKILL after 5 s) and close its log. Idempotent."""
        if self.process is not None:
            if self.process.poll() is None:
                self.process.terminate()
                try:
                    self.process.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait()
            if self.process.stdout is not None:
                self.process.stdout.close()
            self.process = None
        if self._log is not None:
            self._log.close()
            self._log = None


def main(argv: list[str] | None = None) -> None:
    """Run the loopback bridge until SIGTERM, Ctrl-C, or the parent process ends."""
    parser = argparse.ArgumentParser(description="meshcat server on 127.0.0.1 (started by optlight)")
    parser.add_argument("--parent-pid", type=int, default=None, help="stop when this process is gone")
    args = parser.parse_args(argv)
    bridge = LoopbackBridge(host=LOOPBACK)
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    sys.stdout = sys.stderr  # anything the bridge prints later goes to the log, not the pipe
    if args.parent_pid is not None:
        parent = args.parent_pid

        def check_parent() -> None:
            if os.getppid() != parent:
                tornado.ioloop.IOLoop.current().stop()

        tornado.ioloop.PeriodicCallback(check_parent, 500).start()
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
