"""bboxpick-rollouts: a tiny random checkpoint's closed-loop episodes, failures kept and labelled, the
actions the policy executed, merged with an expert demo; training seeds only."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers_cli import cli_env
from test_suite import _random_checkpoint

from lerobot_bboxpick.data.collect import check_resumable
from lerobot_bboxpick.data.features import EPISODE_OUTCOME
from lerobot_bboxpick.data.replay import episode_arrays, load_dataset
from lerobot_bboxpick.data.rollouts import RolloutsConfig, episode_stats, record_rollouts
from lerobot_bboxpick.sim.layouts import SETTINGS
from lerobot_bboxpick.sim.outcome import OUTCOMES

REPO = "test/rollouts"
MAX_STEPS = 30
SETTINGS_USED = ("grid_id", "pile_id")  # seed 1000 -> grid_id, 1001 -> pile_id (seed % 2)


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    return _random_checkpoint(tmp_path_factory.mktemp("ckpt") / "pretrained_model")


@pytest.fixture(scope="module")
def recorded(checkpoint, tmp_path_factory) -> tuple[Path, dict]:
    from helpers_data import make_expert_dataset

    tmp = tmp_path_factory.mktemp("rollouts")
    make_expert_dataset(tmp / "expert", seeds=[0], repo_id="test/expert")
    cfg = RolloutsConfig(
        policy_path=checkpoint, repo_id=REPO, root=tmp / "ds", settings=",".join(SETTINGS_USED),
        episodes=1, max_steps=MAX_STEPS, merge_with=tmp / "expert", stats_png=tmp / "stats.png",
    )  # fmt: skip
    return tmp, record_rollouts(cfg)


@pytest.mark.slow
def test_every_episode_is_kept_with_its_outcome_and_merged_after_the_demo(recorded):
    tmp, summary = recorded
    records = json.loads(next((tmp / "ds.collect").glob("shard_*/seeds.json")).read_text())
    assert [r["seed"] for r in records] == [1000, 1001] and all(r["kept"] for r in records)
    assert summary["episodes"] == 3 and summary["attempted"] == 2
    ds = load_dataset(REPO, tmp / "ds")
    assert ds.num_episodes == 3
    outcomes = np.asarray(ds.hf_dataset[EPISODE_OUTCOME]).ravel()
    done = np.asarray(ds.hf_dataset["next.done"]).ravel()
    success = np.asarray(ds.hf_dataset["next.success"]).ravel()
    reward = np.asarray(ds.hf_dataset["next.reward"]).ravel()
    arrays = [episode_arrays(ds, e) for e in range(3)]
    # Episode 0: the expert demo (merged first), a pick.
    assert arrays[0]["seed"] == 0 and {OUTCOMES[o] for o in outcomes[: arrays[0]["to"]]} == {"pick"}
    for arr, record, setting in zip(arrays[1:], records, SETTINGS_USED, strict=True):
        rows = slice(arr["from"], arr["to"])
        assert arr["seed"] == record["seed"] and SETTINGS[arr["setting"]] == setting
        assert arr["to"] - arr["from"] == record["frames"] <= MAX_STEPS
        assert {OUTCOMES[o] for o in outcomes[rows]} == {record["outcome"]}  # constant, = the rollout's
        assert np.flatnonzero(done[rows]).tolist() == [record["frames"] - 1]  # terminal frame only
        # Sparse terminal reward as the env gives it: 1 on a pick step, 0 otherwise.
        np.testing.assert_array_equal(reward[rows], success[rows].astype(np.float32))
    rollout_outcomes = {r["outcome"] for r in records}
    assert "pick" not in rollout_outcomes  # a random policy does not pick in 30 steps: failures kept
    assert summary["outcomes"] == {o: sum(r["outcome"] == o for r in records) for o in summary["outcomes"]}
    stats = episode_stats(REPO, tmp / "ds")
    assert [(s["setting"], s["outcome"], s["length"]) for s in stats] == [
        ("grid_id", "pick", arrays[0]["to"]),
        *[(r["setting"], r["outcome"], r["frames"]) for r in records],
    ]
    assert (tmp / "stats.png").stat().st_size > 10_000


@pytest.mark.slow
def test_actions_are_what_the_policy_returned_and_replay_to_the_same_states(recorded, checkpoint):
    from lerobot_bboxpick.eval.rollout import PolicyRunner, rollout
    from lerobot_bboxpick.sim.env import LegoPickEnv

    tmp, _ = recorded
    arr = episode_arrays(load_dataset(REPO, tmp / "ds"), 1)  # seed 1000, grid_id
    # A direct rollout of the same checkpoint on the same seed returns the dataset's actions.
    runner = PolicyRunner.from_pretrained(checkpoint)
    returned = []
    act = runner.act
    runner.act = lambda obs, task: returned.append(act(obs, task)) or returned[-1]
    result = rollout(runner, "grid_id", 1000, policy_seed=1000, max_steps=MAX_STEPS)
    assert result["steps"] == len(arr["actions"])
    np.testing.assert_allclose(arr["actions"], np.array(returned), atol=1e-5)
    # Open-loop replay of the recorded actions: frame t holds the observation before step t.
    env = LegoPickEnv(setting="grid_id", episode_length=MAX_STEPS)
    obs, _ = env.reset(seed=1000)
    for t in range(10):
        np.testing.assert_allclose(arr["states"][t], obs["agent_pos"], atol=1e-5)
        np.testing.assert_allclose(arr["bboxes"][t], obs["bbox"], atol=1e-5)
        obs, *_ = env.step(arr["actions"][t])
    env.close()


@pytest.mark.parametrize("seed_start", [4999, 5000, 10000])
def test_evaluation_seeds_are_refused_naming_the_split(checkpoint, tmp_path, seed_start):
    with pytest.raises(ValueError, match=r"seed_start: seeds .* not all train \(0-4999\) seeds"):
        RolloutsConfig(
            policy_path=checkpoint, root=tmp_path / "x", settings="grid_id,pile_id", seed_start=seed_start
        )


def test_cli_refuses_evaluation_seeds(checkpoint, tmp_path):
    cmd = [sys.executable, "-m", "lerobot_bboxpick.data.rollouts", f"--policy_path={checkpoint}"]
    result = subprocess.run(
        [*cmd, f"--root={tmp_path / 'x'}", "--seed_start=6000"], capture_output=True, text=True, env=cli_env()
    )
    assert result.returncode != 0 and "not all train (0-4999) seeds" in result.stderr


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"policy_path": None}, "policy_path=None must be a checkpoint folder with config.json"),
        ({"merge_with": "nowhere"}, "merge_with=nowhere is not a LeRobotDataset folder"),
        ({"settings": "grid_id,piles"}, "valid settings: grid_id, grid_ood"),
        ({"max_steps": 0}, "max_steps=0 must be an integer >= 1"),
        ({"episodes": 0}, "episodes=0 must be an integer >= 1"),
    ],
)
def test_bad_options_name_the_field(checkpoint, tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        RolloutsConfig(**{"policy_path": checkpoint, "root": tmp_path / "x", **kwargs})


def test_resume_with_another_checkpoint_is_refused(checkpoint, tmp_path):
    cfg = RolloutsConfig(policy_path=checkpoint, root=tmp_path / "ds", resume=True).collect_config()
    shard = cfg.work_dir / "shard_00001000"
    shard.mkdir(parents=True)
    other = {"weights": "0123456789abcdef", "max_steps": 300}
    (shard / "seeds.json").write_text(json.dumps([{"seed": 1000, "kept": True, "run_key": other}]))
    with pytest.raises(ValueError, match="choose another --root"):
        check_resumable(cfg, {"weights": "fedcba9876543210", "max_steps": 300})
    check_resumable(cfg, other)  # the same run resumes
