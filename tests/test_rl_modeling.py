"""The critic model: its frozen encoder's features are the bbox_diffusion policy's own, byte for byte;
save/load round trips; the encoder stays frozen; bad inputs are refused by name."""

from __future__ import annotations

import json

import pytest
import torch

from lerobot_bboxpick.apps.bench import _policy_features
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy
from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel, load_policy

SMALL_CRITIC = {"state_embed_dim": 64, "action_embed_dim": 32, "hidden_dim": 64}


def tiny_policy(seed: int = 0, **overrides) -> BboxDiffusionPolicy:
    """A randomly initialised, small bbox_diffusion policy (224 px camera, 48 px encoder input)."""
    torch.manual_seed(seed)
    inputs, outputs = _policy_features(image_size=224)
    config = BboxDiffusionConfig(
        device="cpu", input_features=inputs, output_features=outputs, image_size=48, feature_stage=1,
        num_keypoints=8, down_dims=(16, 32), diffusion_step_embed_dim=16, **overrides,
    )  # fmt: skip
    return BboxDiffusionPolicy(config)


def obs(b: int, seed: int = 1) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    state = torch.tensor([0.5, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.07]).repeat(b, 2, 1)
    state[..., :3] += 0.02 * torch.rand(b, 2, 3, generator=g)
    return {
        "observation.images.wrist": torch.rand(b, 2, 3, 224, 224, generator=g),
        "observation.state": state,
        "observation.bbox": torch.tensor([0.3, 0.3, 0.5, 0.6]).repeat(b, 2, 1),
    }


def chunks(b: int, seed: int = 2) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    c = torch.zeros(b, 16, 10)
    c[..., :3] = 0.05 * torch.randn(b, 16, 3, generator=g)
    c[..., 3], c[..., 7], c[..., 9] = 1.0, 1.0, 0.05
    return c


@pytest.fixture(scope="module")
def policy() -> BboxDiffusionPolicy:
    p = tiny_policy()
    with torch.no_grad():  # EMA weights differ from the trained ones: the critic must take the EMA ones
        for param in p.model.parameters():
            param.add_(0.01)
    return p


def test_frozen_encoder_features_are_the_policys_own(policy):
    critic = IqlCriticModel.from_policy(IqlCriticConfig(**SMALL_CRITIC), policy)
    batch = obs(3)
    model = policy.ema_model.eval()
    ref = model.global_condition(*model._inputs(batch))
    critic.train()  # a frozen encoder stays in eval mode (centre crop) even then
    got = critic.encode(batch)
    assert torch.equal(got, ref)
    assert got.shape[1] == critic.dims.state_dim
    # and not the non-EMA model's, which differ
    other = policy.model.eval()
    assert (other.global_condition(*other._inputs(batch)) - ref).abs().max() > 1e-4
    # the mask really enters: another box changes the features
    moved = {**batch, "observation.bbox": torch.tensor([0.6, 0.6, 0.8, 0.9]).repeat(3, 2, 1)}
    assert (critic.encode(moved) - got).abs().max() > 1e-4


def test_frozen_encoder_gets_no_gradient_and_no_optimiser_group(policy):
    critic = IqlCriticModel.from_policy(IqlCriticConfig(**SMALL_CRITIC), policy).train()
    s = critic.encode(obs(2))
    loss = critic.q(s, chunks(2)).sum() + critic.v(s).sum()
    loss.backward()
    assert not s.requires_grad
    assert all(p.grad is None for p in critic.encoder.parameters())
    assert critic.critic.q.action_proj[0][0].weight.grad.abs().sum() > 0  # the chunk MLP trains
    groups = critic.get_optim_params(4e-4, 0.1)
    assert len(groups) == 1 and groups[0]["lr"] == 4e-4
    unfrozen = IqlCriticModel.from_policy(IqlCriticConfig(freeze_encoder=False, **SMALL_CRITIC), policy)
    lrs = [g["lr"] for g in unfrozen.get_optim_params(4e-4, 0.1)]
    assert lrs == pytest.approx([4e-4, 4e-5])
    assert unfrozen.train().encoder.training  # augmentation on when the encoder trains


def test_save_load_round_trip_gives_identical_outputs(policy, tmp_path):
    critic = IqlCriticModel.from_policy(IqlCriticConfig(expectile=0.8, **SMALL_CRITIC), policy)
    with torch.no_grad():  # make the target Qs differ from the online ones, so both must be saved
        for p in critic.critic.q_target.parameters():
            p.mul_(0.5)
    critic.save_pretrained(tmp_path / "critic")
    assert json.loads((tmp_path / "critic" / "config.json").read_text())["expectile"] == 0.8
    assert (
        json.loads((tmp_path / "critic" / "encoder" / "config.json").read_text())["type"] == "bbox_diffusion"
    )
    loaded = IqlCriticModel.from_pretrained(tmp_path / "critic")
    batch, a = obs(2), chunks(2)
    with torch.no_grad():
        s, s2 = critic.encode(batch), loaded.encode(batch)
        assert torch.equal(s, s2)
        assert torch.equal(critic.v(s), loaded.v(s2))
        assert torch.equal(critic.q(s, a), loaded.q(s2, a))
        flat = critic.flat_actions(a)
        assert torch.equal(critic.critic.q_target_min(s, flat), loaded.critic.q_target_min(s2, flat))
    assert loaded.config.expectile == 0.8 and not loaded.training


def test_warm_start_from_a_saved_policy_checkpoint(policy, tmp_path):
    policy.save_pretrained(tmp_path / "policy")
    critic = IqlCriticModel.from_policy_checkpoint(IqlCriticConfig(**SMALL_CRITIC), tmp_path / "policy")
    model = policy.ema_model.eval()
    batch = obs(2)
    assert torch.equal(critic.encode(batch), model.global_condition(*model._inputs(batch)))
    # the loader keeps the checkpoint's denoising steps unless told otherwise (relabelling proposes at 4)
    steps = policy.config.num_inference_steps
    assert load_policy(tmp_path / "policy").config.num_inference_steps == steps
    assert (
        load_policy(tmp_path / "policy", num_inference_steps=steps + 3).config.num_inference_steps
        == steps + 3
    )


def test_bad_inputs_are_refused_by_name(policy, tmp_path):
    critic = IqlCriticModel.from_policy(IqlCriticConfig(**SMALL_CRITIC), policy)
    with pytest.raises(ValueError, match=r"action chunk must have shape \(\.\.\., 16, 10\)"):
        critic.q(torch.zeros(1, critic.dims.state_dim), torch.zeros(1, 8, 10))
    with pytest.raises(KeyError, match="observation.bbox"):
        critic.encode({k: v for k, v in obs(1).items() if k != "observation.bbox"})
    with pytest.raises(ValueError, match="expectile=1.5 must be in"):
        IqlCriticConfig(expectile=1.5)
    with pytest.raises(FileNotFoundError, match="model.safetensors is missing"):
        (tmp_path / "empty").mkdir()
        (tmp_path / "empty" / "config.json").write_text("{}")
        IqlCriticModel.from_pretrained(tmp_path / "empty")
