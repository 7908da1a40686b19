"""bbox_diffusion through LeRobot's own CLIs: lerobot-train on a dataset the test records, then
lerobot-eval on the saved checkpoint, both in subprocesses."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent
TINY = [  # a policy small enough to train a few steps in seconds on a CPU
    "--policy.type=bbox_diffusion",
    "--policy.device=cpu",
    "--policy.backbone=resnet10t",
    "--policy.image_size=64",
    "--policy.down_dims=[32,64]",
    "--policy.diffusion_step_embed_dim=32",
    "--policy.num_inference_steps=4",
    "--policy.mask_centroid=true",  # the CPU recipe's option, so the CLI path covers it
    "--policy.use_amp=true",  # the recipe trains under bf16 autocast; lerobot-eval then evaluates under it
]


def _env() -> dict:
    return {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "2"}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from helpers_data import make_expert_dataset

    root = tmp_path_factory.mktemp("bd") / "data"
    make_expert_dataset(root, seeds=[0, 1], repo_id="test/bd")
    return root


@pytest.fixture(scope="module")
def checkpoint(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("bd_train") / "train"
    cmd = [
        BIN / "lerobot-train",
        *TINY,
        "--dataset.repo_id=test/bd",
        f"--dataset.root={dataset}",
        f"--output_dir={out}",
        "--steps=2",
        "--batch_size=2",
        "--num_workers=0",
        "--save_freq=2",
        "--log_freq=1",
        "--wandb.enable=false",
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=_env())
    assert result.returncode == 0, result.stderr[-4000:]
    path = out / "checkpoints" / "last" / "pretrained_model"
    assert (path / "model.safetensors").exists() and (path / "policy_postprocessor.json").exists()
    return path


def test_bad_options_name_the_field_and_the_allowed_values():
    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig

    with pytest.raises(ValueError, match="mask_centroid=true needs bbox_mode='mask'"):
        BboxDiffusionConfig(bbox_mode="none", mask_centroid=True)
    with pytest.raises(ValueError, match="bbox_mode='box' is not one of mask, lowdim, none"):
        BboxDiffusionConfig(bbox_mode="box")


def test_presets_fill_only_what_the_user_left_unset():
    """The cpu preset brings the recipe's 12 executed steps and the mask centroid; the ablation modes
    never get the centroid from a preset, and an explicit value always wins."""
    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig

    cpu = BboxDiffusionConfig()
    assert (cpu.n_action_steps, cpu.mask_centroid) == (12, True)
    paper = BboxDiffusionConfig(preset="paper")
    assert (paper.n_action_steps, paper.mask_centroid) == (8, False)
    for mode in ("none", "lowdim"):
        assert BboxDiffusionConfig(bbox_mode=mode).mask_centroid is False
    explicit = BboxDiffusionConfig(mask_centroid=False, n_action_steps=4)
    assert (explicit.n_action_steps, explicit.mask_centroid) == (4, False)


def test_train_saves_a_loadable_checkpoint_with_its_processors(checkpoint):
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["type"] == "bbox_diffusion" and config["bbox_mode"] == "mask"
    pre = (checkpoint / "policy_preprocessor.json").read_text()
    post = (checkpoint / "policy_postprocessor.json").read_text()
    assert "bbox_diffusion_relative_pose" in pre and "bbox_diffusion_absolute_pose" in post
    # The relative/absolute pair is linked by the same id in both files.
    pair_pre = json.loads(pre)["steps"][-1]["config"]["pair_id"]
    assert pair_pre in post


def test_eval_runs_the_checkpoint_in_lego_pick(checkpoint, tmp_path):
    out = tmp_path / "eval"
    cmd = [
        BIN / "lerobot-eval",
        f"--policy.path={checkpoint}",
        "--policy.device=cpu",
        "--env.type=lego_pick",
        "--env.setting=grid_id",
        "--env.episode_length=12",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        "--seed=10000",
        f"--output_dir={out}",
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=_env())
    assert result.returncode == 0, result.stderr[-4000:]
    info = json.loads((out / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1 and info["overall"]["pc_success"] == 0.0


def test_checkpoint_actions_are_made_absolute_from_the_observed_pose(checkpoint):
    """The loaded postprocessor turns the policy's relative action into T_observed @ T_rel: the
    relative/absolute pair is wired after loading (not returning raw relative poses)."""
    import torch

    from lerobot_bboxpick.eval.rollout import PolicyRunner
    from lerobot_bboxpick.policies.bbox_diffusion.processor_bbox_diffusion import absolute_pose10_torch
    from lerobot_bboxpick.sim.env import LegoPickEnv

    runner = PolicyRunner.from_pretrained(checkpoint)
    env = LegoPickEnv(setting="grid_id")
    obs, info = env.reset(seed=3)
    env.close()
    runner.reset()
    batch = runner.observation_batch(obs, info["task"])
    torch.manual_seed(0)
    relative = runner.policy.select_action(batch)
    absolute = runner.postprocessor(relative)
    state = torch.as_tensor(obs["agent_pos"])[None]
    expected = absolute_pose10_torch(relative[:, None], state)[:, 0]
    assert (absolute - expected).abs().max() < 1e-5
    assert (absolute - relative).abs().max() > 0.1  # it did change: the TCP is ~0.5 m from the origin
