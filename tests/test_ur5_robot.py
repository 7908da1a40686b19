"""The ``ur5`` robot on its MuJoCo backend, in process: features, the expert teleoperator, every safety
refusal, the speed limit, the target given as a box, the tracker and its lost-track stop, the scene clock."""

from __future__ import annotations

import numpy as np
import pytest
from lerobot.robots.utils import make_robot_from_config
from lerobot.teleoperators.utils import make_teleoperator_from_config

import lerobot_bboxpick  # noqa: F401  (registers ur5 and bboxpick_expert)
from lerobot_bboxpick.data.tracking import bbox_iou
from lerobot_bboxpick.robots.ur5 import UR5, UR5Config
from lerobot_bboxpick.robots.ur5.safety import UnsafeActionError
from lerobot_bboxpick.robots.ur5.ur5 import BBOX_KEYS, POSE_KEYS
from lerobot_bboxpick.teleoperators.bboxpick_expert import BboxpickExpert, BboxpickExpertConfig


class FakeClock:
    """A settable clock for the scene timer."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _robot(**kwargs) -> UR5:
    robot = make_robot_from_config(UR5Config(**{"seed": 0, "scene_time_s": 1e6, **kwargs}))
    robot.connect()
    return robot


def _pose10(obs: dict) -> np.ndarray:
    return np.array([obs[k] for k in POSE_KEYS])


def _box(obs: dict) -> np.ndarray:
    return np.array([obs[k] for k in BBOX_KEYS])


def _action(pose10: np.ndarray) -> dict:
    return {k: float(v) for k, v in zip(POSE_KEYS, pose10, strict=True)}


@pytest.fixture
def robot():
    r = _robot()
    yield r
    r.disconnect()


def test_lerobot_finds_the_robot_and_the_teleoperator_by_name():
    robot = make_robot_from_config(UR5Config())
    assert isinstance(robot, UR5) and not robot.is_connected
    assert isinstance(make_teleoperator_from_config(BboxpickExpertConfig()), BboxpickExpert)
    # Cameras and .pos scalars only: what lerobot-rollout passes to a policy.
    assert robot.observation_features["wrist"] == (224, 224, 3)
    scalars = [k for k, v in robot.observation_features.items() if v is float]
    assert scalars == list(POSE_KEYS + BBOX_KEYS) and all(k.endswith(".pos") for k in scalars)
    assert list(robot.action_features) == list(POSE_KEYS)


def test_observation_is_the_env_state_and_the_oracle_box(robot):
    obs = robot.get_observation()
    env = robot.backend.env
    np.testing.assert_allclose(_pose10(obs), env.agent_pos(), atol=1e-6)
    np.testing.assert_allclose(_box(obs), env.brick_box(env.target).bbox, atol=1e-6)
    assert obs["wrist"].shape == (224, 224, 3) and obs["wrist"].dtype == np.uint8
    assert _box(obs)[2] > _box(obs)[0] > 0


def test_expert_teleoperator_picks_the_target_through_the_robot(robot):
    expert = make_teleoperator_from_config(BboxpickExpertConfig())
    expert.connect()
    for _ in range(200):
        robot.get_observation()
        sent = robot.send_action(expert.get_action())
        if robot.backend.info["outcome"] == "pick":
            break
    assert robot.backend.info["outcome"] == "pick"
    assert expert.plans == 1 and set(sent) == set(POSE_KEYS)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda a: a.update({"tcp_z.pos": float("nan")}), r"\['z'\] are not finite"),
        (lambda a: a.update({"tcp_x.pos": 1.5}), r"x=1.5000 m is outside the workspace box"),
        (lambda a: a.update({"tcp_z.pos": -0.05}), r"z=-0.0500 m is outside the workspace box"),
        (lambda a: a.pop("gripper_width.pos"), r"missing \['gripper_width.pos'\]"),
        (lambda a: a.update({"elbow.pos": 0.0}), r"unknown \['elbow.pos'\]"),
        (lambda a: a.update({"gripper_width.pos": 0.2}), r"gripper_width=0.2000 m is outside"),
        (lambda a: a.update(dict.fromkeys(POSE_KEYS[3:6], 0.0)), r"r00..r02 \(a rot6d row\)"),
    ],
)
def test_unsafe_actions_are_refused_naming_the_field_and_nothing_moves(robot, change, message):
    before = _pose10(robot.get_observation())
    action = _action(before)
    change(action)
    with pytest.raises(UnsafeActionError, match=message):
        robot.send_action(action)
    np.testing.assert_allclose(_pose10(robot.get_observation()), before, atol=1e-9)


def test_a_far_target_is_approached_at_the_speed_limit(robot):
    start = _pose10(robot.get_observation())
    target = start.copy()
    target[0] += 0.2  # 20 cm in one 50 ms step would be 4 m/s
    sent = robot.send_action(_action(target))
    step = np.linalg.norm(np.array([sent[k] for k in POSE_KEYS[:3]]) - start[:3])
    assert step == pytest.approx(robot.config.safety.max_tcp_speed / robot.config.fps, rel=1e-6)
    # The acceleration bound: from rest the next step may grow by at most a_max * dt^2.
    sent2 = robot.send_action(_action(target))
    step2 = np.linalg.norm(np.array([sent2[k] - sent[k] for k in POSE_KEYS[:3]]))
    dt = 1 / robot.config.fps
    assert step2 <= step + robot.config.safety.max_tcp_acceleration * dt * dt + 1e-9


def test_a_box_around_another_brick_makes_it_the_target():
    probe = _robot()
    env = probe.backend.env
    other = next(i for i in range(12) if i != env.target and env.brick_box(i).in_view)
    box = env.brick_box(other).bbox
    probe.disconnect()
    robot = _robot(bbox=",".join(f"{v:.4f}" for v in box))
    try:
        assert robot.backend.env.target == other
        first = _box(robot.get_observation())
        np.testing.assert_allclose(first, np.round(box, 4), atol=1e-6)  # the person's box, as given
        # Then the oracle follows the designated brick.
        second = _box(robot.get_observation())
        assert bbox_iou(second, robot.backend.env.brick_box(other).bbox) > 0.99
    finally:
        robot.disconnect()


def test_a_box_on_the_empty_table_is_refused():
    with pytest.raises(ValueError, match="covers no brick"):
        _robot(bbox="0.02,0.02,0.06,0.06")


def test_tracked_box_follows_the_target_during_an_expert_pick():
    robot = _robot(bbox_source="tracked")
    expert = make_teleoperator_from_config(BboxpickExpertConfig())
    expert.connect()
    ious = []
    try:
        for _ in range(60):  # the approach: the target stays in view
            obs = robot.get_observation()
            env = robot.backend.env
            ious.append(float(bbox_iou(_box(obs), env.brick_box(env.target).bbox)))
            robot.send_action(expert.get_action())
    finally:
        robot.disconnect()
    assert np.mean(ious) > 0.6, ious


def test_a_lost_target_stops_the_arm_and_actions_are_ignored():
    robot = _robot(bbox_source="tracked", max_lost_frames=3)
    try:
        obs = robot.get_observation()
        start = _pose10(obs)
        # Someone takes the target brick off the table: the tracker loses it.
        env = robot.backend.env
        adr = env.ids.brick_qpos[env.target]
        env.data.qpos[adr : adr + 3] = [3.0, 3.0, 0.02]
        target = start.copy()
        target[2] -= 0.01
        for _ in range(10):
            robot.send_action(_action(target))
            obs = robot.get_observation()
            if robot._halted:
                break
        assert robot._halted and robot.prompt.lost_frames == 4  # stopped on the 4th lost frame
        assert np.all(_box(obs) == 0)
        held = _pose10(robot.get_observation())
        far = held.copy()
        far[:2] += 0.05
        robot.send_action(_action(far))
        np.testing.assert_allclose(_pose10(robot.get_observation()), held, atol=2e-3)
    finally:
        robot.disconnect()


def test_scenes_change_on_the_clock_and_the_expert_replans():
    clock = FakeClock()
    robot = make_robot_from_config(UR5Config(seed=0, scene_time_s=5.0))
    robot.connect()
    robot.backend._clock = clock  # the scene timer reads this clock
    expert = make_teleoperator_from_config(BboxpickExpertConfig(takeover_gap_s=1e9))
    expert._clock = clock
    expert.connect()
    try:
        robot.get_observation()  # starts scene 0's clock
        robot.send_action(expert.get_action())
        clock.t = 4.9
        robot.get_observation()
        assert robot.backend.scene_index == 0
        clock.t = 5.0
        robot.get_observation()
        assert robot.backend.scene_index == 1 and robot.backend.seed == 1
        robot.send_action(expert.get_action())
        assert expert.plans == 2
        assert robot.backend.outcomes[0]["seed"] == 0
    finally:
        robot.disconnect()


def test_the_expert_takes_over_from_where_the_arm_is():
    clock = FakeClock()
    robot = _robot()
    expert = BboxpickExpert(BboxpickExpertConfig(takeover_gap_s=0.2), clock=clock)
    expert.connect()
    try:
        robot.get_observation()
        robot.send_action(expert.get_action())
        clock.t = 1.0  # the policy drove meanwhile: the next call re-plans from the current pose
        moved = _pose10(robot.get_observation())
        moved[1] += 0.02
        for _ in range(5):
            robot.send_action(_action(moved))
        first = expert.get_action()
        assert expert.plans == 2
        now = _pose10(robot.get_observation())
        # The new plan starts at the arm's pose: its first step is a small one from there.
        assert np.linalg.norm(np.array([first[k] for k in POSE_KEYS[:3]]) - now[:3]) < 0.01
    finally:
        robot.disconnect()


def test_the_expert_needs_a_simulated_robot():
    expert = make_teleoperator_from_config(BboxpickExpertConfig(robot_id="nobody"))
    expert.connect()
    with pytest.raises(LookupError, match="no connected ur5 robot with backend=mujoco and id 'nobody'"):
        expert.get_action()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"backend": "ros"}, "robot.backend='ros' is not one of: mujoco, rtde"),
        ({"bbox": "0.5,0.5,0.4,0.6"}, "robot.bbox='0.5,0.5,0.4,0.6' must be 'x0,y0,x1,y1'"),
        ({"bbox": "a,b"}, "robot.bbox='a,b' must be"),
        ({"bbox_source": "gps"}, "robot.bbox_source='gps' is not one of: oracle, tracked"),
        ({"setting": "kitchen"}, "setting='kitchen' is not a lego_pick setting"),
        ({"backend": "rtde"}, "robot.backend=rtde needs the target"),
        ({"scene_time_s": 0}, r"robot.scene_time_s=0 must be > 0"),
    ],
)
def test_bad_config_names_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        UR5Config(**kwargs)


def test_keyboard_deltas_become_the_absolute_pose_action(robot):
    """LeRobot's end-effector teleoperators' deltas, through bboxpick-record-ee's processor, move the arm
    by step_m per step along the table axes, and the dataset's action keys stay the ur5's pose10."""
    from lerobot.datasets import aggregate_pipeline_dataset_features, create_initial_features

    from lerobot_bboxpick.apps.record_ee import ee_teleop_action_processor

    pipeline = ee_teleop_action_processor(step_m=0.01)
    features = aggregate_pipeline_dataset_features(
        pipeline=pipeline, initial_features=create_initial_features(action=robot.action_features)
    )
    assert features["action"]["names"] == list(POSE_KEYS)
    obs = robot.get_observation()
    start = _pose10(obs)
    action = pipeline(({"delta_x": 1.0, "delta_y": 0.0, "delta_z": -1.0, "gripper": 0.0}, obs))
    np.testing.assert_allclose(
        np.array([action[k] for k in POSE_KEYS]) - start, [0.01, 0, -0.01, *[0] * 6, -0.005]
    )
    for _ in range(10):
        robot.send_action(pipeline(({"delta_x": 1.0, "delta_y": 0.0, "delta_z": 0.0, "gripper": 1.0}, obs)))
        obs = robot.get_observation()
    moved = _pose10(obs) - start
    assert moved[0] == pytest.approx(0.10, abs=0.01) and abs(moved[1]) < 0.01  # the arm lags its targets
    with pytest.raises(
        ValueError, match=r"takes \['delta_x', 'delta_y', 'delta_z'\] and 'gripper', got \['x'\]"
    ):
        pipeline(({"x": 1.0}, obs))
