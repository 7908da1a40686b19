"""Scripted expert: privileged-state pick of the target brick, emitting the env's absolute action.

Phases (paper section 4.3): from the start pose, approach above the target while turning the
gripper top-down with its fingers across the brick's faces, descend, close, lift, and carry the brick
back toward the start pose. Each segment is a minimum-jerk blend (position lerp + rotation slerp),
so motions start and stop smoothly; per-episode speed and approach offsets come from a seeded rng.
``turn="late"`` keeps the start rotation on the way and turns once above the brick, where a wrist camera
sees the brick's yaw (on the way the brick spans 2-3 px of a 64 px policy image).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from lerobot_bboxpick import geometry
from lerobot_bboxpick.sim.env import _TOP_DOWN, LegoPickEnv

GRASP_HEIGHT = 0.008  # TCP (fingertip) height above the brick's bottom face at the grasp
PREGRASP_HEIGHT = 0.09
LIFT_HEIGHT = 0.16
OPEN_WIDTH = 0.075
CLOSED_WIDTH = 0.0
TURNS = ("early", "late")  # when the expert turns the gripper onto the brick: on the way, or above it
TURN_SECONDS = 0.8  # the late turn, above the brick


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk time scaling of s in [0, 1]."""
    return s**3 * (10 - 15 * s + 6 * s**2)


@dataclass(frozen=True)
class Waypoint:
    """A TCP pose + gripper width to reach after ``duration`` seconds."""

    T: np.ndarray
    width: float
    duration: float


def tcp_yaw(T: np.ndarray) -> float:
    """The yaw (rad) of a TCP pose ``T`` (4x4): its rotation about the vertical from the top-down pose."""
    z_turn = T[:3, :3] @ _TOP_DOWN.T
    return float(np.arctan2(z_turn[1, 0], z_turn[0, 0]))


def grasp_rotation(brick_yaw: float, current_yaw: float = 0.0) -> np.ndarray:
    """Top-down TCP rotation with the finger axis along one of the brick's faces.

    A 2x2 brick is square, so yaws a quarter turn apart grasp alike: take the one nearest
    ``current_yaw`` to spare the wrist.
    """
    k = np.round((current_yaw - brick_yaw) / (np.pi / 2))
    yaw = brick_yaw + k * np.pi / 2
    return Rotation.from_euler("z", yaw).as_matrix() @ _TOP_DOWN


class ScriptedExpert:
    """Plans a pick of ``env``'s target (or of ``brick``) at reset and replays it step by step."""

    def __init__(
        self, rng: np.random.Generator | None = None, vary: bool = True, turn: str = "early"
    ) -> None:
        if turn not in TURNS:
            raise ValueError(f"turn={turn!r}: allowed values are {', '.join(TURNS)}")
        self.rng = rng or np.random.default_rng(0)
        self.vary = vary
        self.turn = turn
        self._actions: np.ndarray | None = None
        self._i = 0

    def plan(self, env: LegoPickEnv, brick: int | None = None, in_place: bool = False) -> np.ndarray:
        """Action sequence (N, 10) for picking ``brick`` (default: the target) from the current state.

        ``in_place``: a correction of an arm already near the brick (DAgger): turn and shift onto the grasp
        at the current height (at least 1.5 cm above the grasp, gripper opening), then descend; instead of
        going back above the brick first. Either way the episode's rng draws are the same.
        """
        brick = env.target if brick is None else brick
        rng = self.rng
        speed = rng.uniform(0.85, 1.2) if self.vary else 1.0
        offset = rng.uniform(-0.01, 0.01, size=2) if self.vary else np.zeros(2)
        B = env.brick_pose(brick)
        brick_yaw = float(np.arctan2(B[1, 0], B[0, 0]))
        T0 = env.tcp_pose()
        R_grasp = grasp_rotation(brick_yaw, tcp_yaw(T0) if in_place else 0.0)
        p = B[:3, 3]

        def pose(xyz: np.ndarray, R: np.ndarray) -> np.ndarray:
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, xyz
            return T

        grasp = pose(np.array([p[0], p[1], p[2] + GRASP_HEIGHT]), R_grasp)
        if in_place:
            height = max(float(T0[2, 3] - p[2]), GRASP_HEIGHT + 0.015)
            approach = [
                Waypoint(pose(np.array([p[0], p[1], p[2] + height]), R_grasp), OPEN_WIDTH, 0.8 / speed),
                Waypoint(grasp, OPEN_WIDTH, (0.4 + 8 * (height - GRASP_HEIGHT)) / speed),
            ]
        else:
            above = np.array([p[0] + offset[0], p[1] + offset[1], p[2] + PREGRASP_HEIGHT])
            turn_late = self.turn == "late"
            approach = [
                Waypoint(pose(above, T0[:3, :3] if turn_late else R_grasp), OPEN_WIDTH, 2.2 / speed),
                *([Waypoint(pose(above, R_grasp), OPEN_WIDTH, TURN_SECONDS / speed)] if turn_late else []),
                Waypoint(
                    pose(np.array([p[0], p[1], p[2] + PREGRASP_HEIGHT * 0.5]), R_grasp),
                    OPEN_WIDTH,
                    0.6 / speed,
                ),
                Waypoint(grasp, OPEN_WIDTH, 0.9 / speed),
            ]
        waypoints = [
            *approach,
            Waypoint(grasp, CLOSED_WIDTH, 0.6),
            Waypoint(grasp, CLOSED_WIDTH, 0.25),
            Waypoint(pose(np.array([p[0], p[1], LIFT_HEIGHT]), R_grasp), CLOSED_WIDTH, 1.2 / speed),
            Waypoint(T0, CLOSED_WIDTH, 2.2 / speed),
        ]
        return self.through(T0, env.gripper_width(), waypoints, env.options.fps)

    @staticmethod
    def through(T0: np.ndarray, w0: float, waypoints: list[Waypoint], fps: int) -> np.ndarray:
        """Actions (N, 10) at ``fps`` moving from (T0, w0) through the waypoints with min-jerk segments."""
        actions = []
        T_prev, w_prev = T0, w0
        for wp in waypoints:
            n = max(1, round(wp.duration * fps))
            s = min_jerk(np.arange(1, n + 1) / n)
            slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T_prev[:3, :3], wp.T[:3, :3]])))
            R = slerp(s).as_matrix()
            pos = T_prev[:3, 3] + s[:, None] * (wp.T[:3, 3] - T_prev[:3, 3])
            width = w_prev + s * (wp.width - w_prev)
            T = np.tile(np.eye(4), (n, 1, 1))
            T[:, :3, :3], T[:, :3, 3] = R, pos
            actions.append(np.concatenate([geometry.mat_to_pose9(T), width[:, None]], axis=1))
            T_prev, w_prev = wp.T, wp.width
        return np.concatenate(actions).astype(np.float32)

    def reset(self, env: LegoPickEnv, brick: int | None = None, in_place: bool = False) -> None:
        """Plan the episode from the env's current (just reset) state (``plan``)."""
        self._actions = self.plan(env, brick, in_place)
        self._i = 0

    @property
    def done(self) -> bool:
        """All planned actions were emitted."""
        return self._actions is not None and self._i >= len(self._actions)

    def act(self) -> np.ndarray:
        """The next action (the last one again once the plan is finished)."""
        if self._actions is None:
            raise RuntimeError("call reset(env) before act()")
        a = self._actions[min(self._i, len(self._actions) - 1)]
        self._i += 1
        return a
