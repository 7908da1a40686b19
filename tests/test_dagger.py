"""``bboxpick-dagger``: the intervention rule on the real simulator, the expert's takeover, the recorded
corrections (only them, from the takeover on) through the CLI, and the options' errors."""

import json
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from helpers_cli import cli_env
from test_suite import _random_checkpoint

from lerobot_bboxpick import geometry
from lerobot_bboxpick.data.collect import ShardTask, record_shard
from lerobot_bboxpick.data.dagger import DaggerConfig, ExpertTakeover, InterventionRule, grasp_error
from lerobot_bboxpick.data.features import EPISODE_OUTCOME
from lerobot_bboxpick.data.replay import episode_arrays, load_dataset
from lerobot_bboxpick.eval.rollout import rollout
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.expert import ScriptedExpert
from lerobot_bboxpick.sim.outcome import OUTCOMES

SEED = 4000


class OffsetExpert:
    """A stand-in policy: the scripted expert's plan turned by ``yaw_deg`` about the vertical and shifted by
    ``xy`` (m), and closing ``close_early`` steps early; a policy that goes wrong in a known way."""

    def __init__(self, env: LegoPickEnv, yaw_deg: float = 0.0, xy: tuple = (0.0, 0.0)) -> None:
        self.env, self.yaw, self.xy = env, np.radians(yaw_deg), np.array([*xy, 0.0])
        self.calls = 0

    def reset(self) -> None:
        self.expert = ScriptedExpert(np.random.default_rng(self.env.episode_seed))
        self.expert.reset(self.env)

    def act(self, observation: dict, task: str) -> np.ndarray:
        self.calls += 1
        action = self.expert.act().astype(np.float64)
        T = geometry.pose9_to_mat(action[:9])
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        T[:3, :3] = turn @ T[:3, :3]
        T[:3, 3] += self.xy
        return np.concatenate([geometry.mat_to_pose9(T), action[9:]])


@pytest.fixture
def env():
    env = LegoPickEnv(setting="random_id", episode_length=300)
    yield env
    env.close()


def _run(env, policy, correction="in_place"):
    actor = ExpertTakeover(policy, env, InterventionRule(), correction)
    errors = []
    result = rollout(actor, "random_id", SEED, env=env, on_step=lambda *a: errors.append(grasp_error(env)))
    return actor, result, np.array(errors)


def test_an_aligned_policy_is_never_interrupted_and_picks(env):
    actor, result, errors = _run(env, OffsetExpert(env))
    assert actor.takeover_step is None and result["outcome"] == "pick"
    low = errors[errors[:, 0] < 0.04]
    assert len(low) > 10 and low[:, 1].max() < 0.002 and np.degrees(np.abs(low[:, 2])).max() < 1.0


@pytest.mark.parametrize(
    ("offset", "reason"),
    [({"yaw_deg": 30.0}, "off_yaw"), ({"xy": (0.0, 0.025)}, "off_xy")],
)
def test_a_policy_off_the_grasp_is_taken_over_low_and_the_expert_picks(env, offset, reason):
    policy = OffsetExpert(env, **offset)
    actor, result, errors = _run(env, policy)
    assert actor.reason == reason and result["outcome"] == "pick"
    # The takeover comes when the gripper first gets below the check height, not before.
    heights = errors[:, 0]
    first_low = int(np.argmax(heights < 0.04))
    assert first_low - 1 <= actor.takeover_step <= first_low + 1
    assert policy.calls == actor.takeover_step + 1  # the policy is not asked again after the takeover
    # The expert grasps aligned: within 2 mm and 1 degree at the grasp.
    at_grasp = errors[heights < 0.012]
    assert np.abs(at_grasp[:, 1]).min() < 0.002 and np.degrees(np.abs(at_grasp[:, 2])).min() < 1.0


@pytest.mark.parametrize(
    ("correction", "highest_m"), [("in_place", (0.0, 0.045)), ("replan", (0.085, 0.095))]
)
def test_the_correction_turns_in_place_or_goes_back_above(env, correction, highest_m):
    actor, result, errors = _run(env, OffsetExpert(env, yaw_deg=30.0), correction)
    assert actor.reason == "off_yaw" and result["outcome"] == "pick"
    # Until the grasp closes, the in-place correction stays at the takeover height (< 4 cm above the brick),
    # the replanned one first climbs back to the pre-grasp height (9 cm).
    after = errors[actor.takeover_step :, 0]
    before_grasp = after[: int(np.argmax(after < 0.012))]
    assert highest_m[0] <= before_grasp.max() <= highest_m[1]


def test_an_unknown_correction_names_the_allowed_values():
    with pytest.raises(ValueError, match="correction='nudge' is not one of in_place, replan"):
        ExpertTakeover(None, None, InterventionRule(), "nudge")


def test_closing_high_and_patience_fire(env):
    env.reset(seed=SEED)
    action = np.concatenate([geometry.mat_to_pose9(env.tcp_pose()), [0.0]])  # close where it is, high up
    rule = InterventionRule(patience_steps=50)
    assert grasp_error(env)[0] > 0.1
    assert rule.reason(env, action, step=0) == "closing_high"
    action[9] = 0.075
    assert rule.reason(env, action, step=49) is None
    assert rule.reason(env, action, step=50) == "patience"


@pytest.mark.parametrize(
    ("field", "value"),
    [("xy_tolerance_m", 0.0), ("yaw_tolerance_deg", -1.0), ("patience_steps", 0), ("check_height_m", 0.0)],
)
def test_bad_rule_values_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"{field}={value!r} must be > 0"):
        InterventionRule(**{field: value})


def test_an_episode_without_frames_is_not_kept(tmp_path):
    class NoCorrection:
        run_key = None

        def make_env(self, setting):
            return SimpleNamespace(close=lambda: None)

        def __call__(self, env, seed):
            return [], "pick", {"takeover_step": None, "reason": None}

    task = ShardTask(
        tmp_path / "shard_00000000", (1, 2), ("grid_id",) * 2, "test/x", False, None, NoCorrection()
    )
    records = record_shard(task)
    assert [(r["kept"], r["frames"], r["takeover_step"]) for r in records] == [(False, 0, None)] * 2
    assert not (tmp_path / "shard_00000000" / "meta").exists()  # no dataset was written


@pytest.mark.slow
def test_cli_records_the_corrections_only_and_merges_them_after_the_demos(tmp_path):
    from helpers_data import make_expert_dataset

    checkpoint = _random_checkpoint(tmp_path / "ckpt" / "pretrained_model")
    make_expert_dataset(tmp_path / "demos", seeds=[0], repo_id="test/demos")
    # A random policy never picks; with the alignment checks opened wide (it closes high up at once
    # otherwise) the expert takes over at step 6 of every episode, by patience.
    patience = 6
    cmd = [
        sys.executable, "-m", "lerobot_bboxpick.data.dagger", f"--policy_path={checkpoint}",
        "--repo_id=test/dagger", f"--root={tmp_path / 'ds'}", "--settings=grid_id,pile_id", "--episodes=1",
        f"--rule.patience_steps={patience}", "--rule.check_height_m=1", "--rule.xy_tolerance_m=1",
        "--rule.yaw_tolerance_deg=90", f"--merge_with={tmp_path / 'demos'}",
    ]  # fmt: skip
    result = subprocess.run(cmd, capture_output=True, text=True, env=cli_env(), timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads((tmp_path / "ds.collect" / "dagger_summary.json").read_text())
    records = json.loads(next((tmp_path / "ds.collect").glob("shard_*/seeds.json")).read_text())
    picked = [r for r in records if r["outcome"] == "pick"]
    assert len(picked) == 2 and all(
        r["reason"] == "patience" and r["takeover_step"] == patience for r in records
    )
    assert summary["dagger"]["takeovers"]["patience"] == len(records)
    assert summary["dagger"]["corrections_kept"] == 2 and summary["episodes"] == 3
    ds = load_dataset("test/dagger", tmp_path / "ds")
    outcomes = np.asarray(ds.hf_dataset[EPISODE_OUTCOME]).ravel()
    for episode, record in zip((1, 2), picked, strict=True):
        arr = episode_arrays(ds, episode)
        assert arr["seed"] == record["seed"] and arr["to"] - arr["from"] == record["frames"]
        assert {OUTCOMES[o] for o in outcomes[arr["from"] : arr["to"]]} == {"pick"}
        # Only the correction: every step from the takeover to the pick, none of the policy's before it.
        assert record["frames"] == record["steps"] - patience
        assert arr["actions"][:, 9].min() < 0.01  # the expert closed the gripper


def test_evaluation_seeds_are_refused(tmp_path):
    checkpoint = _random_checkpoint(tmp_path / "ckpt" / "pretrained_model")
    with pytest.raises(ValueError, match=r"not all train \(0-4999\) seeds"):
        DaggerConfig(policy_path=checkpoint, root=tmp_path / "x", seed_start=5000)
