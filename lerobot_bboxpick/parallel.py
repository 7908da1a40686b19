"""Worker pools of ``bboxpick-collect``, ``bboxpick-rollouts`` and ``bboxpick-suite``: local processes
or a Ray cluster.

``worker_pool(workers, ray_address)`` is a context manager yielding a pool with multiprocessing's
interface (``imap_unordered``, ``imap``, ``map``, ...). Without an address the pool is multiprocessing's,
with spawned processes (each opens its own EGL context; nothing is inherited from the parent). With one
it is Ray's drop-in ``ray.util.multiprocessing.Pool``: one Ray actor per worker, each holding a CPU, so
Ray places them across the cluster's nodes. ``ray_address`` is what ``ray.init`` takes: ``"auto"`` (the
cluster this machine joined with ``ray start``), ``"ray://<head>:10001"`` (Ray Client) or ``"local"`` (a
new Ray instance on this machine with ``workers`` CPUs). Ray is an optional extra, imported only then.
See docs/ray.md.
"""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

RAY_INSTALL_HINT = 'pip install "lerobot_policy_bboxpick[ray]"'
# Environment variables copied from this process to every Ray worker when set here (a Ray worker's
# environment is its node's, not ours): headless rendering, offline Hugging Face Hub, thread counts.
FORWARDED_ENV = (
    "MUJOCO_GL",
    "PYOPENGL_PLATFORM",
    "HF_HUB_OFFLINE",
    "HF_DATASETS_OFFLINE",
    "OMP_NUM_THREADS",
)


def worker_env() -> dict[str, str]:
    """The environment variables a Ray worker gets: those of ``FORWARDED_ENV`` set in this process, and
    ``MUJOCO_GL=egl`` unless set otherwise (it must be in place before the worker imports MuJoCo)."""
    env = {name: os.environ[name] for name in FORWARDED_ENV if name in os.environ}
    env.setdefault("MUJOCO_GL", "egl")
    return env


def check_ray(ray_address: str | None) -> None:
    """Raise an ImportError naming the extra to install if ``ray_address`` is given and Ray is missing
    (cheap: Ray is looked up, not imported; the configs call it so that a run fails before any work)."""
    if ray_address and importlib.util.find_spec("ray") is None:
        raise ImportError(f"ray_address={ray_address!r} needs Ray, an optional extra: {RAY_INSTALL_HINT}")


@contextmanager
def worker_pool(
    workers: int,
    ray_address: str | None = None,
    ray_remote_args: dict[str, Any] | None = None,
    **kwargs: Any,
) -> Iterator[Any]:
    """A pool of ``workers`` processes: spawned local ones, or Ray actors when ``ray_address`` is given.

    ``kwargs`` go to the pool's constructor (``maxtasksperchild``, ``initializer``, ``initargs``).
    ``ray_remote_args`` (Ray only) update the actors' options; the default reserves one CPU per actor and
    sets the environment of ``worker_env``. Ray is initialized here when it is not yet (``ray_address`` as
    ``ray.init``'s address) and shut down again on exit; a Ray already initialized by the caller is used
    as it is. On exit the pool is terminated, as multiprocessing's ``with Pool(...)`` does.
    """
    if not ray_address:
        with mp.get_context("spawn").Pool(workers, **kwargs) as pool:
            yield pool
        return
    check_ray(ray_address)
    import ray
    from ray.util.multiprocessing import Pool as RayPool

    started = not ray.is_initialized()
    if started:
        local = {"num_cpus": workers, "include_dashboard": False} if ray_address == "local" else {}
        ray.init(address=ray_address, **local)
    try:
        remote_args = {"num_cpus": 1, "runtime_env": {"env_vars": worker_env()}, **(ray_remote_args or {})}
        with RayPool(workers, ray_address=ray_address, ray_remote_args=remote_args, **kwargs) as pool:
            yield RaisingPool(pool)
    finally:
        if started:
            ray.shutdown()


class RaisingPool:
    """Ray's Pool whose ``imap`` and ``imap_unordered`` raise a worker's exception, as multiprocessing's do.

    Ray's iterators yield the failure as a value instead (its ``map`` and ``apply`` raise it); every
    other attribute is the wrapped pool's.
    """

    def __init__(self, pool: Any) -> None:
        self.pool = pool

    def __getattr__(self, name: str) -> Any:
        if name == "pool":  # not set yet (e.g. while copying): no recursion
            raise AttributeError(name)
        return getattr(self.pool, name)

    def imap(self, func: Callable, iterable: Iterable, chunksize: int = 1) -> Iterator[Any]:
        """Results in the order of ``iterable``; a worker's exception is raised here."""
        return _raise_failures(self.pool.imap(func, iterable, chunksize=chunksize))

    def imap_unordered(self, func: Callable, iterable: Iterable, chunksize: int = 1) -> Iterator[Any]:
        """Results as they finish; a worker's exception is raised here."""
        return _raise_failures(self.pool.imap_unordered(func, iterable, chunksize=chunksize))


def _raise_failures(results: Iterable[Any]) -> Iterator[Any]:
    from ray.util.multiprocessing.pool import PoolTaskError

    for result in results:
        if isinstance(result, PoolTaskError):  # the task raised: re-raise its own exception
            raise result.underlying
        if isinstance(result, Exception):  # a Ray failure (e.g. the actor died)
            raise result
        yield result
