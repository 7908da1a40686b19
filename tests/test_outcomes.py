"""Every outcome class (paper section 5.4) comes out of a scripted situation that should produce it."""

import numpy as np

from lerobot_bboxpick.expert import GRASP_HEIGHT, ScriptedExpert, Waypoint, grasp_rotation


def _run(env, actions) -> dict:
    info = {}
    for a in actions:
        _, _, _, _, info = env.step(a)
    return info


def _pose(xyz, R):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, xyz
    return T


def test_expert_pick_is_pick(grid_env):
    grid_env.reset(seed=3)
    expert = ScriptedExpert(np.random.default_rng(3))
    expert.reset(grid_env)
    speed_limited = 0
    while not expert.done:
        _, reward, _, _, info = grid_env.step(expert.act())
        speed_limited += info["speed_limited"]
    assert info["outcome"] == "pick" and info["is_success"] is True and reward == 1.0
    assert speed_limited == 0  # the demos move within the env's TCP speed limits
    # The brick really is up: >= 5 cm above the table, between the fingers.
    assert grid_env.brick_pose(grid_env.target)[2, 3] > 0.05


def test_picking_another_brick_is_wrong(grid_env):
    grid_env.reset(seed=4)
    other = (grid_env.target + 5) % 12
    expert = ScriptedExpert(np.random.default_rng(4))
    expert.reset(grid_env, brick=other)
    while not expert.done:
        _, reward, _, _, info = grid_env.step(expert.act())
    assert info["outcome"] == "wrong" and info["is_success"] is False and reward == 0.0
    assert grid_env.brick_pose(other)[2, 3] > 0.05 and grid_env.brick_pose(grid_env.target)[2, 3] < 0.01


def test_pressing_on_the_target_without_grasping_is_contact(grid_env):
    grid_env.reset(seed=5)
    B = grid_env.brick_pose(grid_env.target)
    R = grasp_rotation(float(np.arctan2(B[1, 0], B[0, 0])))
    top = B[:3, 3] + [0, 0, 0.03]  # closed fingertips 1 cm into the brick's top: they press on it
    plan = ScriptedExpert.through(
        grid_env.tcp_pose(),
        grid_env.gripper_width(),
        [
            Waypoint(_pose(top + [0, 0, 0.08], R), 0.0, 2.0),
            Waypoint(_pose(top - [0, 0, 0.012], R), 0.0, 1.0),
            Waypoint(_pose(top + [0, 0, 0.1], R), 0.0, 1.0),
        ],
        grid_env.options.fps,
    )
    info = _run(grid_env, plan)
    assert info["outcome"] == "contact" and info["is_success"] is False


def test_closing_on_air_is_empty(grid_env):
    grid_env.reset(seed=6)
    B = grid_env.brick_pose(grid_env.target)
    R = grasp_rotation(float(np.arctan2(B[1, 0], B[0, 0])))
    beside = B[:3, 3] + [0.0, 0.0, 0.12]  # 12 cm above the target: close, lift, nothing in hand
    plan = ScriptedExpert.through(
        grid_env.tcp_pose(),
        grid_env.gripper_width(),
        [
            Waypoint(_pose(beside, R), 0.075, 2.0),
            Waypoint(_pose(beside, R), 0.0, 0.6),
            Waypoint(_pose(beside + [0, 0, 0.05], R), 0.0, 0.6),
        ],
        grid_env.options.fps,
    )
    info = _run(grid_env, plan)
    assert info["outcome"] == "empty"
    heights = grid_env.data.xpos[grid_env.ids.brick_bodies, 2]
    assert np.abs(heights).max() < 0.005  # nothing moved


def test_episode_terminates_once_a_brick_is_lifted():
    from lerobot_bboxpick.sim.env import LegoPickEnv

    env = LegoPickEnv(setting="grid_id", terminate_on_lift=True)
    env.reset(seed=3)
    expert = ScriptedExpert(np.random.default_rng(3))
    expert.reset(env)
    steps = 0
    while True:
        _, _, terminated, truncated, info = env.step(expert.act())
        steps += 1
        if terminated or truncated:
            break
    env.close()
    assert terminated and info["outcome"] == "pick"
    assert steps < len(expert._actions)  # it ended at the lift, before the carry back


def test_grasp_height_keeps_fingertips_above_the_table():
    assert 0.0 < GRASP_HEIGHT < 0.0192


def test_a_thrown_brick_ends_the_episode_as_sim_unstable(grid_env):
    """A brick far faster than the gripper can move it means the contact solver blew up: the env ends
    the episode and flags it, instead of scoring whatever the explosion did. A normal pick stays below
    the threshold with a wide margin."""
    from lerobot_bboxpick.sim.outcome import UNSTABLE_BRICK_SPEED

    obs, info = grid_env.reset(seed=3)
    expert = ScriptedExpert(np.random.default_rng(3))
    expert.reset(grid_env)
    while not expert.done:
        _, _, terminated, _, info = grid_env.step(expert.act())
    assert info["outcome"] == "pick" and not info["sim_unstable"] and not terminated
    assert grid_env._tracker.peak_brick_speed < UNSTABLE_BRICK_SPEED / 2

    obs, info = grid_env.reset(seed=3)
    hold = obs["agent_pos"].copy()
    other = (grid_env.target + 1) % 12
    dof = grid_env.ids.brick_dof[other]
    grid_env.data.qvel[dof : dof + 3] = [0.0, 12.0, 3.0]  # as an exploding contact would throw it
    _, _, terminated, _, info = grid_env.step(hold)
    assert info["sim_unstable"] and terminated
    assert info["outcome"] == "empty"  # nothing tracked after the blow-up
