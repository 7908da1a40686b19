"""Serve an ASGI app with uvicorn on a socket we bind first (so port 0 gives a free port we can print)."""

from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass
from typing import Any


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host``:``port`` (port 0: a free one); a clear error when taken."""
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as e:
        sock.close()
        raise OSError(f"cannot listen on {host}:{port} ({e.strerror}); choose another --port") from e
    sock.listen(128)
    return sock


def url_of(sock: socket.socket) -> str:
    """The http URL of a bound socket."""
    host, port = sock.getsockname()[:2]
    return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"


@dataclass
class BackgroundServer:
    """A uvicorn server running on a thread; ``stop()`` shuts it down."""

    url: str
    server: Any
    thread: threading.Thread

    def stop(self, timeout: float = 10.0) -> None:
        """Ask uvicorn to exit and wait for its thread."""
        self.server.should_exit = True
        self.thread.join(timeout=timeout)


def serve_in_thread(
    app: Any, host: str = "127.0.0.1", port: int = 0, timeout_s: float = 20.0
) -> BackgroundServer:
    """Start ``app`` on a background thread and return once it accepts connections."""
    import uvicorn

    sock = bind(host, port)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="off", ws="websockets-sansio"))
    thread = threading.Thread(
        target=server.run, kwargs={"sockets": [sock]}, name="dashboard-http", daemon=True
    )
    thread.start()
    deadline = time.monotonic() + timeout_s
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            server.should_exit = True
            raise RuntimeError(f"the web server did not start within {timeout_s} s")
        time.sleep(0.02)
    return BackgroundServer(url_of(sock), server, thread)


def serve_forever(app: Any, host: str, port: int, on_ready: Any = None) -> None:
    """Run ``app`` in the foreground until Ctrl-C; ``on_ready(url)`` is called once it listens."""
    import uvicorn

    sock = bind(host, port)
    if on_ready is not None:
        on_ready(url_of(sock))
    uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="off", ws="websockets-sansio")).run(
        sockets=[sock]
    )
