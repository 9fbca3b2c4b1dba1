"""A meshcat server that listens on 127.0.0.1 only and serves the viewer page with an overlay.

meshcat's own server (``meshcat.servers.zmqserver``) binds its ZeroMQ socket to
127.0.0.1 but its web server to every interface (0.0.0.0 and [::]), and it outlives a
parent killed by a signal. This module runs the same bridge (its ``ZMQWebSocketBridge``,
the real meshcat server) with these changes:

* the web server listens on 127.0.0.1 only;
* the page at ``/static/`` is meshcat's page with the overlay (title, HTML legend, page
  script, amplification slider) last sent by the ZeroMQ command ``set_overlay``;
* a websocket message ``{"type": "closedloop", ...}`` from the page (the slider) is kept,
  the latest one, until the ZeroMQ command ``get_control`` fetches it (JSON, ``{}`` if
  none);
* it stops when its parent process is gone (checked every ``PARENT_POLL`` s) or on SIGTERM.

:func:`start_server` runs it as a child process (this file as a script, so that the
server does not import pinocchio); :func:`insert_overlay` puts an overlay into a page (the
live one here, the static one in :mod:`closedloop.viewer.viewer`).
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import re
import signal
import subprocess
import sys
import tempfile
import threading

HOST = "127.0.0.1"
#: Seconds between two checks that the parent process is still there.
PARENT_POLL = 0.5
#: Seconds to wait for the server to print its addresses, and for it to stop.
START_TIMEOUT, STOP_TIMEOUT = 30.0, 5.0
SET_OVERLAY, GET_CONTROL = b"set_overlay", b"get_control"
_TITLE = re.compile(r"<title>.*?</title>", re.S)


def insert_overlay(page: str, overlay: dict) -> str:
    """``page`` with the overlay's ``title`` and its ``body`` HTML placed before ``</body>``."""
    title = f"<title>{overlay.get('title', 'MeshCat')}</title>"
    page = _TITLE.sub(lambda _: title, page, count=1)
    head, sep, tail = page.rpartition("</body>")
    if not sep:
        return page + overlay.get("body", "")
    return head + overlay.get("body", "") + sep + tail


def start_server() -> tuple[subprocess.Popen, str, str]:
    """Start the server as a child process; returns (process, ZeroMQ URL, web URL).

    Raises:
        RuntimeError: the server did not start: the interpreter cannot be run, the server
            exited (its last line on stderr is in the message) or did not give its
            addresses within ``START_TIMEOUT`` s (it is stopped).
    """
    log = tempfile.TemporaryFile()  # the server's stderr: a pipe not read would fill up
    try:
        proc = subprocess.Popen(
            [sys.executable, "-I", "-u", os.path.abspath(__file__), str(os.getpid())],
            stdout=subprocess.PIPE,
            stderr=log,
            stdin=subprocess.DEVNULL,
            start_new_session=True,  # Ctrl-C in a terminal reaches the parent, which stops it
        )
    except OSError as e:
        log.close()
        raise RuntimeError(
            f"cannot run {sys.executable!r} for the meshcat server ({e.strerror or e})"
        ) from None
    with log:
        found: queue.Queue = queue.Queue()
        threading.Thread(target=_read_urls, args=(proc.stdout, found), daemon=True).start()
        try:
            urls, timed_out = found.get(timeout=START_TIMEOUT), False
        except queue.Empty:
            urls, timed_out = {}, True
        if len(urls) == 2:
            return proc, urls["zmq_url"], urls["web_url"]
        if not timed_out:  # it closed its stdout: it is exiting, with its own code
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(STOP_TIMEOUT)
        stop_server(proc)
        if timed_out:
            raise RuntimeError(f"the meshcat server gave no address within {START_TIMEOUT:g} s")
        log.seek(0)
        lines = log.read().decode("utf-8", "replace").strip().splitlines()
        last = f": {lines[-1].strip()}" if lines else ""
        raise RuntimeError(
            f"the meshcat server exited with code {proc.returncode} before starting{last}"
        )


def _read_urls(stream, found: queue.Queue) -> None:
    """Put the server's {"zmq_url": ..., "web_url": ...} into ``found`` once both are read
    from its stdout ``stream``, or what was read at its end; then close the stream."""
    urls = {}
    with stream:
        for line in stream:
            key, _, value = line.decode("utf-8", "replace").strip().partition("=")
            if key in ("zmq_url", "web_url"):
                urls[key] = value
            if len(urls) == 2:
                break
    found.put(urls)


def stop_server(proc: subprocess.Popen) -> None:
    """Stop a server of :func:`start_server` (SIGTERM, then SIGKILL) and reap it."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _main(parent: int) -> None:  # pragma: no cover - runs in the child process
    import tornado.ioloop
    import tornado.web
    from meshcat.servers.zmqserver import (
        VIEWER_HTML,
        VIEWER_ROOT,
        StaticFileHandlerNoCache,
        WebSocketHandler,
        ZMQWebSocketBridge,
    )

    class LocalApplication(tornado.web.Application):
        def listen(self, port, address=None, **kwargs):
            return super().listen(port, address=HOST, **kwargs)

    class PageHandler(tornado.web.RequestHandler):
        def initialize(self, bridge):
            self.bridge = bridge

        def get(self):
            with open(os.path.join(VIEWER_ROOT, VIEWER_HTML), encoding="utf-8") as f:
                page = f.read()
            self.set_header("Cache-Control", "no-store")
            self.write(insert_overlay(page, self.bridge.overlay))

    class ControlHandler(WebSocketHandler):
        def on_message(self, message):
            try:
                data = json.loads(message)
            except (TypeError, ValueError):
                data = None
            if isinstance(data, dict) and data.get("type") == "closedloop":
                self.bridge.control = data
            else:
                super().on_message(message)

    class LocalBridge(ZMQWebSocketBridge):
        def __init__(self, **kwargs):
            self.overlay, self.control = {}, {}
            super().__init__(**kwargs)

        def make_app(self):
            return LocalApplication(
                [
                    (r"/static/", PageHandler, {"bridge": self}),
                    (r"/static/(.*)", StaticFileHandlerNoCache, {"path": VIEWER_ROOT}),
                    (r"/", ControlHandler, {"bridge": self}),
                ]
            )

        def handle_zmq(self, frames):
            if frames[0] == SET_OVERLAY:
                self.overlay = json.loads(frames[1].decode("utf-8"))
                self.zmq_socket.send(b"ok")
            elif frames[0] == GET_CONTROL:
                self.zmq_socket.send(json.dumps(self.control).encode("utf-8"))
                self.control = {}
            else:
                super().handle_zmq(frames)

    bridge = LocalBridge(host=HOST)
    loop = tornado.ioloop.IOLoop.current()
    signal.signal(signal.SIGTERM, lambda *_: loop.add_callback_from_signal(loop.stop))

    def check_parent():
        if os.getppid() != parent:
            loop.stop()

    tornado.ioloop.PeriodicCallback(check_parent, 1000.0 * PARENT_POLL).start()
    print(f"zmq_url={bridge.zmq_url}")
    print(f"web_url={bridge.web_url}")
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":  # pragma: no cover
    _main(int(sys.argv[1]))
