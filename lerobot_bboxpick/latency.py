"""UMI-style latency compensation on a real arm, as pure functions (times in seconds, one clock).

``bbox_diffusion`` applies it on the action path (``--policy.compensate_latency=true``): each new chunk
keeps only its :func:`fresh_steps`; the robot then executes them one per control tick.

* The wrist image reaches us ``camera_latency_s`` after it was captured, so an observation's time is
  its receive time minus that latency (:func:`observation_time`).
* A policy's action chunk predicted from that observation holds step ``i`` for the time
  ``obs_time + i * dt`` (UMI: the chunk starts at the observation's step). The arm trails its command
  by ``action_latency_s``, so step ``i`` must be commanded for ``obs_time + i * dt - action_latency_s``;
  steps whose command time has passed are dropped (:func:`schedule_chunk`), as UMI's ``eval_real.py``
  and ``umi_env.exec_actions`` do.

Default camera latency, 0.17 s, for a GoPro (HDMI out) through an Elgato HD60 X capture card: the value
UMI's ``eval_real.py`` uses for exactly that chain (its ``umi_env`` default is 0.125 s; users of the
same chain report 0.13-0.16 s measured). The capture card's buffering dominates it, so measure yours
(e.g. film a millisecond clock on a screen and compare) and set ``camera_latency_s``. Default action
latency, 0.1 s: UMI's ``robot_action_latency`` for a UR5e servoing with lookahead 0.1 s, gain 300.
"""

from __future__ import annotations

import math

import numpy as np

GOPRO_ELGATO_CAMERA_LATENCY_S = 0.17
UR_ACTION_LATENCY_S = 0.1


def _finite(name: str, value: float, minimum: float | None = None, strict: bool = False) -> float:
    v = float(value)
    if not math.isfinite(v) or (minimum is not None and (v <= minimum if strict else v < minimum)):
        bound = "" if minimum is None else f" and {'>' if strict else '>='} {minimum}"
        raise ValueError(f"{name}={value!r} must be finite{bound}")
    return v


def observation_time(receive_time: float, camera_latency_s: float = GOPRO_ELGATO_CAMERA_LATENCY_S) -> float:
    """When the frame received at ``receive_time`` was captured: ``receive_time - camera_latency_s``."""
    return _finite("receive_time", receive_time) - _finite("camera_latency_s", camera_latency_s, 0.0)


def fresh_steps(
    num_steps: int,
    start_time: float,
    dt: float,
    now: float,
    action_latency_s: float = UR_ACTION_LATENCY_S,
    hold_last_if_late: bool = True,
) -> np.ndarray:
    """Indices of the steps of a ``num_steps`` chunk that can still be commanded at ``now``.

    Step ``i`` is due at ``start_time + i * dt`` and must be commanded ``action_latency_s`` earlier;
    steps whose command time is ``<= now`` are dropped. If every step is late (inference took longer than
    the chunk), ``hold_last_if_late`` keeps UMI's fallback, the last step alone; otherwise none.
    """
    if int(num_steps) < 1:
        raise ValueError(f"num_steps={num_steps!r} must be >= 1")
    times = _command_times(int(num_steps), _finite("start_time", start_time), dt, action_latency_s)
    keep = _later(times, now)
    if len(keep) == 0 and hold_last_if_late:
        keep = np.array([num_steps - 1])
    return keep


def _later(times: np.ndarray, now: float) -> np.ndarray:
    return np.flatnonzero(times > _finite("now", now))


def _command_times(num_steps: int, start_time: float, dt: float, action_latency_s: float) -> np.ndarray:
    dt = _finite("dt", dt, 0.0, strict=True)
    action_latency_s = _finite("action_latency_s", action_latency_s, 0.0)
    return start_time + np.arange(num_steps) * dt - action_latency_s


def schedule_chunk(
    actions: np.ndarray,
    obs_time: float,
    dt: float,
    now: float,
    action_latency_s: float = UR_ACTION_LATENCY_S,
    hold_last_if_late: bool = True,
) -> list[tuple[np.ndarray, float]]:
    """The ``(action, target_time)`` pairs of an ``(N, 10)`` chunk still in the future at ``now``.

    Step ``i`` gets ``target_time = obs_time + i * dt - action_latency_s`` (when the arm must be
    commanded to be at it so that it actually is at ``obs_time + i * dt``); pairs with
    ``target_time <= now`` are dropped (:func:`fresh_steps`). If every step is late,
    ``hold_last_if_late`` keeps UMI's fallback: the last action, at the first step time after ``now`` on
    the chunk's ``dt`` grid; otherwise the list is empty.
    """
    a = np.asarray(actions, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] != 10:
        raise ValueError(f"actions must have shape (N, 10) with N >= 1 (pose10 per step), got {a.shape}")
    times = _command_times(len(a), _finite("obs_time", obs_time), dt, action_latency_s)
    keep = _later(times, now)
    if len(keep):
        return [(a[i].copy(), float(times[i])) for i in keep]
    if not hold_last_if_late:
        return []
    # Smallest grid index whose time is strictly after now (floor + 1 also covers now on the grid).
    k = math.floor((now - (obs_time - action_latency_s)) / dt) + 1
    return [(a[-1].copy(), obs_time + k * dt - action_latency_s)]


def command_send_time(target_time: float, schedule_delay_s: float) -> float:
    """When to call ``RtdeArm.command`` so its target is due at ``target_time``: the arm schedules a target
    ``schedule_delay_s`` (``RtdeArm.schedule_delay_s``) after it arrives."""
    return _finite("target_time", target_time) - _finite("schedule_delay_s", schedule_delay_s, 0.0)
