"""Q-guided diffusion (rl.q_guidance): the critic's gradient moves sampled chunks toward higher Q, within
the per-step bound; a critic that ignores actions changes nothing; the suite's flags reach the run key."""

from __future__ import annotations

import json

import pytest
import torch
from test_rl_modeling import obs, tiny_policy

from lerobot_bboxpick.geometry import relative_pose10_torch
from lerobot_bboxpick.rl.q_guidance import QGuidance
from lerobot_bboxpick.rl.rerank import QRerankSelector, sample_chunks


class TargetCritic:
    """Q = -|relative position of the chunk's last pose - target|^2 (m^2): highest at ``target``."""

    def __init__(self, target: torch.Tensor) -> None:
        self.target = target
        self.encodes = 0  # observations encoded: guidance and reranking share one encoding

    def encode(self, batch):
        self.encodes += 1
        return torch.zeros(batch["observation.state"].shape[0], 1)

    def q(self, state, chunk):
        return -((chunk[:, -1, :3] - self.target) ** 2).sum(-1)


class ActionBlindCritic(TargetCritic):
    """Q depends on the state only (the paper's failure mode, taken to the limit)."""

    def q(self, state, chunk):
        return state[:, 0] + 0.0 * chunk.sum((1, 2))


def _last_relative_position(policy, batch, chunk: torch.Tensor) -> torch.Tensor:
    return relative_pose10_torch(chunk, batch["observation.state"][:, -1])[0, -1, :3]


@pytest.fixture(scope="module")
def policy():
    return tiny_policy().eval()


def test_guidance_moves_the_chunk_toward_higher_q_within_the_bound(policy):
    batch = obs(1)
    plain = sample_chunks(policy, batch, 1, torch.Generator().manual_seed(0))[:, 0]
    start = _last_relative_position(policy, batch, plain)
    target = start + torch.tensor([0.06, -0.04, 0.0])  # 7.2 cm away from the unguided chunk's end
    guidance = QGuidance(TargetCritic(target), scale=100.0, max_step=0.1)
    corrections = []
    guide_for = guidance.guide

    def recording_guide(p, b, repeats=1, features=None):
        g = guide_for(p, b, repeats, features)

        def wrapped(x):
            c = g(x)
            corrections.append(c)
            return c

        return wrapped

    guidance.guide = recording_guide
    selector = QRerankSelector(guidance.critic, n=1, guidance=guidance)
    guided = selector(policy, batch, torch.Generator().manual_seed(0))
    assert guidance.critic.encodes == 1  # one encoding served the guide and the ranking
    end = _last_relative_position(policy, batch, guided)
    before, after = (start - target).norm().item(), (end - target).norm().item()
    assert after < before - 0.01, (before, after)  # at least 1 cm closer (the last step alone: <= 2.1)
    # every correction respects the bound, and the bound was active (the gradient was larger)
    assert len(corrections) == policy.config.num_inference_steps
    peak = max(c.abs().max().item() for c in corrections)
    assert peak == pytest.approx(0.1)
    assert guidance.q_trace[-1] > guidance.q_trace[0]


def test_a_critic_blind_to_actions_leaves_the_policys_chunk_unchanged(policy):
    batch = obs(2)
    plain = sample_chunks(policy, batch, 2, torch.Generator().manual_seed(1))
    guidance = QGuidance(ActionBlindCritic(torch.zeros(3)), scale=100.0, max_step=0.1)
    guided = sample_chunks(policy, batch, 2, torch.Generator().manual_seed(1), guidance)
    assert torch.equal(guided, plain)


def test_guidance_refuses_epsilon_policies_and_bad_bounds():
    eps_policy = tiny_policy(prediction_type="epsilon").eval()
    guidance = QGuidance(TargetCritic(torch.zeros(3)), scale=1.0, max_step=0.02)
    with pytest.raises(ValueError, match="prediction_type='sample'"):
        sample_chunks(eps_policy, obs(1), 1, None, guidance)
    with pytest.raises(ValueError, match="guidance_scale"):
        QGuidance(TargetCritic(torch.zeros(3)), scale=0.0, max_step=0.02)
    with pytest.raises(ValueError, match="guidance_max_step"):
        QGuidance(TargetCritic(torch.zeros(3)), scale=1.0, max_step=2.0)
    with pytest.raises(ValueError, match="selector's own critic"):
        QRerankSelector(TargetCritic(torch.zeros(3)), n=2, guidance=guidance)


def test_suite_flags_need_a_critic_and_enter_the_run_key(tmp_path):
    from lerobot_bboxpick.eval.suite import SuiteConfig, run_key

    ckpt = "examples/bbox_diffusion_lego_pick"
    with pytest.raises(ValueError, match="critic_path"):
        SuiteConfig(policies=ckpt, guidance_scale=1.0)
    critic = tmp_path / "critic"
    critic.mkdir()
    (critic / "config.json").write_text(json.dumps({}))
    (critic / "model.safetensors").write_bytes(b"weights")
    plain = run_key(SuiteConfig(policies=ckpt, critic_path=critic, rerank_samples=4), ckpt)
    assert "guidance_scale" not in plain and plain["rerank_samples"] == 4  # older tables' keys hold
    guided = run_key(
        SuiteConfig(policies=ckpt, critic_path=critic, rerank_samples=1, guidance_scale=3.0), ckpt
    )
    assert (guided["guidance_scale"], guided["guidance_max_step"]) == (3.0, 0.02)
    assert guided["critic"] == plain["critic"]
