"""The main job end to end: collect expert demos -> ``lerobot-train`` bbox_diffusion -> ``bboxpick-suite``.

    lerobot_bboxpick run                  # quick profile: ~15 min on 2 cores, sized to this machine
    lerobot_bboxpick run --profile full   # the 90-minute CPU recipe and the full 6 x 30 suite
    lerobot_bboxpick run --profile full --bbox-mode none   # the no-prompt ablation on the same demos

Each stage is the project's (or LeRobot's) own command, run with the options printed beside it, and
each one resumes: collection continues its shards, training continues from its last checkpoint,
the suite keeps the episodes already in its JSONL. Re-running a finished job only re-prints the table.

Machines of this kind differ 3-4x in speed, so training is sized by time, not by a fixed step count:
the first ``CALIBRATION_STEPS`` steps of the real ``lerobot-train`` run measure this machine's rate,
and the quick profile derives its step count from its time budget (both printed). Precision follows
the CPU (``lerobot_bboxpick.precision``). Third-party output (lerobot-train's log, dataset bars,
encoder lines) goes to ``<out>/logs``; the console shows our progress bars and the ETA of each stage.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

from tqdm import tqdm

from lerobot_bboxpick import seeds
from lerobot_bboxpick.precision import PrecisionChoice, choose_precision
from lerobot_bboxpick.shipped_checkpoints import SHIPPED_CHECKPOINT
from lerobot_bboxpick.sim.layouts import SETTINGS

CALIBRATION_STEPS = 40  # the first steps of the real run; their rate sizes the rest
LOG_FREQ = 10  # lerobot-train logs every this many steps
# lerobot-train's log line: "... updt_s:0.412 data_s:0.003" (means over the last log interval).
_STEP_LINE = re.compile(r"step:(\S+) .*updt_s:([\d.]+) data_s:([\d.]+)")


# The fast encoder input: 64 px, one observed frame (2.5x the model's training samples/s of the 96 px
# two-frame preset, ~1.4x with lerobot-train's data loading; docs/benchmarks.md).
FAST_ENCODER = ("--policy.image_size=64", "--policy.n_obs_steps=1")
# The practical recipe's policy options: the gripper's height above the table as an input (validation
# Pick 88% against 61% without it, the same demos and schedule; docs/results.md) and 4 DDIM steps, the
# step count its validation and test rows were measured at.
PRACTICAL_POLICY = ("--policy.height_input=true", "--policy.num_inference_steps=4")
PRACTICAL_STEPS = 12000  # 96,000 samples of batch 8, float32: 32 minutes on a 2-core Zen 4 EPYC


@dataclass(frozen=True)
class Profile:
    """Sizes of one end-to-end run."""

    episodes: int  # expert demonstrations collected (training seeds from 0)
    train_settings: str  # settings the demos come from (seeds cycle through them)
    # Training length: a time budget (steps derived from the calibrated rate, capped at ``steps``), or
    # None for a fixed ``steps`` (a recipe is defined by its samples: steps x batch_size).
    train_minutes: float | None
    steps: int
    batch_size: int
    warmup_steps: int
    suite_episodes: int  # per setting, test seeds from 10000
    videos: int  # rollout MP4s kept per setting
    bbox_mode: str = "mask"
    # Chunk steps executed before predicting again, and the augmented mask's centroid/size as extra
    # conditioning (mask mode only): the policy's defaults, re-checked on validation seeds
    # (docs/results.md).
    n_action_steps: int = 12
    mask_centroid: bool = True
    # lerobot-train's --policy.use_amp (bf16 autocast for encoder and UNet); None: bf16 only where the
    # CPU runs it natively (lerobot_bboxpick.precision).
    use_amp: bool | None = None
    # Further lerobot-train --policy.* options of the recipe (e.g. a smaller input for a faster run).
    policy_args: tuple[str, ...] = ()
    # Fraction of demos recorded as recoveries (bboxpick-collect --recovery).
    recovery: float = 0.0
    # Settings the suite evaluates.
    suite_settings: str = ",".join(SETTINGS)
    # lerobot-train's --seed (its default): another value repeats the recipe with a second training seed.
    train_seed: int = 1000
    # lerobot-train's --num_workers. On 2 cores a loader worker competes with the update's two threads:
    # on an AVX2-only EPYC in float32 the fast encoder's batch-8 step took 0.35-0.55 s with one worker
    # (slowing as the run went on: a 9-minute budget took 13.4) and a steady 0.33 s loading in the main
    # process (docs/benchmarks.md).
    loader_workers: int = 1
    # With a time budget: never fewer steps than this, however slow the machine. Below it the policy does
    # not pick reliably (validation), so a slow machine trains longer rather than show a failing policy.
    min_steps: int = 0


PROFILES = {
    # About 15 minutes on any machine of this kind: ~9 of them training, whatever the machine's rate, with
    # the fast encoder (twice the preset's samples/s) in batches of 8: in a fixed time, more updates of
    # fewer samples learn faster here (validation seeds: batch 8 x 2900 steps picked 16/20 on grid_id,
    # batch 16 x 1900 13/20, batch 32 x 600 0/20; docs/results.md). A slow machine (AVX2 only, float32)
    # fits ~1600 such steps in 9 minutes: 11/20 at the default lr; lr 1e-3 picked 18/20 with one training
    # seed and 2/20 with another, so the default stays (docs/results.md). So the budget has a floor of
    # 2900 steps (23,200 samples; 16/20 with both training seeds): there training takes ~15 minutes
    # instead of 9. Evaluated on the two layouts it trains on.
    "quick": Profile(
        episodes=60,
        train_settings="grid_id,identical_4",
        train_minutes=9.0,
        steps=4000,
        batch_size=8,
        warmup_steps=100,
        suite_episodes=10,
        videos=1,
        policy_args=FAST_ENCODER,
        suite_settings="grid_id,identical_4",
        loader_workers=0,
        min_steps=2900,
    ),
    # The CPU recipe (docs/results.md): 5000 steps of batch 32 (160k samples), ~45 min at ~1.9 steps/s
    # with bf16 autocast on a 2-core CPU that has it natively, ~80 min in float32.
    "full": Profile(
        episodes=200,
        train_settings="grid_id,identical_4",
        train_minutes=None,
        steps=5000,
        batch_size=32,
        warmup_steps=300,
        suite_episodes=30,
        videos=2,
    ),
    # The practical recipe (docs/results.md): demos from every layout, the fast 64 px single-frame encoder
    # with the gripper's height, batches of 8 in float32 (on validation seeds batch 8 x 12,000 matched batch
    # 32 x 5000 at 60% of the samples); what the shipped checkpoint (examples/) was trained with. No
    # recovery demos: with the height input they bought nothing (two training seeds each on validation
    # seeds: 313 of 360 picks without them, 300 with 30% of them).
    "practical": Profile(
        episodes=180,
        train_settings=",".join(SETTINGS),
        train_minutes=None,
        steps=PRACTICAL_STEPS,
        batch_size=8,
        warmup_steps=300,
        suite_episodes=30,
        videos=1,
        use_amp=False,
        policy_args=FAST_ENCODER + PRACTICAL_POLICY,
    ),
}


def _bin(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def _env() -> dict[str, str]:
    return {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}


def _episodes_in(root: Path) -> int:
    info = root / "meta" / "info.json"
    return json.loads(info.read_text())["total_episodes"] if info.exists() else 0


def train_command(
    profile: Profile, dataset_root: Path, repo_id: str, out: Path, steps: int, use_amp: bool
) -> list[str]:
    """The ``lerobot-train`` call training to ``steps`` (resuming when ``out`` holds a checkpoint)."""
    save_freq = f"--save_freq={max(CALIBRATION_STEPS, steps // 5)}"
    last = out / "checkpoints" / "last" / "pretrained_model"
    if (last / "train_config.json").exists():
        # --steps follows the caller, so a run resumed after calibration (or a grown profile) trains
        # to the new length.
        return [
            _bin("lerobot-train"),
            f"--config_path={last / 'train_config.json'}",
            "--resume=true",
            f"--steps={steps}",
            save_freq,
        ]
    return [
        _bin("lerobot-train"),
        "--policy.type=bbox_diffusion",
        f"--policy.bbox_mode={profile.bbox_mode}",
        f"--policy.mask_centroid={str(profile.mask_centroid and profile.bbox_mode == 'mask').lower()}",
        "--policy.device=cpu",
        f"--policy.scheduler_warmup_steps={profile.warmup_steps}",
        f"--policy.n_action_steps={profile.n_action_steps}",
        f"--policy.use_amp={str(use_amp).lower()}",
        *profile.policy_args,
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={dataset_root}",
        f"--output_dir={out}",
        f"--steps={steps}",
        f"--batch_size={profile.batch_size}",
        f"--seed={profile.train_seed}",
        f"--num_workers={profile.loader_workers}",
        save_freq,
        f"--log_freq={LOG_FREQ}",
        "--wandb.enable=false",
    ]


def trained_steps(out: Path) -> int:
    """Optimisation steps of the last checkpoint in a lerobot-train output folder (0 if none)."""
    state = out / "checkpoints" / "last" / "training_state" / "training_step.json"
    return json.loads(state.read_text())["step"] if state.exists() else 0


def run_train(cmd: list[str], log: Path, start: int, total: int) -> float | None:
    """Run ``lerobot-train`` with its output in ``log`` and our progress bar on the console.

    Returns the measured seconds per step, or None: the wall-clock time between its first and last log
    lines per step in between (everything a step costs, the loader's contention included), or with a
    single log line its logged update + data time.
    """
    print("+ " + shlex.join(cmd), flush=True)
    print(f"  lerobot-train's log: {log}", flush=True)
    log.parent.mkdir(parents=True, exist_ok=True)
    per_step: list[float] = []
    marks: list[tuple[float, int]] = []  # (wall clock, steps done) at each log line
    with open(log, "a") as sink, tqdm(total=total, initial=start, desc="train", unit="step") as bar:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=_env(), bufsize=1
        )
        assert proc.stdout is not None
        for line in proc.stdout:
            sink.write(line)
            match = _STEP_LINE.search(line)
            if match:
                # LeRobot abbreviates steps from 1000 on ("step:3K"): then count log lines instead.
                logged = match.group(1)
                step = _parse_count(logged) if logged.isdigit() else bar.n + LOG_FREQ
                per_step.append(float(match.group(2)) + float(match.group(3)))
                bar.update(max(0, step - bar.n))
                marks.append((time.perf_counter(), bar.n))
        if proc.wait() != 0:
            raise subprocess.CalledProcessError(proc.returncode, cmd, output=f"see {log}")
    return wall_seconds_per_step(marks) or _mean_steady(per_step)


def wall_seconds_per_step(marks: list[tuple[float, int]]) -> float | None:
    """Seconds per step between the first and the last ``(wall clock, steps done)`` mark, or None with
    fewer than two. The first mark ends the warm-up (start-up, first batches), so it is the start."""
    if len(marks) < 2 or marks[-1][1] <= marks[0][1]:
        return None
    (t0, s0), (t1, s1) = marks[0], marks[-1]
    return (t1 - t0) / (s1 - s0)


def _mean_steady(per_step: list[float]) -> float | None:
    # The first interval includes warm-up (first batches, allocator); later ones are the steady rate.
    steady = per_step[1:] or per_step
    return sum(steady) / len(steady) if steady else None


def _parse_count(text: str) -> int:
    """LeRobot's ``format_big_number``: 40, 1K, 1.2K ... -> int."""
    scale = {"K": 1e3, "M": 1e6, "B": 1e9}
    return int(float(text[:-1]) * scale[text[-1]]) if text[-1] in scale else int(float(text))


def budget_steps(profile: Profile, seconds_per_step: float) -> int:
    """Steps that fit the profile's time budget at the measured rate (``profile.steps`` if it has none)."""
    if profile.train_minutes is None:
        return profile.steps
    fitted = int(profile.train_minutes * 60 / seconds_per_step)
    return max(CALIBRATION_STEPS, profile.min_steps, min(profile.steps, fitted))


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min"


def run_pipeline(profile_name: str = "quick", out_dir: Path = Path("outputs/main"), **overrides) -> Path:
    """Collect -> train -> suite for a profile; returns the suite's table.md."""
    from lerobot_bboxpick.data.collect import CollectConfig, collect
    from lerobot_bboxpick.eval.suite import SuiteConfig, run_suite

    profile = replace(PROFILES[profile_name], **overrides)
    out_dir = Path(out_dir) / profile_name
    logs = out_dir / "logs"
    repo_id = f"local/lego_pick_{profile_name}"
    data = out_dir / "data"
    t0 = time.perf_counter()
    print(
        f"[1/3] expert demos: {profile.episodes} in {profile.train_settings} "
        f"(training seeds from {seeds.TRAIN_START}) -> {data}; ETA on the bar",
        flush=True,
    )
    if _episodes_in(data) < profile.episodes:
        summary = collect(
            CollectConfig(
                repo_id=repo_id,
                root=data,
                settings=profile.train_settings,
                episodes=profile.episodes,
                recovery=profile.recovery,
                workers=2,
                resume=True,
                log_file=logs / "collect.log",
            )
        )
        print(json.dumps(summary), flush=True)
    t1 = time.perf_counter()

    # The demos serve every bbox_mode; training and suite folders are per mode (ablations side by side).
    suffix = "" if profile.bbox_mode == "mask" else f"_{profile.bbox_mode}"
    train = out_dir / f"train{suffix}"
    precision = _precision(train, profile.use_amp)
    print(f"[2/3] lerobot-train bbox_diffusion -> {train}; precision: {precision.reason}", flush=True)
    steps = _sized_steps(train)
    log = logs / f"train{suffix}.log"
    if steps is None:  # no sizing recorded yet: calibrate on the first steps of the real run
        print(f"  calibrating: the first {CALIBRATION_STEPS} steps measure this machine's rate", flush=True)
        if trained_steps(train) < CALIBRATION_STEPS:
            cmd = train_command(profile, data, repo_id, train, CALIBRATION_STEPS, precision.use_amp)
            seconds_per_step = run_train(cmd, log, trained_steps(train), CALIBRATION_STEPS)
        else:
            seconds_per_step = None
        seconds_per_step = seconds_per_step or _fallback_rate(log)
        steps = budget_steps(profile, seconds_per_step)
        sizing = {
            "seconds_per_step": round(seconds_per_step, 4),
            "samples_per_s": round(profile.batch_size / seconds_per_step, 2),
            "precision": precision.name,
            "train_minutes": profile.train_minutes,
            "steps": steps,
            "samples": steps * profile.batch_size,
        }
        (train / "sizing.json").write_text(json.dumps(sizing, indent=1))
        budget = f"budget {profile.train_minutes:g} min -> " if profile.train_minutes else "fixed "
        if profile.train_minutes and steps == profile.min_steps > CALIBRATION_STEPS:
            budget += "at least "  # the floor: the budget buys fewer steps than picking needs here
        print(
            f"  measured {sizing['samples_per_s']} samples/s ({seconds_per_step:.2f} s/step, "
            f"batch {profile.batch_size}, {precision.name}); {budget}{steps} steps "
            f"({sizing['samples']} samples); ETA {_minutes((steps - CALIBRATION_STEPS) * seconds_per_step)}",
            flush=True,
        )
    if trained_steps(train) < steps:
        cmd = train_command(profile, data, repo_id, train, steps, precision.use_amp)
        run_train(cmd, log, trained_steps(train), steps)
    t2 = time.perf_counter()

    checkpoint = train / "checkpoints" / "last" / "pretrained_model"
    settings = profile.suite_settings.split(",")
    n_episodes = 2 * len(settings) * profile.suite_episodes
    print(
        f"[3/3] bboxpick-suite: policy + expert, {profile.suite_episodes} test episodes x {len(settings)} "
        # No fixed per-episode guess: it was 1.6 s of wall clock on one 2-core machine and 5.7 s on another.
        f"settings ({n_episodes} episodes); ETA on the bar",
        flush=True,
    )
    table = run_suite(
        SuiteConfig(
            policies=f"expert,bbox_diffusion{suffix}={checkpoint}",
            settings=profile.suite_settings,
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


def what_next(table: Path, checkpoint: Path) -> str:
    """The closing message of the main job: where its artefacts are and what to run next."""
    suite = table.parent
    videos = sorted((suite / "videos").glob("bbox_diffusion*/*.mp4"))
    sheets = sorted(suite.glob("outcomes_bbox_diffusion*.png"))
    lines = [
        f"report: {table} (bar chart {suite / 'outcomes.png'}, per-episode JSONL {suite / 'episodes.jsonl'})",
        f"outcome contact sheet: {sheets[0] if sheets else '(none)'}",
        f"a rollout video: {videos[0] if videos else '(none)'}",
        "",
        "What next:",
        "  # the shipped checkpoint (practical recipe, all six settings), no training needed:",
        f"  bboxpick-suite --policies=shipped={SHIPPED_CHECKPOINT} --episodes=30 "
        "--out_dir=outputs/suite_shipped",
        f"  lerobot-eval --policy.path={SHIPPED_CHECKPOINT} --env.type=lego_pick --env.setting=random_id "
        "--eval.n_episodes=10 --eval.batch_size=1",
        "  # the recipe that made the shipped checkpoint (45-60 minutes on 2 cores) and its 6 x 30 suite:",
        "  bash scripts/main.sh --profile practical",
        "  # the paper protocol (grid demos only, about 90 minutes):",
        "  bash scripts/main.sh --profile full",
        "  # share this checkpoint on the Hugging Face Hub (needs `hf auth login` and network):",
        f"  hf upload <your-user>/bbox_diffusion_lego_pick {checkpoint}",
    ]
    return "\n".join(lines)


def _precision(train: Path, requested: bool | None) -> PrecisionChoice:
    """The run's precision: what an existing checkpoint was started with, else the CPU's choice."""
    config = train / "checkpoints" / "last" / "pretrained_model" / "config.json"
    if config.exists() and requested is None:
        use_amp = bool(json.loads(config.read_text()).get("use_amp", False))
        return PrecisionChoice(use_amp, f"{'bf16 autocast' if use_amp else 'float32'}, as the run began")
    return choose_precision(requested)


def _sized_steps(train: Path) -> int | None:
    sizing = train / "sizing.json"
    return json.loads(sizing.read_text())["steps"] if sizing.exists() else None


def _fallback_rate(log: Path) -> float:
    """Seconds per step from an earlier log of this run (a calibration interrupted after its checkpoint)."""
    values = [
        float(m.group(2)) + float(m.group(3))
        for m in map(_STEP_LINE.search, log.read_text().splitlines() if log.exists() else [])
        if m
    ]
    if not values:
        raise RuntimeError(f"no lerobot-train step timings in {log}; delete the training folder and re-run")
    return sum(values) / len(values)
