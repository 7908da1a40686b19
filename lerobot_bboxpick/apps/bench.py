"""Benchmarks (figures, not pass/fail tests): env steps per second beside the bare render rate.

Both are measured in the same run, per setting, so the ratio says how much the env adds on top of
rendering the wrist view (physics substeps, IK, fisheye warp, bbox projection, outcome tracking).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_bboxpick.precision import choose_precision
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.expert import ScriptedExpert
from lerobot_bboxpick.sim.layouts import SETTINGS

log = logging.getLogger(__name__)


def bench_env(setting: str, steps: int = 120, renders: int = 120, seed: int = 0) -> dict[str, float]:
    """Env steps/s (scripted-expert actions, so contacts and grasps happen) and bare render fps."""
    env = LegoPickEnv(setting=setting, terminate_on_lift=False)
    env.reset(seed=seed)
    expert = ScriptedExpert(np.random.default_rng(seed))
    expert.reset(env)
    actions = [expert.act() for _ in range(steps)]
    env.camera.render_pinhole(env.data)  # warm-up: first frame compiles shaders
    t0 = time.perf_counter()
    for _ in range(renders):
        env.camera.render_pinhole(env.data)
    render_fps = renders / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for a in actions:
        env.step(a)
    steps_per_s = steps / (time.perf_counter() - t0)
    env.close()
    return {
        "setting": setting,
        "env_steps_per_s": steps_per_s,
        "bare_render_fps": render_fps,
        "ratio": steps_per_s / render_fps,
    }


def bench_table(settings: tuple[str, ...] = SETTINGS, steps: int = 120) -> str:
    """Markdown table of ``bench_env`` for each setting."""
    lines = [
        "| setting | env steps/s | bare render fps (512 px wide view) | env / render |",
        "|---|---|---|---|",
    ]
    for s in settings:
        r = bench_env(s, steps=steps)
        lines.append(f"| {s} | {r['env_steps_per_s']:.1f} | {r['bare_render_fps']:.1f} | {r['ratio']:.2f} |")
    return "\n".join(lines)


def _policy_features(image_size: int = 224) -> tuple[dict, dict]:
    from lerobot.configs import FeatureType, PolicyFeature

    inputs = {
        "observation.images.wrist": PolicyFeature(FeatureType.VISUAL, (3, image_size, image_size)),
        "observation.state": PolicyFeature(FeatureType.STATE, (10,)),
        "observation.bbox": PolicyFeature(FeatureType.STATE, (4,)),
    }
    return inputs, {"action": PolicyFeature(FeatureType.ACTION, (10,))}


def random_training_batch(batch_size: int) -> dict:
    """A training batch of random tensors in the bench's layout: two observed 224 px frames, states and
    boxes, a 16-step action chunk (drawn from torch's global generator, in this order)."""
    import torch

    return {
        "observation.images.wrist": torch.rand(batch_size, 2, 3, 224, 224),
        "observation.state": torch.rand(batch_size, 2, 10),
        "observation.bbox": torch.rand(batch_size, 2, 4),
        "action": torch.rand(batch_size, 16, 10),
        "action_is_pad": torch.zeros(batch_size, 16, dtype=torch.bool),
    }


def _interleaved_training_rates(policies: dict[str, Any], batch: dict, steps: int = 8) -> dict[str, float]:
    """Training samples/s of each policy on random tensors, from the median of ``steps`` timed steps taken
    in turn (one step of each policy, then the next round).

    Taking the steps in turn means a host whose speed drifts during the run (another tenant, a clock change)
    moves every policy's figure alike, so their ratio holds; timing one policy's steps after the other's let
    the drift between the two blocks into the ratio. The median keeps a single slow step (allocator growth,
    a process waking up) out of it.
    """
    optimisers = {name: _preset_optimizer(policy) for name, policy in policies.items()}
    times: dict[str, list[float]] = {name: [] for name in policies}
    for round_ in range(steps + 1):  # round 0 warms up (allocations, AdamW state)
        for name, policy in policies.items():
            policy.train()
            t0 = time.perf_counter()
            loss, _ = policy.forward(batch)
            loss.backward()
            optimisers[name].step()
            optimisers[name].zero_grad()
            if hasattr(policy, "update"):
                policy.update()
            if round_:
                times[name].append(time.perf_counter() - t0)
    return {name: len(batch["action"]) / float(np.median(ts)) for name, ts in times.items()}


CHUNKS_TIMED = 5  # chunks per inference median (after one warm-up chunk)


def _chunk_ms(policy: Any, obs: dict, chunks: int = CHUNKS_TIMED) -> float:
    """Median ms for one full action chunk (encoder + DDIM) from an empty action queue."""
    import torch

    policy.eval()
    times = []
    with torch.no_grad():
        for _ in range(chunks + 1):  # the first chunk warms up
            policy.reset()
            t0 = time.perf_counter()
            policy.select_action(dict(obs))
            times.append(time.perf_counter() - t0)
    return 1000 * float(np.median(times[1:]))


def bench_policies(batch_size: int = 32, image_size: int = 96, training_steps: int = 8) -> str:
    """Markdown table: bbox_diffusion CPU preset beside LeRobot's stock diffusion at the same input size.

    Both use 2 observation steps, a 16-step horizon and 16 DDIM steps per chunk; images arrive at
    224 px and are resized to ``image_size`` by each policy. Training is timed with the two policies'
    steps in turn (``training_steps`` each). Also the paper preset's encoder (CLIP ViT-L/14 at 224,
    random init) parameter count and CPU latency.
    """
    import timm
    import torch
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy

    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
    from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy

    torch.manual_seed(0)
    inputs, outputs = _policy_features()
    batch = random_training_batch(batch_size)
    obs = {k: v[:1, -1] for k, v in batch.items() if k.startswith("observation")}
    ours = BboxDiffusionPolicy(
        BboxDiffusionConfig(
            device="cpu", input_features=inputs, output_features=outputs, image_size=image_size
        )
    )
    stock_cfg = DiffusionConfig(
        device="cpu",
        input_features=inputs,
        output_features=outputs,
        horizon=16,
        n_action_steps=8,
        resize_shape=(image_size, image_size),
        pretrained_backbone_weights=None,
        use_group_norm=True,
        noise_scheduler_type="DDIM",
        num_inference_steps=16,
    )
    from lerobot.configs import NormalizationMode

    stock_cfg.normalization_mapping = {k: NormalizationMode.IDENTITY for k in ("VISUAL", "STATE", "ACTION")}
    stock = DiffusionPolicy(stock_cfg)
    ours_name, stock_name = "bbox_diffusion (cpu preset)", "LeRobot diffusion (stock)"
    # LeRobot's ``--policy.use_amp=true`` trains under bf16 autocast on the CPU (Accelerate). Where the
    # CPU runs bf16 natively both policies are timed both ways; where it would be emulated (~70x slower
    # matmuls) only float32 is, or the bench would not finish (lerobot_bboxpick.precision).
    choice = choose_precision()
    precisions = {"float32": False, "bf16 autocast": True} if choice.use_amp else {"float32": False}
    rows = {}
    policies = {ours_name: ours, stock_name: stock}
    for precision, amp in precisions.items():
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=amp):
            rates = _interleaved_training_rates(policies, batch, steps=training_steps)
            for name, policy in policies.items():
                n = sum(p.numel() for p in policy.parameters() if p.requires_grad) / 1e6
                rows[(name, precision)] = (rates[name], _chunk_ms(policy, obs), n)
    lines = [
        f"Precision: {choice.reason}.\n",
        f"Training: the median of {training_steps} steps per policy on random tensors, the two policies' "
        f"steps taken in turn; inference: the median of {CHUNKS_TIMED} chunks.\n",
        f"| policy ({image_size} px input, batch {batch_size}) | precision | train samples/s | ms per "
        "16-step DDIM chunk | trainable params (M) |",
        "|---|---|---|---|---|",
    ]
    for (name, precision), (sps, ms, n) in rows.items():
        lines.append(f"| {name} | {precision} | {sps:.1f} | {ms:.0f} | {n:.1f} |")
    for precision in precisions:
        (o_sps, o_ms, _), (s_sps, s_ms, _) = rows[(ours_name, precision)], rows[(stock_name, precision)]
        lines.append(f"| ratio ours / stock | {precision} | {o_sps / s_sps:.2f}x | {o_ms / s_ms:.2f}x | |")
    best = max(rows[(ours_name, p)][0] for p in precisions)
    stock_fp32 = rows[(stock_name, "float32")][0]
    lines.append(f"| ratio ours (faster precision) / stock float32 | | {best / stock_fp32:.2f}x | | |")
    vit = timm.create_model("vit_large_patch14_clip_224", pretrained=False, num_classes=0).eval()
    x = torch.rand(2, 3, 224, 224)
    with torch.no_grad():
        vit(x)
        t0 = time.perf_counter()
        vit(x)
    vit_ms = 1000 * (time.perf_counter() - t0)
    n_vit = sum(p.numel() for p in vit.parameters()) / 1e6
    lines.append(
        f"\nPaper type's encoder (CLIP ViT-L/14 @ 224): {n_vit:.0f} M parameters, "
        f"{vit_ms:.0f} ms to encode the 2 observation frames on this CPU."
    )
    return "\n".join(lines)


# Training-speed levers: bbox_diffusion config overrides timed beside the preset in one run.
TRAINING_LEVERS: dict[str, dict[str, Any]] = {
    "preset (96 px, 2 observed frames)": {},
    "80 px": {"image_size": 80},
    "64 px": {"image_size": 64},
    "1 observed frame": {"n_obs_steps": 1},
    "64 px, 1 frame (fast encoder)": {"image_size": 64, "n_obs_steps": 1},
    "fast encoder + 48 px target view": {"image_size": 64, "n_obs_steps": 1, "target_crop_size": 48},
    "half-width UNet": {"down_dims": (32, 64, 128)},
}


def _preset_optimizer(policy: Any) -> Any:
    """The optimizer lerobot-train builds for ``policy`` (its config's preset: fused AdamW for ours,
    torch's default AdamW for stock diffusion), so a timed step is the step training runs."""
    return policy.config.get_optimizer_preset().build(policy.get_optim_params())


def _lever_policy(overrides: dict[str, Any]) -> Any:
    """A randomly initialised (seed 0) bbox_diffusion policy with the preset's config and ``overrides``."""
    import torch

    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
    from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy

    torch.manual_seed(0)
    inputs, outputs = _policy_features()
    config = BboxDiffusionConfig(device="cpu", input_features=inputs, output_features=outputs, **overrides)
    return BboxDiffusionPolicy(config)


def bench_training_levers(batch_size: int = 32, steps: int = 6) -> str:
    """Markdown table: where a training step's time goes, per ``TRAINING_LEVERS`` entry (float32, random
    tensors, no data loading): the whole step, the observation encoder's forward + backward, and the
    paired augmentation, with samples/s and its ratio to the preset; plus LeRobotDataset's own sample rate
    (one process, a freshly collected 2-episode dataset), the loader's ceiling."""
    import tempfile

    import torch

    rows = {}
    for name, overrides in TRAINING_LEVERS.items():
        policy = _lever_policy(overrides).train()
        config = policy.config
        t = config.n_obs_steps
        batch = {
            "observation.images.wrist": torch.rand(batch_size, t, 3, 224, 224),
            "observation.state": torch.rand(batch_size, t, 10),
            "observation.bbox": torch.tensor([0.4, 0.4, 0.5, 0.5]).expand(batch_size, t, 4),
            "action": torch.rand(batch_size, 16, 10),
        }
        opt = _preset_optimizer(policy)
        step, encode, augment = [], [], []
        for _ in range(steps + 1):  # the first step warms up
            t0 = time.perf_counter()
            loss, _ = policy.forward(batch)
            loss.backward()
            opt.step()
            opt.zero_grad()
            policy.update()
            t1 = time.perf_counter()
            model = policy.model
            cond = model.global_condition(
                batch["observation.images.wrist"], batch["observation.state"], batch["observation.bbox"]
            )
            cond.sum().backward()
            opt.zero_grad()
            t2 = time.perf_counter()
            model.augment(
                batch["observation.images.wrist"], torch.rand(batch_size, t, 1, 224, 224), config.image_size
            )
            step.append(t1 - t0)
            encode.append(t2 - t1)
            augment.append(time.perf_counter() - t2)
        rows[name] = [float(np.median(x[1:])) for x in (step, encode, augment)]
    base = rows[next(iter(TRAINING_LEVERS))][0]
    lines = [
        f"| training lever (float32, batch {batch_size}, model only) | s per step | samples/s | ratio to the "
        "preset | encoder fwd+bwd s | augmentation s |",
        "|---|---|---|---|---|---|",
    ]
    for name, (st, enc, aug) in rows.items():
        lines.append(
            f"| {name} | {st:.3f} | {batch_size / st:.1f} | {base / st:.2f}x | {enc:.3f} | {aug:.3f} |"
        )
    with tempfile.TemporaryDirectory() as tmp:
        rates = _dataset_sample_rates(Path(tmp))
    lines.append(
        "\nLeRobotDataset `__getitem__`, one process (a 16-step action and the video frame decoded "
        "per sample); lerobot-train's loader worker shares the 2 cores with the step:\n"
    )
    lines += ["| observation window | samples/s | ratio |", "|---|---|---|"]
    base_rate = next(iter(rates.values()))
    lines += [f"| {name} | {r:.0f} | {r / base_rate:.2f}x |" for name, r in rates.items()]
    return "\n".join(lines)


# The loader's cost depends on the observation window (LeRobotDataset queries one window per key with
# delta timestamps; a single current step is read from the frame's own row).
LOADER_WINDOWS: dict[str, dict[str, Any]] = {
    "preset: 2 observed steps": {},
    "fast encoder: 1 observed step": {"n_obs_steps": 1, "image_size": 64},
}


def _dataset_sample_rates(tmp: Path, samples: int = 96) -> dict[str, float]:
    """Samples/s of ``LeRobotDataset.__getitem__`` per ``LOADER_WINDOWS`` entry, one process, with the
    delta timestamps lerobot-train derives from that policy config."""
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    from lerobot_bboxpick.data.collect import CollectConfig, collect

    collect(CollectConfig(repo_id="bench/data", root=tmp / "ds", episodes=2, workers=1))
    meta = LeRobotDatasetMetadata("bench/data", root=tmp / "ds")
    rates = {}
    for name, overrides in LOADER_WINDOWS.items():
        window = resolve_delta_timestamps(_lever_policy(overrides).config, meta)
        dataset = LeRobotDataset("bench/data", root=tmp / "ds", delta_timestamps=window)
        order = np.random.default_rng(0).integers(0, len(dataset), samples).tolist()
        dataset[order[0]]
        t0 = time.perf_counter()
        for i in order:
            dataset[i]
        rates[name] = samples / (time.perf_counter() - t0)
    return rates


# Inference-speed levers, each a set of bbox_diffusion config overrides timed beside the preset in one run
# (docs/benchmarks.md holds their pick rates on validation seeds).
INFERENCE_LEVERS: dict[str, dict[str, Any]] = {
    "preset (96 px, 2 obs, 16 DDIM steps)": {},
    "8 DDIM steps": {"num_inference_steps": 8},
    "4 DDIM steps": {"num_inference_steps": 4},
    "half-width UNet (32, 64, 128)": {"down_dims": (32, 64, 128)},
    "64 px, 1 observed frame": {"image_size": 64, "n_obs_steps": 1},
    "64 px, 1 frame, 8 DDIM steps": {"image_size": 64, "n_obs_steps": 1, "num_inference_steps": 8},
    "64 px, 1 frame, 6 DDIM steps": {"image_size": 64, "n_obs_steps": 1, "num_inference_steps": 6},
    "64 px, 1 frame, 4 DDIM steps": {"image_size": 64, "n_obs_steps": 1, "num_inference_steps": 4},
    "ONNX Runtime UNet (preset otherwise)": {"onnx_inference": True},
    "64 px, 1 frame, ONNX Runtime UNet (16 DDIM steps)": {
        "image_size": 64,
        "n_obs_steps": 1,
        "onnx_inference": True,
    },
    "64 px, 1 frame, ONNX Runtime, 12 DDIM steps": {
        "image_size": 64,
        "n_obs_steps": 1,
        "onnx_inference": True,
        "num_inference_steps": 12,
    },
    "64 px, 1 frame, half-width UNet, 16 DDIM steps": {
        "image_size": 64,
        "n_obs_steps": 1,
        "down_dims": (32, 64, 128),
    },
    "64 px, 1 frame, half-width UNet, 12 DDIM steps": {
        "image_size": 64,
        "n_obs_steps": 1,
        "down_dims": (32, 64, 128),
        "num_inference_steps": 12,
    },
    "64 px, 1 frame, half-width UNet, 8 DDIM steps": {
        "image_size": 64,
        "n_obs_steps": 1,
        "down_dims": (32, 64, 128),
        "num_inference_steps": 8,
    },
    "64 px, 1 frame, 48 px target view, 4 DDIM steps": {
        "image_size": 64,
        "n_obs_steps": 1,
        "target_crop_size": 48,
        "num_inference_steps": 4,
    },
}


def bench_inference_levers(chunks: int = 20, threads: int | None = None) -> str:
    """Markdown table: ms per predicted chunk (encoder + denoising, float32 as evaluation runs) of each
    ``INFERENCE_LEVERS`` entry with its ratio to the preset. The levers take turns chunk by chunk, so a
    host whose speed drifts during the run (shared or throttled CPUs) moves every lever alike and the
    ratios hold; ``threads`` sets torch's thread count (None: torch's default)."""
    import torch

    from lerobot_bboxpick.policies.bbox_diffusion.onnx_runtime import require_onnxruntime

    if threads is not None:
        torch.set_num_threads(threads)
    obs = {
        "observation.images.wrist": torch.rand(1, 3, 224, 224),
        "observation.state": torch.rand(1, 10),
        "observation.bbox": torch.tensor([[0.4, 0.4, 0.5, 0.5]]),
    }
    levers = dict(INFERENCE_LEVERS)
    try:
        require_onnxruntime()
    except ImportError as err:  # an optional extra: its rows are left out, with a warning
        levers = {name: o for name, o in levers.items() if not o.get("onnx_inference")}
        log.warning("no ONNX Runtime rows: %s", err)
    policies = {name: _lever_policy(overrides).eval() for name, overrides in levers.items()}
    samples: dict[str, list[float]] = {name: [] for name in policies}
    with torch.no_grad():
        for round_ in range(chunks + 2):  # the first two rounds trace and warm up each UNet
            for name, policy in policies.items():
                policy.reset()
                t0 = time.perf_counter()
                policy.select_action(dict(obs))  # empty queue: a full chunk
                if round_ >= 2:
                    samples[name].append(time.perf_counter() - t0)
    times = {name: 1000 * float(np.median(s)) for name, s in samples.items()}
    base = times[next(iter(INFERENCE_LEVERS))]
    lines = [
        f"| inference lever (float32, {torch.get_num_threads()} torch threads, median of {chunks} "
        "interleaved chunks) | ms per 16-step chunk | ratio to the preset |",
        "|---|---|---|",
    ]
    lines += [f"| {name} | {ms:.1f} | {ms / base:.2f}x |" for name, ms in times.items()]
    return "\n".join(lines)


def bench_collect(episodes: int = 6, settings: str = "grid_id") -> str:
    """Markdown table: expert episodes/min and frames/s written by bboxpick-collect with 1 and 2 workers
    (same seeds, fresh temporary datasets; includes video encoding and the final aggregation)."""
    import json
    import tempfile

    from lerobot_bboxpick.data.collect import CollectConfig, collect

    lines = ["| workers | episodes | seconds | episodes/min | frames written/s |", "|---|---|---|---|---|"]
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as tmp:
            root = Path(tmp) / "ds"
            t0 = time.perf_counter()
            collect(
                CollectConfig(
                    repo_id="bench/collect",
                    root=root,
                    settings=settings,
                    episodes=episodes,
                    workers=workers,
                    shard_size=max(1, episodes // (2 * workers)),
                )
            )
            seconds = time.perf_counter() - t0
            frames = json.loads((root / "meta" / "info.json").read_text())["total_frames"]
        lines.append(
            f"| {workers} | {episodes} | {seconds:.1f} | {60 * episodes / seconds:.1f} | "
            f"{frames / seconds:.1f} |"
        )
    return "\n".join(lines)


def save_random_checkpoint(path: str | Path, **config_overrides: Any) -> Path:
    """A randomly initialised bbox_diffusion checkpoint (policy + its processors) saved the way
    ``lerobot-train`` saves ``pretrained_model/``; costs what a trained one costs at inference."""
    from lerobot.policies.factory import make_pre_post_processors

    from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
    from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy

    inputs, outputs = _policy_features(224)
    config = BboxDiffusionConfig(
        input_features=inputs, output_features=outputs, device="cpu", **config_overrides
    )
    path = Path(path)
    BboxDiffusionPolicy(config).save_pretrained(path)
    pre, post = make_pre_post_processors(config, dataset_stats=None)
    pre.save_pretrained(path)
    post.save_pretrained(path)
    return path


def bench_suite(episodes: int = 2, workers: int = 2, full_suite: int = 6 * 30) -> str:
    """Suite episodes/min for one CPU-preset policy over all six settings, and the projected minutes of
    the full 6 x 30 suite. The policy is randomly initialised: it never lifts a brick, so every episode
    runs to the 300-step limit, the slowest case a trained policy can meet."""
    import tempfile

    from lerobot_bboxpick.eval.suite import SuiteConfig, read_episodes, run_suite

    with tempfile.TemporaryDirectory() as tmp:
        ckpt = save_random_checkpoint(Path(tmp) / "random" / "pretrained_model")
        t0 = time.perf_counter()
        run_suite(
            SuiteConfig(
                policies=f"cpu_preset={ckpt}",
                episodes=episodes,
                workers=workers,
                videos=0,
                out_dir=Path(tmp) / "suite",
            )
        )
        seconds = time.perf_counter() - t0
        lines = read_episodes(Path(tmp) / "suite" / "episodes.jsonl")
    n = len(lines)
    steps = sum(r["steps"] for r in lines)
    per_min = 60 * n / seconds
    return "\n".join(
        [
            "| suite (cpu preset, all 6 settings) | workers | episodes | env steps | seconds | episodes/min "
            f"| projected minutes for {full_suite} episodes |",
            "|---|---|---|---|---|---|---|",
            f"| random-init policy (all episodes 300 steps) | {workers} | {n} | {steps} | {seconds:.0f} "
            f"| {per_min:.1f} | {full_suite / per_min:.1f} |",
        ]
    )
