"""``lerobot_bboxpick trace``: where the gripper closes relative to its target, in mm and degrees, on the
real simulator: the expert closes centred, 8 mm up and turned onto the brick; an arm that descends without
turning and closes 40 mm up is reported so."""

import numpy as np
import pytest

from lerobot_bboxpick.apps.cli import main
from lerobot_bboxpick.eval.rollout import ExpertRunner
from lerobot_bboxpick.eval.trace import trace_episode, trace_table, yaw_error_deg
from lerobot_bboxpick.sim.env import LegoPickEnv

TURNED_SEED = 5001  # random_id validation scene whose target is turned 44 degrees from the start gripper


class DescendWithoutTurning:
    """A stand-in policy: straight over the target, down to ``close_height`` above its bottom face at
    1 cm per step, never turning, then shut."""

    def __init__(self, env: LegoPickEnv, close_height: float) -> None:
        self.env, self.close_height = env, close_height

    def reset(self) -> None:
        """Nothing to plan."""

    def act(self, observation: dict, task: str) -> np.ndarray:
        """The next absolute pose10: 1 cm toward the goal, the start rotation, open until there."""
        action = np.array(observation["agent_pos"], dtype=np.float64)
        goal = self.env.brick_pose(self.env.target)[:3, 3] + [0.0, 0.0, self.close_height]
        step = goal - action[:3]
        arrived = np.linalg.norm(step) < 0.002
        action[:3] += step * min(1.0, 0.01 / max(np.linalg.norm(step), 1e-9))
        action[9] = 0.0 if arrived else 0.075
        return action


@pytest.fixture(scope="module")
def env():
    env = LegoPickEnv(setting="random_id", episode_length=300)
    yield env
    env.close()


def test_yaw_error_wraps_to_a_quarter_turn():
    def rz(deg: float) -> np.ndarray:
        a = np.radians(deg)
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    assert yaw_error_deg(rz(10), rz(0)) == pytest.approx(10)
    assert yaw_error_deg(rz(100), rz(0)) == pytest.approx(10)  # a quarter turn lines up the other face
    assert yaw_error_deg(rz(-40), rz(30)) == pytest.approx(20)  # -70 -> +20
    assert yaw_error_deg(rz(45), rz(0)) == pytest.approx(-45)


def test_the_expert_closes_centred_low_and_turned_onto_the_brick(env):
    trace = trace_episode(ExpertRunner(env), env, "random_id", TURNED_SEED)
    k = trace.close_step()
    assert trace.outcome == "pick" and k is not None
    assert abs(trace.yaw_errors[0]) > 30  # the brick starts turned against the gripper...
    assert abs(trace.yaw_errors[k]) < 2  # ...and the expert has turned onto it by the close
    assert 1000 * np.linalg.norm(trace.offsets[k, :2]) < 3
    assert 1000 * trace.offsets[k, 2] == pytest.approx(8, abs=3)  # GRASP_HEIGHT


def test_an_arm_that_never_turns_and_closes_high_is_traced_so(env):
    trace = trace_episode(DescendWithoutTurning(env, 0.04), env, "random_id", TURNED_SEED)
    k = trace.close_step()
    assert trace.outcome == "empty" and k is not None
    assert 1000 * trace.offsets[k, 2] == pytest.approx(40, abs=5)
    assert trace.yaw_errors[k] == pytest.approx(trace.yaw_errors[0], abs=2)
    row = trace_table([trace]).splitlines()[2].split(" | ")
    assert row[2] == "empty" and int(row[6]) == pytest.approx(40, abs=5)


def test_the_trace_command_names_a_bad_seed_list(capsys):
    with pytest.raises(SystemExit):
        main(["trace", "--policy", "expert", "--seeds", "5001,x"])
    assert "'5001,x' is not comma-separated integers" in capsys.readouterr().err
