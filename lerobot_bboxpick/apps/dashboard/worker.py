"""``SimWorker``: the one thread that owns every MuJoCo object and runs all simulation in order.

MuJoCo's GL contexts belong to the thread that made them, and an ``MjData`` must not be stepped by
two threads at once; so every request becomes a job on this thread's queue, and a running rollout
advances by ``tick`` between jobs. Requests from many browsers wait their turn; an exception in a
job is handed back to whoever submitted it, and one in a tick to ``on_tick_error``: the thread lives on.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

T = TypeVar("T")
log = logging.getLogger(__name__)

_STOP = object()


class SimWorker:
    """Runs submitted jobs one at a time on one thread; between jobs it calls ``tick``.

    ``tick()`` advances whatever is running and returns the seconds until it wants to run again,
    or None when nothing runs (the thread then sleeps until the next job).
    """

    def __init__(
        self,
        tick: Callable[[], float | None],
        on_tick_error: Callable[[BaseException], None],
        name: str = "mujoco-worker",
    ) -> None:
        self._tick = tick
        self._on_tick_error = on_tick_error
        self._jobs: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, fn: Callable[..., T], *args: Any) -> Future[T]:
        """Queue ``fn(*args)`` to run on the worker thread."""
        if not self._thread.is_alive():
            raise RuntimeError("the MuJoCo worker has stopped")
        future: Future[T] = Future()
        self._jobs.put((fn, args, future))
        return future

    def call(self, fn: Callable[..., T], *args: Any, timeout: float | None = None) -> T:
        """Run ``fn(*args)`` on the worker thread and return its result (or raise its exception)."""
        if threading.current_thread() is self._thread:  # a job calling another job: run it in place
            return fn(*args)
        return self.submit(fn, *args).result(timeout=timeout)

    @property
    def queued(self) -> int:
        """Jobs waiting (approximate)."""
        return self._jobs.qsize()

    def close(self, cleanup: Callable[[], None] | None = None, timeout: float = 10.0) -> None:
        """Run ``cleanup`` on the worker thread (to free GL contexts there), then stop the thread."""
        if not self._thread.is_alive():
            return
        if cleanup is not None:
            self.submit(cleanup).result(timeout=timeout)
        self._jobs.put(_STOP)
        self._thread.join(timeout=timeout)

    def _loop(self) -> None:
        delay: float | None = None
        while True:
            try:
                item = self._jobs.get(timeout=delay)
            except queue.Empty:
                item = None
            if item is _STOP:
                return
            if item is not None:
                fn, args, future = item
                if future.set_running_or_notify_cancel():
                    try:
                        future.set_result(fn(*args))
                    except BaseException as e:  # handed back to the caller; the worker goes on
                        future.set_exception(e)
            try:
                delay = self._tick()
            except Exception as e:  # a failing policy must not take the simulation down with it
                log.exception("rollout tick failed")
                self._on_tick_error(e)
                delay = None
