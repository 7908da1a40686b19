"""The IQL critic as a LeRobot-style model: the policy's own observation encoder + ``IqlCritic``.

Paper section 5.3: "The critic reuses the diffusion policy's visual encoder backbone so the state
encoding is byte-identical to the BC policy. The visual encoder is frozen and warm-started from the
pretrained diffusion-policy checkpoint." Here the state encoding is literally the policy's code path:
``BboxDiffusionModel.global_condition`` (mask drawing, centre crop, RGB+mask backbone, relative and
scaled observed poses, mask moments) run on copies of the policy's ``encoder`` / ``augment`` /
``obs_scaler`` modules taken from its inference (EMA) model. Actions are chunks relative to the latest
observed TCP pose (``inv(T_base) @ T``, ``lerobot_bboxpick.geometry``), scaled with the policy's own
``PoseScaler`` and flattened (16 x 10 = 160 numbers).

A checkpoint folder holds ``config.json`` (``IqlCriticConfig``), ``model.safetensors`` (critic and
encoder weights: it is self-contained) and ``encoder/config.json`` (the policy config the encoder is
rebuilt from, with ``pretrained_backbone`` off since the weights are in the checkpoint).
"""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import draccus
import torch
from huggingface_hub.constants import CONFIG_NAME, SAFETENSORS_SINGLE_FILE
from lerobot.configs import PreTrainedConfig
from lerobot.utils.hub import HubMixin
from safetensors.torch import load_model, save_model
from torch import Tensor, nn

from lerobot_bboxpick.keys import STATE
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import (
    BboxDiffusionModel,
    BboxDiffusionPaperPolicy,
    BboxDiffusionPolicy,
    PoseScaler,
    global_condition_dim,
    image_feature_dim,
)
from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
from lerobot_bboxpick.rl.iql import IqlBatch, IqlCritic, IqlDims

ENCODER_DIR = "encoder"
POLICY_CLASSES: dict[str, type[BboxDiffusionPolicy]] = {
    "bbox_diffusion": BboxDiffusionPolicy,
    "bbox_diffusion_paper": BboxDiffusionPaperPolicy,
}
ACTION_DIM = 10  # pose10: position, rot6d, gripper width


class PolicyObservationEncoder(nn.Module):
    """The ``bbox_diffusion`` observation path, on its own copies of the policy's modules.

    ``forward`` calls ``BboxDiffusionModel.global_condition`` itself (it only reads ``config``,
    ``augment``, ``encode_images``, ``target_view`` and ``obs_scaler``, which this module has under the same
    names), so the features cannot drift from the policy's when that code changes.
    """

    def __init__(self, model: BboxDiffusionModel) -> None:
        """Copy the observation modules of ``model`` (a policy's ``ema_model`` or ``model``)."""
        super().__init__()
        self.config: BboxDiffusionConfig = model.config
        self.encoder = copy.deepcopy(model.encoder)
        self.target_view = copy.deepcopy(model.target_view)
        self.augment = copy.deepcopy(model.augment)
        self.obs_scaler = copy.deepcopy(model.obs_scaler)

    def encode_images(self, rgb: Tensor, mask: Tensor | None) -> Tensor:
        """The copied encoder's features, always in PyTorch (the policy's ONNX sessions are not copied)."""
        return self.encoder(rgb, mask)

    @classmethod
    def from_policy_config(cls, config: BboxDiffusionConfig) -> PolicyObservationEncoder:
        """Randomly initialised encoder of ``config``'s architecture (no weight download)."""
        config = dataclasses.replace(config, pretrained_backbone=False)
        return cls(BboxDiffusionModel(config))

    @property
    def out_dim(self) -> int:
        """Width of the state feature: the policy's global condition width."""
        return global_condition_dim(self.config, image_feature_dim(self))

    def forward(self, batch: dict[str, Tensor]) -> Tensor:
        """Observations ``(B, n_obs, ...)`` (images in [0, 1], absolute states, bboxes) -> ``(B, D)``."""
        c = self.config
        missing = [k for k in (c.image_key, STATE) if k not in batch]
        if c.bbox_mode != "none" and c.bbox_feature_key not in batch:
            missing.append(c.bbox_feature_key)
        if missing:
            raise KeyError(f"observation batch lacks {missing}; it has {sorted(batch)}")
        images, states = batch[c.image_key], batch[STATE]
        if images.ndim != 5 or states.ndim != 3 or states.shape[1] != c.n_obs_steps:
            raise ValueError(
                f"expected images (B, {c.n_obs_steps}, 3, H, W) and states (B, {c.n_obs_steps}, 10), got "
                f"{tuple(images.shape)} and {tuple(states.shape)}"
            )
        return BboxDiffusionModel.global_condition(self, images, states, batch.get(c.bbox_feature_key))


def load_policy(path: str | Path, num_inference_steps: int | None = None) -> BboxDiffusionPolicy:
    """A ``bbox_diffusion`` / ``bbox_diffusion_paper`` checkpoint (``pretrained_model`` folder), on the CPU,
    without downloading backbone weights (the checkpoint holds them); ``num_inference_steps`` overrides
    its denoising steps per chunk (None: the checkpoint's), as ``--policy.num_inference_steps`` does."""
    config = PreTrainedConfig.from_pretrained(path)
    if config.type not in POLICY_CLASSES:
        raise ValueError(
            f"policy checkpoint {path} has type {config.type!r}; "
            f"the critic needs one of {sorted(POLICY_CLASSES)}"
        )
    config = dataclasses.replace(config, pretrained_backbone=False, device="cpu")
    if num_inference_steps is not None:
        config.num_inference_steps = num_inference_steps
    return POLICY_CLASSES[config.type].from_pretrained(path, config=config)


class IqlCriticModel(nn.Module, HubMixin):
    """State encoder (the policy's, usually frozen) + IQL critic over relative action chunks."""

    def __init__(self, config: IqlCriticConfig, encoder: PolicyObservationEncoder) -> None:
        """Use ``from_policy`` / ``from_policy_checkpoint`` / ``from_pretrained`` rather than this."""
        super().__init__()
        self.config = config
        self.encoder = encoder
        pc = encoder.config
        self.horizon = pc.horizon
        self.action_scaler = PoseScaler(
            pc.action_position_scale, pc.max_gripper_width, pc.action_rotation_scale
        )
        self.dims = IqlDims(
            state_dim=encoder.out_dim,
            action_dim=pc.horizon * ACTION_DIM,
            state_embed_dim=config.state_embed_dim,
            action_embed_dim=config.action_embed_dim,
            hidden_dim=config.hidden_dim,
            num_hidden_layers=config.num_hidden_layers,
        )
        self.critic = IqlCritic(self.dims)
        if config.freeze_encoder:
            self.encoder.requires_grad_(False)
        self.train(False)

    # ------------------------------------------------------------------ construction / checkpoints
    @classmethod
    def from_policy(cls, config: IqlCriticConfig, policy: BboxDiffusionPolicy) -> IqlCriticModel:
        """Warm start from a policy instance: its inference (EMA) model's observation modules."""
        model = policy.ema_model if policy.ema_model is not None else policy.model
        return cls(config, PolicyObservationEncoder(model))

    @classmethod
    def from_policy_checkpoint(cls, config: IqlCriticConfig, path: str | Path) -> IqlCriticModel:
        """Warm start from a saved ``bbox_diffusion`` checkpoint."""
        return cls.from_policy(config, load_policy(path))

    def _save_pretrained(self, save_directory: Path) -> None:
        save_directory = Path(save_directory)
        (save_directory / CONFIG_NAME).write_text(json.dumps(draccus.encode(self.config), indent=4))
        save_model(self, str(save_directory / SAFETENSORS_SINGLE_FILE))
        (save_directory / ENCODER_DIR).mkdir(parents=True, exist_ok=True)
        self.encoder.config._save_pretrained(save_directory / ENCODER_DIR)

    @classmethod
    def from_pretrained(cls, path: str | Path, device: str = "cpu") -> IqlCriticModel:
        """Load a folder written by ``save_pretrained`` (eval mode)."""
        path = Path(path)
        for name in (CONFIG_NAME, SAFETENSORS_SINGLE_FILE, f"{ENCODER_DIR}/{CONFIG_NAME}"):
            if not (path / name).is_file():
                raise FileNotFoundError(f"{path} is not an IQL critic checkpoint: {name} is missing")
        config = draccus.decode(IqlCriticConfig, json.loads((path / CONFIG_NAME).read_text()))
        policy_config = PreTrainedConfig.from_pretrained(path / ENCODER_DIR)
        if not isinstance(policy_config, BboxDiffusionConfig):
            raise ValueError(
                f"{path / ENCODER_DIR} holds a {policy_config.type!r} config, not a bbox_diffusion one"
            )
        model = cls(config, PolicyObservationEncoder.from_policy_config(policy_config))
        load_model(model, str(path / SAFETENSORS_SINGLE_FILE), strict=True, device=device)
        return model.to(device).eval()

    # ------------------------------------------------------------------ modes and parameters
    def train(self, mode: bool = True) -> IqlCriticModel:
        """Like ``nn.Module.train``, but a frozen encoder stays in eval mode (centre crop, no jitter):
        its features are then exactly the policy's at inference."""
        super().train(mode)
        if self.config.freeze_encoder:
            self.encoder.eval()
        return self

    def get_optim_params(self, lr: float, encoder_lr_scale: float) -> list[dict]:
        """Parameter groups: the critic at ``lr``; the encoder at ``lr * encoder_lr_scale`` unless frozen."""
        groups = [{"params": [p for p in self.critic.parameters() if p.requires_grad], "lr": lr}]
        if not self.config.freeze_encoder:
            groups.append({"params": list(self.encoder.parameters()), "lr": lr * encoder_lr_scale})
        return groups

    # ------------------------------------------------------------------ inference
    def encode(self, batch: dict[str, Tensor]) -> Tensor:
        """State features ``(B, state_dim)`` of observations ``(B, n_obs, ...)`` (the policy's features)."""
        with torch.set_grad_enabled(torch.is_grad_enabled() and not self.config.freeze_encoder):
            return self.encoder(batch)

    def flat_actions(self, relative_chunk: Tensor) -> Tensor:
        """Relative chunk ``(..., horizon, 10)`` -> scaled, flattened ``(..., horizon * 10)``."""
        if relative_chunk.shape[-2:] != (self.horizon, ACTION_DIM):
            raise ValueError(
                f"action chunk must have shape (..., {self.horizon}, {ACTION_DIM}) (relative pose10), "
                f"got {tuple(relative_chunk.shape)}"
            )
        return self.action_scaler(relative_chunk.float()).flatten(-2)

    def v(self, state: Tensor) -> Tensor:
        """``V(s)`` (B,) from state features."""
        return self.critic.v(state)

    def q(self, state: Tensor, relative_chunk: Tensor) -> Tensor:
        """``min(Q1, Q2)(s, a)`` (B,) from state features and relative chunks (B, horizon, 10)."""
        return self.critic.q_min(state, self.flat_actions(relative_chunk))

    def iql_batch(
        self,
        state: Tensor,
        relative_chunk: Tensor,
        reward: Tensor,
        done: Tensor,
        discount: Tensor,
        next_state: Tensor,
    ) -> IqlBatch:
        """Assemble an ``IqlBatch`` in the critic's input space."""
        return IqlBatch(
            state=state.float(),
            action=self.flat_actions(relative_chunk),
            reward=reward.float(),
            done=done.bool(),
            discount=discount.float(),
            next_state=next_state.float(),
        )
