"""The Monte-Carlo critic learns which chunk succeeds where, from counterfactual branch points: on held-out
episodes its argmax is the succeeding candidate, its test-B ratio is high where the true one is, and it
saves as a critic checkpoint the suite and the verifier load."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_rl_modeling import SMALL_CRITIC, tiny_policy

from lerobot_bboxpick.rl.chunk_perturbations import Perturbation
from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
from lerobot_bboxpick.rl.counterfactual_dataset import CONFIG_NAME, POINTS_DIR, load_points
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel
from lerobot_bboxpick.rl.train_mc_critic import (
    TrainMcCriticConfig,
    evaluate_critic,
    relative_candidates,
    split_by_episode,
    train_mc_critic,
)
from lerobot_bboxpick.sim.outcome import OUTCOMES

pytestmark = pytest.mark.slow  # trains a critic (~40 s) for the module
KINDS = ["policy", "sample1", "x+0.030", "x-0.030"]
BASE = np.array([0.5, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.07])  # tool down, tcp x = world x


def write_points(root: Path, policy_path: Path, episodes: int = 40, per_episode: int = 2) -> None:
    """Branch points where moving +x picks when the target box is on the image's right, -x when on its
    left, and the policy's own chunks (no offset) never pick."""
    rng = np.random.default_rng(0)
    (root / POINTS_DIR).mkdir(parents=True)
    run_key = {"candidates": KINDS}
    (root / CONFIG_NAME).write_text(
        json.dumps({"run_key": run_key, "config": {"policy_path": str(policy_path)}})
    )
    for e in range(episodes):
        n = per_episode
        right = rng.random(n) < 0.5
        cx = np.where(right, 0.75, 0.25) + rng.uniform(-0.05, 0.05, n)
        bbox = np.stack([cx - 0.08, np.full(n, 0.4), cx + 0.08, np.full(n, 0.55)], 1).astype(np.float32)
        state = np.tile(BASE, (n, 1, 1))
        state[:, 0, :3] += rng.uniform(-0.02, 0.02, (n, 3))
        chunk = np.repeat(state[:, :, None, :], 16, axis=2)[:, 0]  # hold the pose
        cands = np.stack(
            [chunk, chunk + 0.0005 * rng.standard_normal(chunk.shape)]
            + [np.stack([Perturbation("x", d).apply(c) for c in chunk]) for d in (0.03, -0.03)],
            axis=1,
        )
        win = np.stack([np.zeros(n, bool), np.zeros(n, bool), right, ~right], 1)
        np.savez_compressed(
            root / POINTS_DIR / f"grid_id_seed{e}.npz",
            image=rng.integers(0, 255, (n, 1, 3, 224, 224), dtype=np.uint8),
            state=state,
            bbox=bbox[:, None],
            candidates=cands.astype(np.float32),
            outcome=np.where(win, OUTCOMES.index("pick"), OUTCOMES.index("empty")).astype(np.int8),
            steps=np.full((n, 4), 40, np.int16),
            ret=np.where(win, 0.99**39, 0.0).astype(np.float32),
            step=np.arange(n) * 24,
            setting=np.array("grid_id"),
            seed=np.array(e),
            base_outcome=np.array(0),
        )


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("mc")
    policy = tiny_policy(n_obs_steps=1)
    policy.save_pretrained(root / "policy")
    write_points(root / "cf", root / "policy")
    cfg = TrainMcCriticConfig(
        data_dir=root / "cf",
        critic=IqlCriticConfig(**SMALL_CRITIC),
        output_dir=root / "critic",
        steps=600,
        warmup_steps=50,
        lr=1e-3,
        progress=False,
    )
    return cfg, train_mc_critic(cfg)


def test_split_holds_out_whole_episodes(trained):
    cfg, _ = trained
    points = load_points(cfg.data_dir)
    is_val = split_by_episode(points, 0.2, 0)
    assert is_val.sum() == 16  # 8 of 40 episodes, 2 points each
    for seed in set(points.seed.tolist()):
        assert len(set(is_val[points.seed == seed].tolist())) == 1


def test_held_out_argmax_is_the_succeeding_chunk(trained):
    _, report = trained
    r = report["val"]["rerank"]
    assert r["policy_pick"] == 0.0
    assert r["all"]["best_possible_pick"] == 1.0
    assert r["all"]["chosen_pick"] >= 0.85  # the critic learned where to move, per state
    assert r["policy_draws"]["chosen_pick"] == 0.0  # nothing to gain among the policy's own draws


def test_true_and_predicted_x_sensitivity_are_high(trained):
    _, report = trained
    assert report["true_sensitivity"]["axes"]["x"]["ret_change"] == pytest.approx(0.99**39)
    assert report["val"]["test_b"]["axes"]["x"]["ratio"] >= 0.5
    assert "| x |" in (Path(report["checkpoint"]).parents[2] / "mc_report.md").read_text()


def test_checkpoint_reloads_to_the_same_evaluation(trained):
    cfg, report = trained
    model = IqlCriticModel.from_pretrained(report["checkpoint"])
    assert model.horizon == 16 and model.config.state_embed_dim == SMALL_CRITIC["state_embed_dim"]
    points = load_points(cfg.data_dir)
    val = points.subset(split_by_episode(points, cfg.val_fraction, cfg.seed))
    again = evaluate_critic(model, val, relative_candidates(val))
    assert again["rerank"] == report["val"]["rerank"]
    assert again["test_b"]["axes"]["x"]["ratio"] == pytest.approx(
        report["val"]["test_b"]["axes"]["x"]["ratio"]
    )
