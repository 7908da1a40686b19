"""``turn="late"``: the scripted expert keeps its start rotation until it is above the brick, then turns
onto the brick's faces and picks as before; ``bboxpick-collect --expert_turn=late`` records such demos
and refuses to mix them with early-turn shards."""

import numpy as np
import pytest

from lerobot_bboxpick.data.collect import CollectConfig, ExpertRecorder, expert_recorder
from lerobot_bboxpick.eval.trace import yaw_error_deg
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.expert import PREGRASP_HEIGHT, ScriptedExpert

TURNED_SEED = 5001  # random_id scene whose target is turned 44 degrees from the start gripper


@pytest.fixture(scope="module")
def env():
    env = LegoPickEnv(setting="random_id", episode_length=400, terminate_on_lift=False)
    yield env
    env.close()


def _run(env: LegoPickEnv, turn: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Per step: TCP height above the target's bottom face (m), yaw error (deg), gripper command."""
    env.reset(seed=TURNED_SEED)
    expert = ScriptedExpert(np.random.default_rng(TURNED_SEED), turn=turn)
    expert.reset(env)
    heights, yaws, commands, info = [], [], [], {}
    while not expert.done:
        action = expert.act()
        _, _, _, _, info = env.step(action)
        tcp, brick = env.tcp_pose(), env.brick_pose(env.target)
        heights.append(tcp[2, 3] - brick[2, 3])
        yaws.append(yaw_error_deg(tcp[:3, :3], brick[:3, :3]))
        commands.append(action[-1])
    return np.array(heights), np.array(yaws), np.array(commands), info["outcome"]


def test_the_late_expert_turns_above_the_brick_and_still_picks(env):
    early_h, early_yaw, _, early_outcome = _run(env, "early")
    late_h, late_yaw, late_cmd, late_outcome = _run(env, "late")
    assert early_outcome == late_outcome == "pick"
    assert abs(late_yaw[0]) > 40
    # The early expert has turned more than half-way by the time it is 5 cm above the pre-grasp height;
    # the late one is still at its start rotation (within 2 deg) until it is within 1 cm of that height.
    high_early = np.flatnonzero(early_h > PREGRASP_HEIGHT + 0.05)
    assert abs(early_yaw[high_early[-1]]) < abs(early_yaw[0]) / 2
    high_late = np.flatnonzero(late_h > PREGRASP_HEIGHT + 0.01)
    assert np.max(np.abs(late_yaw[high_late] - late_yaw[0])) < 2
    closing = int(np.flatnonzero(late_cmd < 0.0375)[0])
    assert abs(late_yaw[closing]) < 2 and late_h[closing] == pytest.approx(0.008, abs=0.003)


def test_expert_turn_is_checked_and_keys_resumed_collections():
    with pytest.raises(ValueError, match="turn='sideways': allowed values are early, late"):
        ScriptedExpert(turn="sideways")
    with pytest.raises(ValueError, match="expert_turn='soon': allowed values are early, late"):
        CollectConfig(root="/tmp/unused", expert_turn="soon")
    assert ExpertRecorder().run_key is None  # early-turn shards recorded before the option still resume
    assert expert_recorder(0.0, "late").run_key == {"expert_turn": "late"}
    assert expert_recorder(0.3, "early").run_key == {"recovery": 0.3}
    assert expert_recorder(0.3, "late").run_key == {"recovery": 0.3, "expert_turn": "late"}
