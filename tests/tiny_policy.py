"""A tiny, randomly initialised stock LeRobot policy for the ``lego_pick`` env, saved like a checkpoint.

``save_tiny_policy(out_dir)`` writes what ``lerobot-eval --policy.path=out_dir`` loads from a trained
checkpoint's ``pretrained_model/``: ``config.json`` + ``model.safetensors`` (``policy.save_pretrained``)
and ``policy_preprocessor.json`` / ``policy_postprocessor.json`` + the normaliser's
``.safetensors`` (the pipelines of ``make_pre_post_processors`` saved with ``save_pretrained``).

Policy choice: ``diffusion``. Of the stock policies only ACT and Diffusion are small CNN models
(the rest are VLAs, or TDMPC/VQ-BeT with their own feature restrictions). Both are built around a
torchvision ResNet (``vision_backbone`` must start with ``resnet``; resnet18 is the smallest). ACT runs
it on the full 224x224 frame; Diffusion can ``resize_shape`` the frame first (96x96 here: ~5x fewer
FLOPs than 224x224, and unlike a crop it still sees the whole wrist view), its U-Net shrinks with
``down_dims`` and the denoising loop with ``num_inference_steps``. It is also the family of the
project's own policy. No download: ``pretrained_backbone_weights=None`` (random init, and
``use_group_norm=True`` replaces BatchNorm as LeRobot does for from-scratch backbones).

Caveat: stock ACT/Diffusion only read ``observation.state``, ``observation.environment_state`` and the
images. ``observation.bbox`` is a declared input feature here (normalised by the preprocessor with
real stats) but the stock diffusion model does not feed it to the network.

Normalisation stats are computed from real observations of the env, in the representation the
preprocessor sees during ``lerobot-eval`` (``preprocess_observation``: images CHW float in [0, 1]),
with LeRobot's dataset statistics function ``get_feature_stats``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from lerobot.configs import FeatureType
from lerobot.datasets.compute_stats import get_feature_stats
from lerobot.envs.utils import env_to_policy_features, preprocess_observation
from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
from lerobot.policies.factory import make_pre_post_processors
from lerobot.utils.constants import ACTION

from lerobot_bboxpick.sim.env_config import LegoPickEnvConfig

STATS_SEEDS = (0, 1)
STATS_STEPS = 4
# Half-width (m) of the box of TCP positions the stats episodes command around the start pose; the
# policy's unnormalised actions stay inside the observed action range, so an untrained policy only
# moves a few cm.
ACTION_POSITION_JITTER = 0.02
ACTION_WIDTH_RANGE = (0.06, 0.08)


def tiny_diffusion_config(env_cfg: LegoPickEnvConfig) -> DiffusionConfig:
    """A small DiffusionConfig whose features are derived from ``env_cfg``."""
    features = env_to_policy_features(env_cfg)
    return DiffusionConfig(
        input_features={k: ft for k, ft in features.items() if ft.type is not FeatureType.ACTION},
        output_features={k: ft for k, ft in features.items() if ft.type is FeatureType.ACTION},
        device="cpu",
        n_obs_steps=2,
        horizon=16,  # multiple of 2 ** len(down_dims)
        n_action_steps=8,  # the model runs once every 8 env steps
        resize_shape=(96, 96),
        vision_backbone="resnet18",
        pretrained_backbone_weights=None,
        use_group_norm=True,
        spatial_softmax_num_keypoints=16,
        down_dims=(32, 64),
        kernel_size=3,
        n_groups=8,
        diffusion_step_embed_dim=32,
        noise_scheduler_type="DDIM",
        num_train_timesteps=100,
        num_inference_steps=2,
    )


def collect_env_stats(
    env_cfg: LegoPickEnvConfig, seeds: tuple[int, ...] = STATS_SEEDS, n_steps: int = STATS_STEPS
) -> dict[str, dict[str, np.ndarray]]:
    """Stats of real ``lego_pick`` frames: reset each seed, step ``n_steps`` near the start pose.

    Actions are the start pose with a seeded position jitter of +-``ACTION_POSITION_JITTER`` and a
    gripper width in ``ACTION_WIDTH_RANGE`` (the orientation stays the start orientation), so the
    action stats are those of the actions actually sent, not a constant.
    """
    from lerobot_bboxpick.sim.env import LegoPickEnv, start_pose10

    frames: dict[str, list[np.ndarray]] = {}
    actions: list[np.ndarray] = []

    def record(raw_obs: dict) -> None:
        for key, value in preprocess_observation(raw_obs).items():
            frames.setdefault(key, []).append(value.numpy())

    env = LegoPickEnv(**env_cfg.gym_kwargs)
    try:
        for seed in seeds:
            rng = np.random.default_rng(seed)
            obs, _ = env.reset(seed=seed)
            record(obs)
            for _ in range(n_steps):
                action = start_pose10(width=rng.uniform(*ACTION_WIDTH_RANGE))
                action[:3] += rng.uniform(-ACTION_POSITION_JITTER, ACTION_POSITION_JITTER, size=3)
                obs, *_ = env.step(action)
                actions.append(action.astype(np.float32))
                record(obs)
    finally:
        env.close()

    stats: dict[str, dict[str, np.ndarray]] = {}
    for key, batches in frames.items():
        array = np.concatenate(batches)  # (N, C, H, W) images in [0, 1]; (N, D) vectors
        if array.ndim == 4:
            s = get_feature_stats(array, axis=(0, 2, 3), keepdims=True)
            stats[key] = {k: v if k == "count" else np.squeeze(v, axis=0) for k, v in s.items()}  # (3, 1, 1)
        else:
            stats[key] = get_feature_stats(array, axis=0, keepdims=False)
    stats[ACTION] = get_feature_stats(np.stack(actions), axis=0, keepdims=False)
    return stats


def save_tiny_policy(out_dir: Path, seed: int = 0) -> Path:
    """Build the tiny random diffusion policy + its processors and save them to ``out_dir``."""
    out_dir = Path(out_dir)
    env_cfg = LegoPickEnvConfig()
    config = tiny_diffusion_config(env_cfg)
    expected = set(config.input_features) | set(config.output_features)
    stats = collect_env_stats(env_cfg)
    if set(stats) != expected:
        raise RuntimeError(f"stats keys {sorted(stats)} != policy feature keys {sorted(expected)}")

    torch.manual_seed(seed)
    policy = DiffusionPolicy(config)
    preprocessor, postprocessor = make_pre_post_processors(config, dataset_stats=stats)

    out_dir.mkdir(parents=True, exist_ok=True)
    policy.save_pretrained(out_dir)
    preprocessor.save_pretrained(out_dir)
    postprocessor.save_pretrained(out_dir)
    return out_dir
