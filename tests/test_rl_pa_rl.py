"""PA-RL relabelling (rl.pa_rl): local Q-ascent reaches past the proposals within the trust region, a step
that does not improve Q is reverted and the dataset's chunk then stays; the relabel cache's validity mask
is honoured by the policy's training loss."""

from __future__ import annotations

import pytest
import torch
from test_rl_advantage_weighting import two_chunk_batch
from test_rl_modeling import tiny_policy

from lerobot_bboxpick.geometry import absolute_pose10_torch, relative_pose10_torch
from lerobot_bboxpick.rl.pa_rl import ChunkOptimiser, RelabelCache, diagnostics


class TargetCritic:
    """Q = -100 |last relative position - target|^2 (m^2), differentiable; V unused."""

    def __init__(self, target: torch.Tensor) -> None:
        self.target = target

    def encode(self, batch):
        return torch.zeros(batch["observation.state"].shape[0], 1)

    def q(self, state, chunk):
        return -100.0 * ((chunk[:, -1, :3] - self.target) ** 2).sum(-1)


def straight_chunks(ends: torch.Tensor) -> torch.Tensor:
    """Relative chunks (N, 16, 10) moving linearly to the positions ``ends`` (N, 3), width 7 cm."""
    c = torch.zeros(len(ends), 16, 10)
    c[..., 3], c[..., 7], c[..., 9] = 1.0, 1.0, 0.07
    c[..., :3] = torch.linspace(1 / 16, 1, 16)[None, :, None] * ends[:, None, :]
    return c


def setup(target, dataset_end, proposal_ends):
    obs = {k: v[:1] for k, v in two_chunk_batch(2).items() if k != "action"}
    current = obs["observation.state"][:, -1]
    absolute = lambda ends: absolute_pose10_torch(straight_chunks(torch.tensor(ends)), current)  # noqa: E731
    return (
        obs,
        current,
        TargetCritic(torch.tensor(target)),
        absolute([dataset_end]),
        absolute(proposal_ends)[None],
    )


def test_ascent_reaches_past_every_proposal_within_the_trust_region():
    obs, current, critic, dataset_chunk, proposals = setup(
        [0.05, 0.0, 0.0], [0.0, 0.0, 0.0], [[0.01, 0.0, 0.0], [0.02, 0.01, 0.0], [-0.02, 0.0, 0.0]]
    )
    optimiser = ChunkOptimiser(critic, top_k=2, ascent_steps=20, step_size=0.002, max_offset=0.015)
    result = optimiser.relabel(obs, proposals, dataset_chunk)
    chosen = relative_pose10_torch(result.actions, current)[0, -1, :3]
    # the best proposal ends at (2, 1, 0) cm; ascent moves it toward (5, 0, 0) by at most 1.5 cm per axis
    assert chosen.tolist() == pytest.approx([0.035, 0.0, 0.0], abs=1e-4)
    assert bool(result.valid[0]) and not bool(result.dataset_won[0])
    assert result.chosen_q.item() > result.dataset_q.item()
    assert not result.reverted.any()
    # drift: the chosen end minus the dataset's, in the world frame (the robot's "upward drift" axis)
    world_end = absolute_pose10_torch(straight_chunks(torch.tensor([[0.035, 0.0, 0.0]])), current)[0, -1, :3]
    expected = world_end - dataset_chunk[0, -1, :3]
    assert result.drift[0].tolist() == pytest.approx(expected.tolist(), abs=1e-4)
    report = diagnostics([result])
    assert report["mean_drift_mm"] == pytest.approx(35.0, abs=0.1)
    assert report["mean_drift_xyz_mm"] == pytest.approx((1000 * expected).tolist(), abs=0.1)
    # only positions and width move; the rotation stays the proposal's
    assert torch.allclose(result.actions[0, :, 3:9], proposals[0, 1, :, 3:9], atol=1e-5)


def test_no_improvement_is_reverted_and_the_dataset_chunk_is_not_replaced():
    obs, current, critic, dataset_chunk, proposals = setup(
        [0.03, 0.0, 0.0], [0.03, 0.0, 0.0], [[0.031, 0.0, 0.0], [-0.02, 0.0, 0.0]]
    )
    # a step this large overshoots by up to the 3 cm bound: Q drops, so every candidate is reverted
    optimiser = ChunkOptimiser(critic, top_k=2, ascent_steps=3, step_size=10.0, max_offset=0.03)
    result = optimiser.relabel(obs, proposals, dataset_chunk)
    assert result.reverted.all() and bool(result.dataset_won[0])
    assert not bool(result.valid[0])  # the dataset's chunk is already the best: nothing to relabel
    assert torch.allclose(result.actions, dataset_chunk, atol=1e-5)
    report = diagnostics([result])
    assert (report["revert_rate"], report["dataset_action_wins"], report["valid_fraction"]) == (1.0, 1.0, 0.0)


def test_the_training_loss_uses_valid_cache_entries_only(tmp_path):
    policy = tiny_policy(seed=0).train()
    batch = two_chunk_batch(4)
    batch["index"] = torch.tensor([10, 11, 12, 13])
    replacement = batch["action"].clone()
    replacement[..., 0] += 0.05
    path = tmp_path / "cache.safetensors"
    # frame 10 valid, 11 invalid, 12 absent, 13 valid (stored out of order)
    RelabelCache(torch.tensor([13, 11, 10]), replacement[[3, 1, 0]], torch.tensor([True, False, True])).save(
        path
    )
    cache = RelabelCache.load(path)
    applied = cache.apply(batch)
    changed = (applied["action"] != batch["action"]).any(dim=(1, 2)).tolist()
    assert changed == [True, False, False, True]
    assert torch.equal(applied["action"][[0, 3]], replacement[[0, 3]])

    policy.config.parl_cache_path = str(path)
    torch.manual_seed(7)
    loss, _ = policy.forward(batch)
    torch.manual_seed(7)
    expected = policy.model.compute_loss(applied)
    torch.manual_seed(7)
    raw = policy.model.compute_loss(batch)
    assert loss.item() == pytest.approx(expected.item(), rel=1e-6)
    assert abs(loss.item() - raw.item()) > 1e-4  # the relabelled chunks really entered the loss


def test_bad_caches_and_batches_are_refused_by_name(tmp_path):
    with pytest.raises(FileNotFoundError, match="parl_cache_path='nowhere' is not a relabel cache file"):
        RelabelCache.load("nowhere")
    with pytest.raises(ValueError, match="cache index holds a frame twice"):
        RelabelCache(torch.tensor([1, 1]), torch.zeros(2, 16, 10), torch.ones(2, dtype=torch.bool))
    cache = RelabelCache(torch.tensor([1]), torch.zeros(1, 16, 10), torch.ones(1, dtype=torch.bool))
    with pytest.raises(KeyError, match="needs LeRobotDataset's 'index'"):
        cache.apply(two_chunk_batch(2))
    with pytest.raises(ValueError, match="step_size=0.0 must be > 0"):
        ChunkOptimiser(None, step_size=0.0)
