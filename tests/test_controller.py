"""mink IK + joint position actuators: reach, clamping of unreachable targets."""

import numpy as np
import pytest

from lerobot_bboxpick import geometry
from lerobot_bboxpick.sim.controller import WORKSPACE_HIGH, TcpIkController, limit_step
from lerobot_bboxpick.sim.env import LegoPickEnv, _start_joint_angles, start_rotation


def _target(xyz, R=None) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = start_rotation() if R is None else R
    T[:3, 3] = xyz
    return T


def test_ik_alone_converges_to_sub_millimetre():
    controller = TcpIkController(np.array(_start_joint_angles()))
    q = np.array(_start_joint_angles())
    for xyz in ([0.55, 0.1, 0.08], [0.7, -0.2, 0.02], [0.45, 0.25, 0.2]):
        result = controller.solve(q, _target(xyz))
        reached = controller.forward(result.q_arm)
        assert np.linalg.norm(reached[:3, 3] - xyz) < 5e-4
        assert not result.clamped


def test_env_reaches_a_reachable_target_within_2_mm(grid_env):
    grid_env.reset(seed=0)
    for xyz in ([0.55, 0.12, 0.06], [0.66, -0.15, 0.03]):
        action = np.r_[geometry.mat_to_pose9(_target(xyz)), 0.05]
        for _ in range(50):  # 2.5 s: the arm gets there and settles
            obs, _, _, _, info = grid_env.step(action)
        error_mm = 1000 * np.linalg.norm(obs["agent_pos"][:3] - xyz)
        assert error_mm < 2.0, error_mm
        assert not info["ik_clamped"]
        assert abs(obs["agent_pos"][9] - 0.05) < 0.002  # the gripper width follows too


def test_unreachable_target_is_clamped_and_flagged(grid_env):
    grid_env.reset(seed=0)
    far = np.r_[geometry.mat_to_pose9(_target([1.4, 0.0, 0.3])), 0.05]
    for _ in range(30):
        obs, _, _, _, info = grid_env.step(far)
    assert info["ik_clamped"]
    # The arm went to the closest pose it can take: toward the target, inside the workspace box.
    assert obs["agent_pos"][0] > 0.6 and obs["agent_pos"][0] <= WORKSPACE_HIGH[0] + 1e-3
    assert np.isfinite(obs["agent_pos"]).all()


def test_limit_step_keeps_the_straight_path_and_the_bounds():
    R_end = geometry.axis_angle_to_mat(np.array([0.0, 0.0, 0.6]))
    T_from, T_to = _target([0.5, 0.0, 0.1]), _target([0.6, 0.0, 0.1], R=start_rotation() @ R_end)
    T, limited = limit_step(T_from, T_to, max_distance=0.025, max_angle=1.0)
    assert limited
    assert np.linalg.norm(T[:3, 3] - T_from[:3, 3]) == pytest.approx(0.025, abs=1e-9)
    # Rotation advances by the same quarter of the way: 0.15 of 0.6 rad.
    angle = np.linalg.norm(geometry.mat_to_axis_angle(T_from[:3, :3].T @ T[:3, :3]))
    assert angle == pytest.approx(0.15, abs=1e-6)
    T, limited = limit_step(T_from, T_to, max_distance=0.2, max_angle=0.06)
    assert limited and np.linalg.norm(T[:3, 3] - T_from[:3, 3]) == pytest.approx(0.01, abs=1e-9)
    same, limited = limit_step(T_from, T_to, max_distance=0.2, max_angle=1.0)
    assert not limited and same is T_to


def test_a_far_target_is_approached_at_the_speed_limit(grid_env):
    obs, _ = grid_env.reset(seed=0)
    start = obs["agent_pos"][:3].copy()
    action = np.r_[geometry.mat_to_pose9(_target(start + [0.0, -0.2, 0.0])), 0.05]
    _, _, _, _, info = grid_env.step(action)
    assert info["speed_limited"]  # 200 mm in one 50 ms step asks for 4 m/s
    for _ in range(3):
        obs, _, _, _, info = grid_env.step(action)
    moved_mm = 1000 * np.linalg.norm(obs["agent_pos"][:3] - start)
    assert 60 < moved_mm < 105, moved_mm  # 4 steps at <= 25 mm each (0.5 m/s at 20 Hz), arm lags a bit


def test_speed_limits_must_be_positive():
    with pytest.raises(ValueError, match="max_tcp_speed"):
        LegoPickEnv(max_tcp_speed=0.0)
