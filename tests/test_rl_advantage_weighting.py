"""Advantage-weighted fine-tuning (rl.advantage_weighting): the weights are exp(A / T) clipped; trained on
two demonstrated chunks for one observation, the weighted loss makes the policy produce the one the critic
prefers where plain BC averages them; the anchor holds the policy to its reference; the reference sees
the trained model's own draw; bad options name their field."""

from __future__ import annotations

import copy
import dataclasses
import math

import pytest
import torch
import torch.nn.functional as F
from test_rl_modeling import SMALL_CRITIC, obs, tiny_policy

from lerobot_bboxpick.geometry import absolute_pose10_torch, relative_pose10_torch
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.rl.advantage_weighting import AdvantageWeightedLoss
from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel

OFFSET = 0.04  # m: the two demonstrated chunks end 4 cm to either side in x


class LastXCritic:
    """Q = 100 x (m) of the chunk's last relative position, V = 0: A = +4 for the +x chunk, -4 for -x."""

    def eval(self):
        return self

    def requires_grad_(self, flag):
        return self

    def to(self, device):
        return self

    def encode(self, batch):
        return torch.zeros(batch["observation.state"].shape[0], 1)

    def q(self, state, chunk):
        return 100.0 * chunk[:, -1, 0]

    def v(self, state):
        return torch.zeros(state.shape[0])


def two_chunk_batch(b: int = 8) -> dict[str, torch.Tensor]:
    """One observation repeated (its frame at 64 px: the encoder reads 48); half the chunks move linearly
    to +4 cm in x, half to -4 cm."""
    one = obs(1)
    one["observation.images.wrist"] = F.interpolate(one["observation.images.wrist"][0], size=64)[None]
    batch = {k: v.repeat(b, *([1] * (v.ndim - 1))) for k, v in one.items()}
    relative = torch.zeros(b, 16, 10)
    relative[..., 3], relative[..., 7], relative[..., 9] = 1.0, 1.0, 0.07
    sign = torch.tensor([1.0, -1.0]).repeat(b // 2)
    relative[..., 0] = sign[:, None] * torch.linspace(OFFSET / 16, OFFSET, 16)
    batch["action"] = absolute_pose10_torch(relative, batch["observation.state"][:, -1])
    return batch


def train(objective: AdvantageWeightedLoss, policy, steps: int = 250) -> dict:
    torch.manual_seed(0)
    policy.train()
    optimizer = torch.optim.Adam(policy.model.parameters(), lr=2e-3)
    batch = two_chunk_batch()
    for _ in range(steps):
        loss, info = objective(policy.model, batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return info


def mean_last_x(policy, n: int = 32) -> float:
    """Mean final x offset (m) of ``n`` sampled chunks for the training observation (trained weights)."""
    batch = two_chunk_batch(n)
    model = policy.model.eval()
    relative = model.sample(
        {k: v for k, v in batch.items() if k != "action"}, generator=torch.Generator().manual_seed(3)
    )
    return relative[:, -1, 0].mean().item()


def test_weights_are_the_clipped_exponential_of_the_advantage():
    objective = AdvantageWeightedLoss(None, None, temperature=2.0, max_weight=20.0)
    w = objective.weights(torch.tensor([0.0, 2 * math.log(2.0), -2.0, 100.0]))
    assert torch.allclose(w, torch.tensor([1.0, 2.0, math.exp(-1.0), 20.0]))


def test_advantage_weighting_produces_the_preferred_chunk_where_bc_averages():
    weighted = tiny_policy(seed=0)
    objective = AdvantageWeightedLoss(LastXCritic(), None, temperature=1.0, max_weight=20.0, bc_weight=0.0)
    info = train(objective, weighted)
    assert info["awr_advantage"] == pytest.approx(0.0, abs=1e-4)  # +4 and -4 in equal numbers
    assert info["awr_weight"] == pytest.approx((20.0 + math.exp(-4.0)) / 2, rel=1e-4)
    assert info["awr_clipped"] == pytest.approx(0.5)
    bc = tiny_policy(seed=0)
    train(AdvantageWeightedLoss(None, None, bc_weight=0.0), bc)
    x_weighted, x_bc = mean_last_x(weighted), mean_last_x(bc)
    assert x_weighted > 0.75 * OFFSET, (x_weighted, x_bc)  # the +x chunk (4 cm), not the average
    assert abs(x_bc) < 0.4 * OFFSET, (x_weighted, x_bc)  # plain BC: as much -x as +x


def test_anchor_holds_the_policy_to_its_reference():
    finals = {}
    for anchor_weight in (0.0, 50.0):
        policy = tiny_policy(seed=0)
        reference = copy.deepcopy(policy.model)
        objective = AdvantageWeightedLoss(None, reference, bc_weight=0.0, anchor_weight=anchor_weight)
        finals[anchor_weight] = train(objective, policy, steps=120)["anchor_mse"]
    # logged either way; applied, it keeps the predictions several times closer to the reference's
    assert finals[50.0] < finals[0.0] / 4, finals


def test_the_reference_sees_the_trained_models_own_draw():
    policy = tiny_policy(seed=0).train()
    batch = two_chunk_batch(4)
    torch.manual_seed(5)
    alone = policy.model.denoising_terms(batch)
    after_alone = torch.get_rng_state()
    torch.manual_seed(5)
    terms = policy.model.denoising_terms(batch, reference=copy.deepcopy(policy.model).train())
    # same crop, jitter, noise and timestep: an identical copy predicts exactly the same
    assert torch.equal(terms.reference_prediction, terms.prediction)
    assert torch.equal(terms.loss, alone.loss)  # the reference changes nothing of the model's draw
    assert torch.equal(torch.get_rng_state(), after_alone)  # nor the draws that follow
    torch.manual_seed(5)
    assert policy.model.compute_loss(batch).item() == pytest.approx(alone.loss.mean().item())


def test_real_critic_advantages_are_q_minus_v_of_the_relative_chunk():
    policy = tiny_policy(seed=0)
    critic = IqlCriticModel.from_policy(IqlCriticConfig(**SMALL_CRITIC), policy)
    objective = AdvantageWeightedLoss(critic, None)
    batch = two_chunk_batch(4)
    got = objective.advantages(policy.model, batch)
    features = critic.encode({k: v for k, v in batch.items() if k != "action"})
    relative = relative_pose10_torch(batch["action"], batch["observation.state"][:, -1])
    assert torch.allclose(got, critic.q(features, relative) - critic.v(features))
    assert got.std() > 0  # the two chunks differ in Q


def test_bad_options_and_mismatched_critics_name_the_field(tmp_path):
    with pytest.raises(ValueError, match="awr_temperature=0.0 must be > 0"):
        BboxDiffusionConfig(awr_temperature=0.0)
    with pytest.raises(ValueError, match="awr_max_weight=0.5 must be >= 1"):
        BboxDiffusionConfig(awr_max_weight=0.5)
    with pytest.raises(ValueError, match="anchor_weight=-1 must be >= 0"):
        BboxDiffusionConfig(anchor_weight=-1)
    policy = tiny_policy(seed=0)
    with pytest.raises(FileNotFoundError, match="awr_critic_path='nowhere' is not a checkpoint folder"):
        AdvantageWeightedLoss.from_config(dataclasses.replace(policy.config, awr_critic_path="nowhere"))
    critic_dir = tmp_path / "critic"
    IqlCriticModel.from_policy(IqlCriticConfig(**SMALL_CRITIC), policy).save_pretrained(critic_dir)
    other = dataclasses.replace(policy.config, n_obs_steps=1, awr_critic_path=str(critic_dir))
    with pytest.raises(
        ValueError, match=r"awr_critic_path was built for another policy layout \(n_obs_steps"
    ):
        AdvantageWeightedLoss.from_config(other)
    loaded = AdvantageWeightedLoss.from_config(
        dataclasses.replace(policy.config, awr_critic_path=str(critic_dir))
    )
    assert loaded.critic is not None and loaded.reference is None


def test_measured_episode_advantages_weight_like_a_critic():
    """Episode 0 holds the +x chunks, episode 1 the -x ones: advantages +4 / -4 by episode give the loss of
    the critic that says the same (which the test above trains to the +x chunk)."""
    policy = tiny_policy(seed=0).train()
    batch = two_chunk_batch()
    batch["episode_index"] = torch.tensor([0, 1]).repeat(4)
    measured = AdvantageWeightedLoss(
        None, None, temperature=1.0, episode_advantages=torch.tensor([4.0, -4.0])
    )
    critic = AdvantageWeightedLoss(LastXCritic(), None, temperature=1.0)
    assert torch.allclose(measured.advantages(policy.model, batch), critic.advantages(policy.model, batch))
    torch.manual_seed(0)
    loss, info = measured(policy.model, batch)
    torch.manual_seed(0)
    expected, expected_info = critic(policy.model, batch)
    assert loss.item() == pytest.approx(expected.item(), rel=1e-6)
    assert info["awr_weight"] == pytest.approx((20.0 + math.exp(-4.0)) / 2, rel=1e-4)
    assert info == pytest.approx(expected_info, abs=1e-5)
    batch["episode_index"] = torch.tensor([0, 2]).repeat(4)
    with pytest.raises(ValueError, match="advantages for 2 episodes; the batch holds episode 2"):
        measured(policy.model, batch)


def test_a_critic_and_measured_advantages_are_exclusive():
    with pytest.raises(ValueError, match="awr_critic_path and awr_advantages_path are both set"):
        BboxDiffusionConfig(awr_critic_path="c", awr_advantages_path="a.json")
    with pytest.raises(ValueError, match="not both"):
        AdvantageWeightedLoss(LastXCritic(), None, episode_advantages=torch.zeros(2))
