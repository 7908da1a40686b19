"""The main job end to end: collect expert demos -> ``lerobot-train`` the CPU preset -> ``bboxpick-suite``.

    lerobot_bboxpick run                  # quick profile: ~15 min on 2 cores, a few episodes per setting
    lerobot_bboxpick run --profile full   # the 90-minute CPU recipe and the full 6 x 30 suite
    lerobot_bboxpick run --profile full --bbox-mode none   # the no-prompt ablation on the same demos

Each stage is the project's (or LeRobot's) own command, run with the options printed beside it, and
each one resumes: collection continues its shards, training continues from its last checkpoint,
the suite keeps the episodes already in its JSONL. Re-running a finished job only re-prints the table.
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

from lerobot_bboxpick.sim.layouts import SETTINGS


@dataclass(frozen=True)
class Profile:
    """Sizes of one end-to-end run."""

    episodes: int  # expert demonstrations collected
    train_settings: str  # settings the demos come from (seeds cycle through them)
    steps: int  # lerobot-train optimisation steps
    batch_size: int
    warmup_steps: int
    suite_episodes: int  # per setting, held-out seeds from 10000
    videos: int  # rollout MP4s kept per setting
    bbox_mode: str = "mask"
    # Chunk steps executed before predicting again: 12 of 16 picked 5/5 in the canary, 8 picked 0/5 and
    # 16 picked 1/5 (README, "The canary").
    n_action_steps: int = 12
    # Append the augmented mask's centroid/size to the conditioning (mask mode only; see the config):
    # grid_id Pick 13% -> 93% in the 90-minute recipe (README).
    mask_centroid: bool = True
    # lerobot-train's --policy.use_amp: bf16 autocast for the encoder and UNet (poses and masks stay
    # float32 inside the policy). The recipe's 5000 steps took 43 min with it, 76 min without, with the
    # same or better suite results (README); on CPUs without native bf16 it would be slower: --no-amp.
    use_amp: bool = True


PROFILES = {
    # About 15 minutes here (11 of them training): every stage works and the policy starts to pick
    # (2026-11-24: 3 of 12 suite episodes, half of grid_id), far from the full recipe.
    "quick": Profile(
        episodes=30,
        train_settings="grid_id,identical_4",
        steps=1300,
        batch_size=32,
        warmup_steps=100,
        suite_episodes=2,
        videos=1,
    ),
    # The CPU recipe (README, "A policy trained on this machine"): 5000 steps take ~43 minutes at the
    # measured ~1.9 steps/s with batch 32 and bf16 autocast on 2 cores (~76 min in float32).
    "full": Profile(
        episodes=200,
        train_settings="grid_id,identical_4",
        steps=5000,
        batch_size=32,
        warmup_steps=300,
        suite_episodes=30,
        videos=2,
    ),
}


def _bin(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def _run(cmd: list[str]) -> None:
    print("+ " + shlex.join(cmd), flush=True)
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}
    subprocess.run(cmd, check=True, env=env)


def _episodes_in(root: Path) -> int:
    info = root / "meta" / "info.json"
    return json.loads(info.read_text())["total_episodes"] if info.exists() else 0


def train_command(profile: Profile, dataset_root: Path, repo_id: str, out: Path) -> list[str]:
    """The ``lerobot-train`` call of a profile (resuming when ``out`` holds a checkpoint)."""
    last = out / "checkpoints" / "last" / "pretrained_model"
    if (last / "train_config.json").exists():
        # --steps follows the profile, so a run resumed after the profile grew trains to the new length.
        return [
            _bin("lerobot-train"),
            f"--config_path={last / 'train_config.json'}",
            "--resume=true",
            f"--steps={profile.steps}",
        ]
    return [
        _bin("lerobot-train"),
        "--policy.type=bbox_diffusion",
        "--policy.preset=cpu",
        f"--policy.bbox_mode={profile.bbox_mode}",
        f"--policy.mask_centroid={str(profile.mask_centroid and profile.bbox_mode == 'mask').lower()}",
        "--policy.device=cpu",
        f"--policy.scheduler_warmup_steps={profile.warmup_steps}",
        f"--policy.n_action_steps={profile.n_action_steps}",
        f"--policy.use_amp={str(profile.use_amp).lower()}",
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={dataset_root}",
        f"--output_dir={out}",
        f"--steps={profile.steps}",
        f"--batch_size={profile.batch_size}",
        "--num_workers=1",
        f"--save_freq={max(100, profile.steps // 5)}",
        "--log_freq=50",
        "--wandb.enable=false",
    ]


def trained_steps(out: Path) -> int:
    """Optimisation steps of the last checkpoint in a lerobot-train output folder (0 if none)."""
    state = out / "checkpoints" / "last" / "training_state" / "training_step.json"
    return json.loads(state.read_text())["step"] if state.exists() else 0


def run_pipeline(profile_name: str = "quick", out_dir: Path = Path("outputs/main"), **overrides) -> Path:
    """Collect -> train -> suite for a profile; returns the suite's table.md."""
    from lerobot_bboxpick.data.collect import CollectConfig, collect
    from lerobot_bboxpick.eval.suite import SuiteConfig, run_suite

    profile = replace(PROFILES[profile_name], **overrides)
    out_dir = Path(out_dir) / profile_name
    repo_id = f"local/lego_pick_{profile_name}"
    data = out_dir / "data"
    t0 = time.perf_counter()
    print(f"[1/3] expert demos: {profile.episodes} in {profile.train_settings} -> {data}", flush=True)
    if _episodes_in(data) < profile.episodes:
        summary = collect(
            CollectConfig(
                repo_id=repo_id,
                root=data,
                settings=profile.train_settings,
                episodes=profile.episodes,
                workers=2,
                resume=True,
            )
        )
        print(json.dumps(summary), flush=True)
    t1 = time.perf_counter()
    # The demos serve every bbox_mode; training and suite folders are per mode (ablations side by side).
    suffix = "" if profile.bbox_mode == "mask" else f"_{profile.bbox_mode}"
    train = out_dir / f"train{suffix}"
    print(f"[2/3] lerobot-train bbox_diffusion (cpu preset), {profile.steps} steps -> {train}", flush=True)
    if trained_steps(train) < profile.steps:
        _run(train_command(profile, data, repo_id, train))
    t2 = time.perf_counter()
    checkpoint = train / "checkpoints" / "last" / "pretrained_model"
    print(f"[3/3] bboxpick-suite: policy + expert, {profile.suite_episodes} episodes x 6 settings")
    table = run_suite(
        SuiteConfig(
            policies=f"expert,bbox_diffusion{suffix}={checkpoint}",
            settings=",".join(SETTINGS),
            episodes=profile.suite_episodes,
            videos=profile.videos,
            out_dir=out_dir / f"suite{suffix}",
        )
    )
    t3 = time.perf_counter()
    print(
        f"minutes: collect {(t1 - t0) / 60:.1f}, train {(t2 - t1) / 60:.1f}, suite {(t3 - t2) / 60:.1f}",
        flush=True,
    )
    return table
