"""End to end on a real (tiny) dataset: expert picks, a perturbed expert's miss and a wrong-brick pick,
recorded in LegoPickEnv and written with the project's schema; the critic trains with
``bboxpick-train-critic``'s function, reports its diagnostics, reloads, and ``verify`` writes a report."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from test_rl_modeling import SMALL_CRITIC, tiny_policy

import lerobot_bboxpick  # noqa: F401  (MUJOCO_GL before MuJoCo)
from lerobot_bboxpick.data.collect import record_episode
from lerobot_bboxpick.data.features import EPISODE_OUTCOME, create_dataset, make_frame, outcome_code
from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
from lerobot_bboxpick.rl.critic_dataset import (
    OUTCOME_GROUPS,
    CriticDataConfig,
    episode_group,
    load_frame_table,
)
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel
from lerobot_bboxpick.rl.train_critic import TrainCriticConfig, train_critic
from lerobot_bboxpick.rl.verify import VerifyConfig, verify_critic
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.expert import ScriptedExpert
from lerobot_bboxpick.sim.scene import N_BRICKS

REPO_ID = "test/critic"


def record_scripted(
    env: LegoPickEnv, seed: int, shift: tuple[float, float, float] = (0, 0, 0), brick: int | None = None
) -> tuple[list[dict], str]:
    """``record_episode`` with a deliberately wrong expert: its whole plan shifted by ``shift`` (m, table
    frame: a miss) or aimed at ``brick`` instead of the target (a wrong pick)."""
    obs, info = env.reset(seed=seed)
    expert = ScriptedExpert(np.random.default_rng(seed))
    expert.reset(env, brick=brick)
    frames = []
    while not expert.done:
        action = expert.act().copy()
        action[:3] += np.asarray(shift)
        next_obs, reward, terminated, truncated, next_info = env.step(action)
        frames.append(
            make_frame(
                obs["pixels"]["wrist"], obs["agent_pos"], obs["bbox"], action, info["task"],
                reward=reward, success=next_info["is_success"], seed=seed,
                setting=info["setting"], target=info["target"],
            )
        )  # fmt: skip
        obs, info = next_obs, next_info
        if terminated or truncated:
            break
    frames[-1]["next.done"][:] = True
    for f in frames:
        f[EPISODE_OUTCOME][:] = outcome_code(info["outcome"])
    return frames, info["outcome"]


def nearest_other_brick(env: LegoPickEnv) -> int:
    """The brick closest to the target (the expert aimed there lifts the wrong one)."""
    p = env.brick_pose(env.target)[:3, 3]
    d = [np.inf if k == env.target else np.linalg.norm(env.brick_pose(k)[:3, 3] - p) for k in range(N_BRICKS)]
    return int(np.argmin(d))


def build_outcome_dataset(root: Path) -> list[str]:
    """3 expert picks, 1 miss (the plan 5 cm too high: it closes on air), 1 wrong pick; returns the
    outcomes in episode order."""
    env = LegoPickEnv(setting="grid_id", terminate_on_lift=True)
    ds = create_dataset(REPO_ID, root)
    outcomes = []
    try:
        episodes = [record_episode(env, s) for s in (0, 1, 2)]
        episodes.append(record_scripted(env, 3, shift=(0.0, 0.0, 0.05)))
        env.reset(seed=4)
        episodes.append(record_scripted(env, 4, brick=nearest_other_brick(env)))
        for frames, outcome in episodes:
            for frame in frames:
                ds.add_frame(frame)
            ds.save_episode()
            outcomes.append(outcome)
    finally:
        ds.finalize()
        env.close()
    return outcomes


@pytest.fixture(scope="module")
def outcome_dataset(tmp_path_factory) -> tuple[Path, list[str]]:
    root = tmp_path_factory.mktemp("critic") / "dataset"
    return root, build_outcome_dataset(root)


@pytest.mark.slow
def test_train_critic_then_verify_on_a_recorded_dataset(outcome_dataset, tmp_path):
    root, outcomes = outcome_dataset
    assert outcomes == ["pick", "pick", "pick", "empty", "wrong"]
    policy_dir = tmp_path / "policy"
    tiny_policy().save_pretrained(policy_dir)
    data = CriticDataConfig(repo_id=REPO_ID, root=root)
    cfg = TrainCriticConfig(
        dataset=data, policy_path=policy_dir, critic=IqlCriticConfig(**SMALL_CRITIC),
        output_dir=tmp_path / "critic", epochs=12, batch_size=64, lr=3e-3, warmup_steps=10,
        diagnostics_every_epochs=4, progress=False,
    )  # fmt: skip
    result = train_critic(cfg)

    # Diagnostics every 4 epochs and at the end, on both splits, over every transition of the dataset.
    history = [
        json.loads(line) for line in (tmp_path / "critic" / "diagnostics.jsonl").read_text().splitlines()
    ]
    assert [h["epoch"] for h in history if "diagnostics" in h] == [4, 8, 12]
    diag = result["diagnostics"]
    counts = {g: sum(d["grouped"]["count"][g]["all"] for d in diag.values()) for g in OUTCOME_GROUPS}
    ep_len = {g: 0 for g in OUTCOME_GROUPS}
    table = load_frame_table(LeRobotDataset(REPO_ID, root=root))
    for e, (a, b) in enumerate(table.episode_bounds):
        g = episode_group(table, e)
        hits = np.flatnonzero(table.success[a:b])
        ep_len[g] += int(hits[0]) + 1 if g == "success" else b - a  # a success ends at its pick
    assert counts == ep_len
    assert ep_len["miss"] > 0 and ep_len["wrong"] > 0
    # The critic fitted its sparse rewards: on the training episodes success sits above failure at the end.
    train = diag["train"]
    assert len(train["checks"]) == 12
    # The critic fitted the sparse terminal rewards (+1 pick, -1 wrong) of the final chunks it saw.
    q_end = {g: train["grouped"]["q"][g]["terminal"] for g in OUTCOME_GROUPS}
    assert q_end["success"] > 0.3 and q_end["wrong"] < -0.1
    assert q_end["success"] - q_end["wrong"] > 0.6

    # The checkpoint is where LeRobot puts one, reloads, and reproduces the training diagnostics.
    ckpt = Path(result["checkpoint"])
    assert ckpt.resolve() == (tmp_path / "critic" / "checkpoints" / "last" / "pretrained_model").resolve()
    assert ckpt.parent.name == f"{result['steps']:06d}"
    assert json.loads((ckpt / "train_config.json").read_text())["lr"] == 3e-3
    IqlCriticModel.from_pretrained(ckpt)
    report = verify_critic(
        VerifyConfig(
            critic_path=ckpt, dataset=data, out_dir=tmp_path / "verify", split="train", progress=False
        )
    )
    for g in OUTCOME_GROUPS:
        for phase, v in train["grouped"]["v"][g].items():
            got = report["test_a"]["grouped"]["v"][g][phase]
            assert (v is None and got is None) or abs(got - v) < 1e-5
    b = report["test_b"]
    assert b["n_pregrasp"] > 0 and b["state_std"] > 0
    assert all(b["axes"][a]["ratio"] >= 0 for a in "xyz")
    md = (tmp_path / "verify" / "report.md").read_text()
    assert "| action/state sensitivity ratio |" in md and "Ordering score" in md
