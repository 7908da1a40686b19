"""Where the ``bboxpick_expert`` teleoperator finds the simulator it reads.

LeRobot's CLIs build the robot and the teleoperator separately from their configs and never hand one to
the other. The expert needs the simulator's privileged state (brick poses), so the MuJoCo backend
publishes itself here under its robot id while connected, and the teleoperator looks it up by the same
id. Entries are weak: a disconnected or collected robot disappears from the table.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from lerobot_bboxpick.robots.ur5.mujoco_backend import MujocoArm

_LIVE: weakref.WeakValueDictionary[str, MujocoArm] = weakref.WeakValueDictionary()


def publish(robot_id: str, arm: MujocoArm) -> None:
    """Make ``arm`` findable under ``robot_id`` (the robot's ``--robot.id``)."""
    _LIVE[robot_id] = arm


def withdraw(robot_id: str) -> None:
    """Remove ``robot_id`` from the table (at disconnect)."""
    _LIVE.pop(robot_id, None)


def find(robot_id: str | None) -> MujocoArm:
    """The connected simulated arm of ``robot_id`` (or the only one when ``robot_id`` is None)."""
    live = dict(_LIVE)
    if robot_id is not None:
        if robot_id not in live:
            raise LookupError(
                f"no connected ur5 robot with backend=mujoco and id {robot_id!r} in this process "
                f"(connected: {sorted(live) or 'none'}); the expert teleoperator only drives the simulator"
            )
        return live[robot_id]
    if len(live) != 1:
        raise LookupError(
            f"{len(live)} simulated ur5 robots are connected ({sorted(live)}); pass --teleop.robot_id"
            if live
            else "no ur5 robot with --robot.backend=mujoco is connected in this process; the expert "
            "teleoperator reads the simulator's state, so it works with the mujoco backend only"
        )
    return next(iter(live.values()))
