"""Recovery demonstrations: the expert re-planning from a state a policy gets itself into.

The scripted expert never errs, so its demos never show how to get back on course; a policy that
drifts a few centimetres (or bumps the brick on a bad grasp) meets states no demo covers. A recovery
episode first drives the arm off the expert's path with an unrecorded *lead-in*, then records the
expert's fresh plan from that state (DART-style corrective data, without labelling the mistake):

* ``offset``: toward a point 2-5 cm beside the target, between grasp and pre-grasp height, with a yaw
  error of up to 25 degrees, stopped somewhere along the way;
* ``failed_grasp``: a descent 1-1.8 cm off the target, a close and a re-open (the brick may be pushed).

Which episodes get a lead-in, and its kind and size, are drawn from the episode seed, so a collection
is reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from lerobot_bboxpick.data.collect import ExpertRecorder, run_expert
from lerobot_bboxpick.sim.expert import (
    GRASP_HEIGHT,
    OPEN_WIDTH,
    PREGRASP_HEIGHT,
    ScriptedExpert,
    Waypoint,
    grasp_rotation,
)

LEAD_INS = ("offset", "failed_grasp")


def lead_in_actions(env: Any, kind: str, rng: np.random.Generator) -> np.ndarray:
    """Actions (N, 10) from the env's current state that leave the arm off the expert's path."""
    if kind not in LEAD_INS:
        raise ValueError(f"kind={kind!r} is not a lead-in; valid kinds: {', '.join(LEAD_INS)}")
    brick = env.brick_pose(env.target)
    p = brick[:3, 3]
    yaw = float(np.arctan2(brick[1, 0], brick[0, 0]))
    angle = rng.uniform(0, 2 * np.pi)
    direction = np.array([np.cos(angle), np.sin(angle), 0.0])
    T0, fps = env.tcp_pose(), env.options.fps

    def pose(xyz: np.ndarray, yaw_error: float = 0.0) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("z", yaw_error).as_matrix() @ grasp_rotation(yaw)
        T[:3, 3] = xyz
        return T

    if kind == "offset":
        height = rng.uniform(GRASP_HEIGHT + 0.01, PREGRASP_HEIGHT)
        goal = pose(
            p + direction * rng.uniform(0.02, 0.05) + [0, 0, height], rng.uniform(-1, 1) * np.radians(25)
        )
        actions = ScriptedExpert.through(T0, env.gripper_width(), [Waypoint(goal, OPEN_WIDTH, 2.4)], fps)
        return actions[: max(1, int(len(actions) * rng.uniform(0.6, 1.0)))]
    miss = p + direction * rng.uniform(0.01, 0.018)
    waypoints = [
        Waypoint(pose(miss + [0, 0, PREGRASP_HEIGHT]), OPEN_WIDTH, 2.2),
        Waypoint(pose(miss + [0, 0, GRASP_HEIGHT]), OPEN_WIDTH, 1.0),
        Waypoint(pose(miss + [0, 0, GRASP_HEIGHT]), 0.0, 0.6),
        Waypoint(pose(miss + [0, 0, GRASP_HEIGHT]), OPEN_WIDTH, 0.5),
    ]
    return ScriptedExpert.through(T0, env.gripper_width(), waypoints, fps)


@dataclass(frozen=True)
class RecoveryRecorder(ExpertRecorder):
    """``bboxpick-collect --recovery=<fraction>``: that fraction of episodes are recovery episodes."""

    fraction: float = 0.3

    def __post_init__(self) -> None:
        if not 0.0 <= self.fraction <= 1.0:
            raise ValueError(f"recovery={self.fraction!r} must be a fraction in [0, 1]")

    @property
    def run_key(self) -> dict:
        """The fraction decides which seeds are recoveries: a resumed collection must keep it (and the
        expert's turn, when late)."""
        return {"recovery": self.fraction, **(super().run_key or {})}

    def __call__(self, env: Any, seed: int) -> tuple[list[dict], str]:
        """The seed's episode: a plain expert demo, or a lead-in (not recorded) and the recovery."""
        rng = np.random.default_rng([int(seed), 0x5EC0])  # its own stream: the scene's is untouched
        obs, info = env.reset(seed=seed)
        if rng.random() < self.fraction:
            for action in lead_in_actions(env, str(rng.choice(LEAD_INS)), rng):
                obs, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    break
        expert = ScriptedExpert(np.random.default_rng(seed), turn=self.turn)
        expert.reset(env)
        return run_expert(env, obs, info, expert)
