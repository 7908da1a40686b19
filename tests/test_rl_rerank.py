"""Q-reranking keeps the argmax-Q chunk, per state, in the critic's relative action space."""

from __future__ import annotations

import pytest
import torch
from test_rl_modeling import obs

from lerobot_bboxpick.geometry import relative_pose10_torch
from lerobot_bboxpick.rl.rerank import rerank_absolute, rerank_by_q


def test_rerank_picks_the_argmax_per_state():
    # Q = -|mean x of the chunk - target(s)|: state 0 wants x = 0.1, state 1 wants x = -0.2
    state = torch.tensor([[0.1], [-0.2]])
    xs = torch.tensor([[-0.2, 0.0, 0.12, 0.3], [0.3, -0.19, 0.0, -0.5]])
    cand = torch.zeros(2, 4, 16, 10)
    cand[..., 0] = xs[..., None]

    def q(s, a):
        return -(a[..., 0].mean(-1) - s[:, 0]).abs()

    r = rerank_by_q(q, state, cand)
    assert r.index.tolist() == [2, 1]
    assert r.best[:, 0, 0].tolist() == pytest.approx([0.12, -0.19])
    assert r.scores[0].tolist() == pytest.approx([-0.3, -0.1, -0.02, -0.2])
    with pytest.raises(ValueError, match="candidates"):
        rerank_by_q(q, state, cand[0])


class RelativeXCritic:
    """Encodes nothing but the batch size; Q = x of the chunk's first pose relative to the TCP."""

    def encode(self, batch):
        return torch.zeros(batch["observation.state"].shape[0], 1)

    def q(self, state, chunk):
        return chunk[:, 0, 0]


def test_rerank_absolute_scores_in_the_tcp_frame_and_returns_absolute_chunks():
    batch = obs(1)
    base = batch["observation.state"][:, -1]  # rotation rows (1,0,0), (0,-1,0): tcp x = world x
    cand = base[:, None, None, :].repeat(1, 3, 16, 1).clone()
    cand[0, :, :, 0] += torch.tensor([0.01, 0.05, -0.02])[:, None]  # world x offsets
    r = rerank_absolute(RelativeXCritic(), batch, cand)
    assert r.index.tolist() == [1]
    assert torch.equal(r.best, cand[:, 1])
    rel = relative_pose10_torch(cand[0], base)
    assert r.scores[0].tolist() == pytest.approx(rel[:, 0, 0].tolist(), abs=1e-6)
    assert r.scores[0].tolist() == pytest.approx([0.01, 0.05, -0.02], abs=1e-6)


def test_sample_and_rerank_keeps_the_policy_sample_the_critic_scores_highest():
    from test_rl_modeling import SMALL_CRITIC, tiny_policy

    from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
    from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel
    from lerobot_bboxpick.rl.rerank import sample_and_rerank

    policy = tiny_policy().eval()
    critic = IqlCriticModel.from_policy(IqlCriticConfig(**SMALL_CRITIC), policy)
    batch = obs(2)
    r = sample_and_rerank(policy, critic, batch, n=4, generator=torch.Generator().manual_seed(0))
    # the same 8 samples again, scored independently
    repeated = {k: v.repeat_interleave(4, dim=0) for k, v in batch.items()}
    chunks = policy.predict_action_chunk(repeated, generator=torch.Generator().manual_seed(0)).view(
        2, 4, 16, 10
    )
    with torch.no_grad():
        s = critic.encode(batch).repeat_interleave(4, dim=0)
        rel = relative_pose10_torch(
            chunks.flatten(0, 1), batch["observation.state"][:, -1].repeat_interleave(4, 0)
        )
        scores = critic.q(s, rel).view(2, 4)
    assert torch.allclose(r.scores, scores, atol=1e-6)
    assert r.index.tolist() == scores.argmax(1).tolist()
    assert torch.equal(r.best, chunks[torch.arange(2), scores.argmax(1)])
    assert scores.std() > 0  # the samples differ, so the choice means something


def test_selector_makes_select_action_execute_the_critics_choice():
    from test_rl_modeling import tiny_policy

    from lerobot_bboxpick.rl.rerank import QRerankSelector

    policy = tiny_policy().eval()
    batch = {k: v[:, -1] for k, v in obs(1).items()}  # one observation, as the env gives it
    selector = QRerankSelector(RelativeXCritic(), n=6)
    policy.chunk_selector = selector
    policy.reset()
    first = policy.select_action(batch)
    r = selector.last
    assert r is not None and r.scores.shape == (1, 6)
    assert r.index.item() == r.scores.argmax().item()
    assert torch.equal(first, r.best[:, 0])  # the executed action opens the chosen chunk
    assert r.scores.std() > 0
    # the rest of the chunk is queued: no new sampling until n_action_steps actions were taken
    for t in range(1, policy.config.n_action_steps):
        assert torch.equal(policy.select_action(batch), r.best[:, t])
        assert selector.last is r
    with pytest.raises(ValueError, match="n=0"):
        QRerankSelector(RelativeXCritic(), n=0)


def test_selector_residuals_are_scored_and_can_win():
    from test_rl_modeling import tiny_policy

    from lerobot_bboxpick.rl.chunk_perturbations import parse_perturbations
    from lerobot_bboxpick.rl.rerank import QRerankSelector

    policy = tiny_policy().eval()
    batch = obs(1)
    selector = QRerankSelector(RelativeXCritic(), n=2, perturbations=parse_perturbations("x:0.05,yaw:0.3"))
    assert selector.candidates_per_state == 10
    best = selector(policy, batch, torch.Generator().manual_seed(0))
    r = selector.last
    assert r.scores.shape == (1, 10)
    # Q = relative x of the first pose; the +x residual moves the first pose a little forward (ramp), so
    # the best candidate is a draw's x+0.05 residual (index 1 or 6), not a bare draw.
    assert r.index.item() in (1, 6)
    assert torch.equal(best, r.best)
    # the chosen chunk is its draw moved 5 cm along world x at the chunk's end, the rest unchanged
    repeated = {k: v.repeat_interleave(2, dim=0) for k, v in batch.items()}
    draws = policy.predict_action_chunk(repeated, generator=torch.Generator().manual_seed(0))
    draw = draws[r.index.item() // 5]
    delta = best[0] - draw
    assert delta[-1, 0].item() == pytest.approx(0.05, abs=1e-5)
    assert delta[:, 1:].abs().max().item() < 1e-5
