"""Safety limits of the UR5 driver, shared by every backend.

A command is refused (``UnsafeActionError``, naming the field and what is allowed) when it is
malformed, non-finite, or outside the workspace box; a valid command is then limited to the TCP
speed and acceleration bounds before it reaches the arm. The defaults are the ``lego_pick`` env's
(the policy was trained under them): workspace box of ``sim/controller.py``, 0.5 m/s, 1.5 rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lerobot_bboxpick import geometry
from lerobot_bboxpick.sim.controller import WORKSPACE_HIGH, WORKSPACE_LOW, limit_step
from lerobot_bboxpick.sim.scene import MAX_GRIPPER_WIDTH

POSE10_FIELDS = ("x", "y", "z", "r00", "r01", "r02", "r10", "r11", "r12", "gripper_width")


class UnsafeActionError(ValueError):
    """An action the driver refuses to send to the arm."""


@dataclass
class SafetyLimits:
    """Bounds every commanded TCP target must respect (table frame, metres, radians, seconds)."""

    workspace_low: list[float] = field(default_factory=lambda: WORKSPACE_LOW.tolist())
    workspace_high: list[float] = field(default_factory=lambda: WORKSPACE_HIGH.tolist())
    max_tcp_speed: float = 0.5  # m/s
    max_tcp_angular_speed: float = 1.5  # rad/s
    max_tcp_acceleration: float = 2.0  # m/s^2, on the commanded target's velocity
    max_gripper_width: float = MAX_GRIPPER_WIDTH

    def __post_init__(self) -> None:
        low, high = np.asarray(self.workspace_low, float), np.asarray(self.workspace_high, float)
        if low.shape != (3,) or high.shape != (3,) or not np.all(high > low):
            raise ValueError(
                f"workspace_low={self.workspace_low} / workspace_high={self.workspace_high} must be three "
                "numbers each (x, y, z in m) with high > low on every axis"
            )
        for name in ("max_tcp_speed", "max_tcp_angular_speed", "max_tcp_acceleration", "max_gripper_width"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}={getattr(self, name)!r} must be > 0")

    def check_pose10(self, action: np.ndarray | list[float]) -> np.ndarray:
        """``action`` as float64 (10,) if it is a valid absolute pose10 target inside the workspace.

        Raises ``UnsafeActionError`` naming the offending field otherwise (nothing is sent then).
        """
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (10,):
            raise UnsafeActionError(
                f"action must have 10 values {POSE10_FIELDS} (absolute TCP pose in the table frame + "
                f"gripper width), got shape {a.shape}"
            )
        bad = [POSE10_FIELDS[i] for i in range(10) if not np.isfinite(a[i])]
        if bad:
            raise UnsafeActionError(f"action field(s) {bad} are not finite: {a.tolist()}")
        low, high = np.asarray(self.workspace_low), np.asarray(self.workspace_high)
        for i, axis in enumerate("xyz"):
            if not low[i] <= a[i] <= high[i]:
                raise UnsafeActionError(
                    f"action field {axis}={a[i]:.4f} m is outside the workspace box "
                    f"[{low[i]:.3f}, {high[i]:.3f}] (SafetyLimits.workspace_low/high)"
                )
        for rows, name in ((slice(3, 6), "r00..r02"), (slice(6, 9), "r10..r12")):
            if np.linalg.norm(a[rows]) < 1e-6:
                raise UnsafeActionError(f"action fields {name} (a rot6d row) must not be all zero")
        if not -1e-6 <= a[9] <= self.max_gripper_width + 1e-6:
            raise UnsafeActionError(
                f"action field gripper_width={a[9]:.4f} m is outside [0, {self.max_gripper_width}]"
            )
        return a

    def limit_velocity(
        self, T_from: np.ndarray, T_to: np.ndarray, dt: float, v_prev: np.ndarray | None = None
    ) -> tuple[np.ndarray, bool]:
        """``T_to`` pulled back toward ``T_from`` so the move over ``dt`` respects the speed bounds and,
        given the previous linear velocity ``v_prev`` (m/s), the acceleration bound; returns the pose and
        whether it was limited. The limited pose lies on the straight path from ``T_from`` to ``T_to``."""
        max_distance = self.max_tcp_speed * dt
        if v_prev is not None:
            # The speed along the new direction may grow by at most max_acceleration * dt.
            max_distance = min(max_distance, (np.linalg.norm(v_prev) + self.max_tcp_acceleration * dt) * dt)
        return limit_step(T_from, T_to, max_distance, self.max_tcp_angular_speed * dt)


def pose10_to_target(a: np.ndarray) -> tuple[np.ndarray, float]:
    """A checked pose10 as (4x4 TCP pose, gripper width)."""
    return geometry.pose9_to_mat(a[:9]), float(a[9])
