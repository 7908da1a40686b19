"""bbox_diffusion through LeRobot's own CLIs: lerobot-train on a dataset the test records, then
lerobot-eval on the saved checkpoint, both in subprocesses."""

import json
import subprocess
import sys
from dataclasses import MISSING
from pathlib import Path

import pytest
from helpers_cli import TINY_BBOX_DIFFUSION, cli_env

BIN = Path(sys.executable).parent
TINY = [
    *TINY_BBOX_DIFFUSION,
    "--policy.mask_centroid=true",  # the CPU recipe's option, so the CLI path covers it
    "--policy.use_amp=true",  # the recipe trains under bf16 autocast; lerobot-eval then evaluates under it
]


_env = cli_env


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from helpers_data import make_expert_dataset

    root = tmp_path_factory.mktemp("bd") / "data"
    make_expert_dataset(root, seeds=[0, 1], repo_id="test/bd")
    return root


def train_two_steps(policy_args: list[str], dataset: Path, out: Path) -> Path:
    """``lerobot-train`` for 2 steps of batch 2 on the test dataset; its last checkpoint."""
    cmd = [
        BIN / "lerobot-train",
        *policy_args,
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
    return out / "checkpoints" / "last" / "pretrained_model"


@pytest.fixture(scope="module")
def checkpoint(dataset, tmp_path_factory):
    path = train_two_steps(TINY, dataset, tmp_path_factory.mktemp("bd_train") / "train")
    assert (path / "model.safetensors").exists() and (path / "policy_postprocessor.json").exists()
    return path


def test_bad_options_name_the_field_and_the_allowed_values():
    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig

    with pytest.raises(ValueError, match="bbox_mode='box' is not one of mask, lowdim, none"):
        BboxDiffusionConfig(bbox_mode="box")
    with pytest.raises(ValueError, match="pooling='avg' must be 'default' or 'spatial_softmax'"):
        BboxDiffusionConfig(pooling="avg")


def test_defaults_are_what_the_policy_uses():
    """The dataclass (and so --help) shows the real defaults: the CPU recipe's for bbox_diffusion, the
    paper's for bbox_diffusion_paper; only the mask centroid is switched off for the no-mask ablations."""
    from lerobot.configs import PreTrainedConfig

    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import (
        BboxDiffusionConfig,
        BboxDiffusionPaperConfig,
    )

    cpu = BboxDiffusionConfig()
    assert (cpu.backbone, cpu.image_size, cpu.n_action_steps, cpu.mask_centroid) == ("resnet18", 96, 12, True)
    ours = set(BboxDiffusionConfig.__dataclass_fields__) - set(PreTrainedConfig.__dataclass_fields__)
    fields = {n: f for n, f in BboxDiffusionConfig.__dataclass_fields__.items() if n in ours}
    assert len(fields) > 30
    assert all(getattr(cpu, n) == f.default for n, f in fields.items() if f.default is not MISSING)
    paper = BboxDiffusionPaperConfig()
    assert (paper.backbone, paper.image_size, paper.n_action_steps, paper.pretrained_backbone) == (
        "vit_large_patch14_clip_224.openai",
        224,
        8,
        True,
    )
    assert PreTrainedConfig.get_choice_class("bbox_diffusion_paper") is BboxDiffusionPaperConfig
    for mode in ("none", "lowdim"):
        assert BboxDiffusionConfig(bbox_mode=mode).mask_centroid is False
    explicit = BboxDiffusionConfig(mask_centroid=False, n_action_steps=4)
    assert (explicit.n_action_steps, explicit.mask_centroid) == (4, False)


@pytest.mark.slow
def test_train_saves_a_loadable_checkpoint_with_its_processors(checkpoint):
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["type"] == "bbox_diffusion" and config["bbox_mode"] == "mask"
    pre = json.loads((checkpoint / "policy_preprocessor.json").read_text())
    post = json.loads((checkpoint / "policy_postprocessor.json").read_text())
    # LeRobot's own steps only: the policy itself returns absolute poses (no pose state to pair).
    assert [s["registry_name"] for s in post["steps"]] == ["unnormalizer_processor", "device_processor"]
    assert "normalizer_processor" in [s["registry_name"] for s in pre["steps"]]


@pytest.mark.slow
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


@pytest.mark.slow
def test_checkpoint_actions_are_absolute_poses_composed_with_the_observed_pose(checkpoint):
    """A loaded checkpoint returns T_observed @ T_rel from select_action itself (no hidden state in the
    processors): the postprocessor leaves it unchanged and it equals the model's relative sample
    composed with the observed pose."""
    import torch

    from lerobot_bboxpick.eval.rollout import PolicyRunner
    from lerobot_bboxpick.geometry import absolute_pose10_torch
    from lerobot_bboxpick.sim.env import LegoPickEnv

    runner = PolicyRunner.from_pretrained(checkpoint)
    env = LegoPickEnv(setting="grid_id")
    obs, info = env.reset(seed=3)
    env.close()
    runner.reset()
    batch = runner.observation_batch(obs, info["task"])
    n_obs = runner.policy.config.n_obs_steps
    stacked = {
        k: v[:, None].repeat_interleave(n_obs, dim=1) for k, v in batch.items() if k in runner.policy._queues
    }
    torch.manual_seed(0)
    relative = runner.policy._inference_model().sample(stacked)
    torch.manual_seed(0)
    action = runner.policy.select_action(batch)
    assert torch.equal(runner.postprocessor(action), action)
    state = torch.as_tensor(obs["agent_pos"])[None]
    expected = absolute_pose10_torch(relative[:, :1], state)[:, 0]
    assert (action - expected).abs().max() < 1e-5
    assert (action - relative[:, 0]).abs().max() > 0.1  # composed: the TCP is ~0.5 m from the origin


@pytest.mark.slow
def test_train_fine_tunes_a_checkpoint_with_advantage_weights_an_anchor_and_relabels(
    checkpoint, dataset, tmp_path
):
    """``bboxpick-parl-relabel``'s pass over the dataset, then ``lerobot-train --policy.path=<checkpoint>``
    with ``--policy.awr_critic_path``, ``--policy.anchor_policy_path`` and ``--policy.parl_cache_path``:
    the critic-based fine-tuning objectives run in LeRobot's own loop; the saved checkpoint holds the
    policy's weights only."""
    from safetensors.torch import load_file

    from lerobot_bboxpick.rl.configuration_iql_critic import IqlCriticConfig
    from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel
    from lerobot_bboxpick.rl.parl_relabel import ParlRelabelConfig, relabel_dataset

    critic = tmp_path / "critic"
    small = IqlCriticConfig(state_embed_dim=32, action_embed_dim=16, hidden_dim=32)
    IqlCriticModel.from_policy_checkpoint(small, checkpoint).save_pretrained(critic)
    cache = tmp_path / "relabels.safetensors"
    report = relabel_dataset(
        ParlRelabelConfig(
            repo_id="test/bd", root=dataset, policy_path=checkpoint, critic_path=critic, out=cache,
            frame_stride=8, samples=2, ascent_steps=2, num_inference_steps=2, progress=False,
        )
    )  # fmt: skip
    frames = load_file(cache)["index"]
    episode_lengths = [len(ep) for ep in _episode_rows(dataset)]
    assert len(frames) == report["frames"] == sum((n + 7) // 8 for n in episode_lengths)
    assert 0.0 <= report["valid_fraction"] <= 1.0 and report["mean_chosen_q"] >= report["mean_dataset_q"]
    assert report["config"]["num_inference_steps"] == "2"
    fine_tuning = [
        f"--policy.path={checkpoint}",
        "--policy.use_amp=false",
        f"--policy.awr_critic_path={critic}",
        f"--policy.anchor_policy_path={checkpoint}",
        f"--policy.parl_cache_path={cache}",
    ]
    tuned = train_two_steps(fine_tuning, dataset, tmp_path / "awr")
    config = json.loads((tuned / "config.json").read_text())
    assert (config["awr_critic_path"], config["parl_cache_path"]) == (str(critic), str(cache))
    before, after = load_file(checkpoint / "model.safetensors"), load_file(tuned / "model.safetensors")
    assert before.keys() == after.keys()  # neither the critic nor the reference is saved with it
    moved = max(
        (after[k].float() - before[k].float()).abs().max().item() for k in before if k.startswith("model.")
    )
    assert moved > 0  # it trained from the checkpoint's weights


@pytest.mark.slow
def test_train_distils_a_checkpoint_into_half_the_steps_without_saving_the_teacher(
    checkpoint, dataset, tmp_path
):
    """``lerobot-train --policy.path=<teacher> --policy.distill_teacher_path=<teacher>
    --policy.num_inference_steps=4`` (the teacher stepping at 8): LeRobot's own loop trains the student
    from the teacher's weights and saves the policy's weights only; a step count whose steps the
    teacher's cannot pair (7 of 50) is refused by name."""
    from safetensors.torch import load_file

    args = [
        f"--policy.path={checkpoint}",
        "--policy.use_amp=false",
        f"--policy.distill_teacher_path={checkpoint}",
    ]
    student = train_two_steps([*args, "--policy.num_inference_steps=4"], dataset, tmp_path / "student")
    config = json.loads((student / "config.json").read_text())
    assert (config["distill_teacher_path"], config["num_inference_steps"]) == (str(checkpoint), 4)
    before, after = load_file(checkpoint / "model.safetensors"), load_file(student / "model.safetensors")
    assert before.keys() == after.keys()  # the teacher is not saved with the student
    assert max((after[k].float() - before[k].float()).abs().max().item() for k in before) > 0
    refused = subprocess.run(
        [BIN / "lerobot-train", *args, "--policy.num_inference_steps=7", "--dataset.repo_id=test/bd",
         f"--dataset.root={dataset}", f"--output_dir={tmp_path / 'refused'}", "--steps=1", "--batch_size=2",
         "--num_workers=0", "--wandb.enable=false"],
        capture_output=True, text=True, timeout=600, env=_env(),
    )  # fmt: skip
    assert refused.returncode != 0 and "num_inference_steps=7" in refused.stderr


def _episode_rows(root: Path) -> list[list[int]]:
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    hf = LeRobotDataset("test/bd", root=root).hf_dataset.select_columns(["episode_index"])
    episodes = np.asarray(hf.with_format("numpy")[:]["episode_index"]).reshape(-1)
    return [np.flatnonzero(episodes == ep).tolist() for ep in np.unique(episodes)]


@pytest.mark.slow
def test_train_saves_the_target_view_and_the_loaded_policy_samples_with_it(dataset, tmp_path):
    """``--policy.target_crop_size`` through lerobot-train: the checkpoint holds the view's trained
    encoder, the loaded policy uses those weights, and its view sees pixels inside the target's window
    only."""
    import torch
    from safetensors.torch import load_file

    from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy

    view_args = ["--policy.n_obs_steps=1", "--policy.target_crop_size=32"]
    path = train_two_steps([*TINY, *view_args], dataset, tmp_path / "train")
    saved = load_file(path / "model.safetensors")
    view_keys = [k for k in saved if k.startswith("ema_model.target_view.encoder.")]
    assert len(view_keys) > 10
    policy = BboxDiffusionPolicy.from_pretrained(path).eval()
    assert policy.config.target_crop_size == 32
    loaded = policy.state_dict()
    assert all(torch.equal(loaded[k], saved[k]) for k in view_keys)
    model = policy._inference_model()
    g = torch.Generator().manual_seed(0)
    images = torch.rand(1, 1, 3, 224, 224, generator=g)
    boxes = torch.tensor([0.45, 0.45, 0.5, 0.5]).expand(1, 1, 4)  # window: 33.6 px around (106, 106)
    near, far = images.clone(), images.clone()
    near[..., 100:112, 100:112] = 1.0
    far[..., 180:200, 180:200] = 1.0
    with torch.no_grad():
        ref = model.target_view(images, boxes)
        assert (model.target_view(near, boxes) - ref).abs().max() > 1e-4
        assert torch.equal(model.target_view(far, boxes), ref)
    state = torch.tensor([[0.5, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.08]])
    observation = {"observation.state": state[:, None], "observation.bbox": boxes}
    chunk = policy.predict_action_chunk({"observation.images.wrist": images, **observation})
    assert torch.isfinite(chunk).all() and chunk.shape == (1, policy.config.horizon, 10)
