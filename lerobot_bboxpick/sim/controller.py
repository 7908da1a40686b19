"""TCP pose targets -> joint targets with mink IK (solver daqp) on the arm-only model.

The env hands this a 4x4 target pose of the TCP in the table frame; the controller clamps it to the
workspace box, iterates differential IK from the current joint angles until it converges, and
reports how far the result is from the (clamped) target. When the target cannot be reached the
converged damped least-squares solution is the closest pose the arm can take, and ``clamped`` says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import mink
import numpy as np

from lerobot_bboxpick import geometry
from lerobot_bboxpick.sim.scene import ARM_JOINTS, build_robot_model, lookup

# TCP position limits in the table frame (m): above the table, inside the reach we train and test in.
WORKSPACE_LOW = np.array([0.15, -0.50, 0.0])
WORKSPACE_HIGH = np.array([0.85, 0.50, 0.55])


def limit_step(
    T_from: np.ndarray, T_to: np.ndarray, max_distance: float, max_angle: float
) -> tuple[np.ndarray, bool]:
    """``T_to`` moved back toward ``T_from`` so the step stays within ``max_distance`` (m) and
    ``max_angle`` (rad); returns the pose and whether it was limited.

    Translation and rotation are scaled by the same fraction, so the limited step lies on the
    straight (screw-free) path from ``T_from`` to ``T_to``.
    """
    distance = float(np.linalg.norm(T_to[:3, 3] - T_from[:3, 3]))
    rotvec = geometry.mat_to_axis_angle(T_from[:3, :3].T @ T_to[:3, :3])
    angle = float(np.linalg.norm(rotvec))
    fraction = min(1.0, max_distance / max(distance, 1e-12), max_angle / max(angle, 1e-12))
    if fraction >= 1.0:
        return T_to, False
    T = np.eye(4)
    T[:3, 3] = T_from[:3, 3] + fraction * (T_to[:3, 3] - T_from[:3, 3])
    T[:3, :3] = T_from[:3, :3] @ geometry.axis_angle_to_mat(fraction * rotvec)
    return T, True


@dataclass(frozen=True)
class IkResult:
    """Joint targets and how well they reach the requested pose."""

    q_arm: np.ndarray  # (6,)
    position_error: float  # m, between the IK pose and the workspace-clamped target
    rotation_error: float  # rad
    workspace_clamped: bool  # the target position left the workspace box
    unreachable: bool  # the IK did not reach the clamped target within tolerance

    @property
    def clamped(self) -> bool:
        """The executed pose differs from the requested one."""
        return self.workspace_clamped or self.unreachable


class TcpIkController:
    """Differential IK for the UR5e + UMI gripper TCP."""

    def __init__(
        self,
        posture_q: np.ndarray,
        max_iterations: int = 40,
        position_tolerance: float = 2e-4,
        rotation_tolerance: float = 2e-3,
        reach_tolerance: tuple[float, float] = (3e-3, 2e-2),
    ) -> None:
        self.model = build_robot_model()
        self.configuration = mink.Configuration(self.model)
        self._arm_q = np.array([self.model.jnt_qposadr[lookup(self.model, "joint", n)] for n in ARM_JOINTS])
        self.tcp_task = mink.FrameTask(
            "tcp", "site", position_cost=1.0, orientation_cost=0.5, lm_damping=1e-3
        )
        # A weak pull toward a nominal posture keeps the elbow up and the wrist away from flips.
        self.posture_task = mink.PostureTask(self.model, cost=1e-3)
        q0 = np.zeros(self.model.nq)
        q0[self._arm_q] = posture_q
        self.posture_task.set_target(q0)
        self.limits = [mink.ConfigurationLimit(self.model)]
        self.max_iterations = max_iterations
        self.position_tolerance = position_tolerance
        self.rotation_tolerance = rotation_tolerance
        self.reach_tolerance = reach_tolerance

    def forward(self, q_arm: np.ndarray) -> np.ndarray:
        """TCP pose (4x4, table frame) of a joint configuration."""
        q = np.zeros(self.model.nq)
        q[self._arm_q] = q_arm
        self.configuration.update(q)
        return self.configuration.get_transform_frame_to_world("tcp", "site").as_matrix()

    def solve(self, q_arm: np.ndarray, target: np.ndarray) -> IkResult:
        """Joint targets reaching ``target`` (4x4 TCP pose) starting from ``q_arm``."""
        target = np.array(target, dtype=np.float64)
        clamped_pos = np.clip(target[:3, 3], WORKSPACE_LOW, WORKSPACE_HIGH)
        workspace_clamped = bool(np.any(np.abs(clamped_pos - target[:3, 3]) > 1e-9))
        target[:3, 3] = clamped_pos
        q = np.zeros(self.model.nq)
        q[self._arm_q] = q_arm
        self.configuration.update(q)
        self.tcp_task.set_target(mink.SE3.from_matrix(target))
        tasks = [self.tcp_task, self.posture_task]
        pos_err = rot_err = np.inf
        for _ in range(self.max_iterations):
            err = self.tcp_task.compute_error(self.configuration)
            pos_err, rot_err = float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:]))
            if pos_err < self.position_tolerance and rot_err < self.rotation_tolerance:
                break
            velocity = mink.solve_ik(self.configuration, tasks, 1.0, "daqp", damping=1e-4, limits=self.limits)
            self.configuration.integrate_inplace(velocity, 1.0)
        err = self.tcp_task.compute_error(self.configuration)
        pos_err, rot_err = float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:]))
        unreachable = pos_err > self.reach_tolerance[0] or rot_err > self.reach_tolerance[1]
        return IkResult(
            q_arm=self.configuration.q[self._arm_q].copy(),
            position_error=pos_err,
            rotation_error=rot_err,
            workspace_clamped=workspace_clamped,
            unreachable=unreachable,
        )
