"""Integration error of the sampling ODE per UNet call: DDIM against DPM-Solver++ (``--policy.sampler``).

The shipped checkpoint drives eight validation episodes (seeds 5000-5001 of four settings, 120 steps,
16 DDIM steps); at every new chunk its observation is kept. Each observation is then sampled with 16
noise draws by each sampler at 4, 6, 8 and 16 calls, and by DDIM at 50 calls from the same noise (the
converged chunk); the table gives the position error of the executed steps in mm.

From the repository root (about 10 minutes on a 2-core machine running a training beside it):
``python -m lerobot_bboxpick.eval.sampler_error > docs/benchmarks/sampler_error.md``
"""

from __future__ import annotations

import contextlib
import sys

import numpy as np
import torch

from lerobot_bboxpick.eval.rollout import PolicyRunner, rollout
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import sampling_scheduler
from lerobot_bboxpick.shipped_checkpoints import FIRST_SHIPPED_CHECKPOINT

DRAWS = 16


def chunk_observations(runner: PolicyRunner) -> list[dict]:
    """The preprocessed observation at every new chunk of the policy's own validation rollouts."""
    kept: list[dict] = []
    preprocess = runner.observation_batch

    def recording(observation: dict, task: str) -> dict:
        batch = preprocess(observation, task)
        if not runner.policy._actions:  # select_action will sample a new chunk from this one
            kept.append(batch)
        return batch

    runner.observation_batch = recording
    for setting in ("grid_ood", "random_id", "pile_id", "identical_4"):
        for seed in (5000, 5001):
            rollout(runner, setting, seed, policy_seed=seed, max_steps=120)
    runner.observation_batch = preprocess
    return kept


def chunk_positions(runner: PolicyRunner, batches: list[dict], sampler: str, steps: int) -> np.ndarray:
    """(observations, DRAWS, n_action_steps, 3) executed chunk positions in metres, sampled by ``sampler``
    in ``steps`` UNet calls (set on the runner's policy, which keeps them); the same noise for every
    sampler and step count."""
    policy = runner.policy
    policy.config.sampler, policy.config.num_inference_steps = sampler, steps
    model = policy._inference_model()
    model.sampling_scheduler = sampling_scheduler(policy.config, model.noise_scheduler)
    out = []
    for batch in batches:
        repeated = {k: v.expand(DRAWS, *v.shape[1:]) for k, v in batch.items() if torch.is_tensor(v)}
        chunk = policy.predict_action_chunk(repeated, generator=torch.Generator().manual_seed(0))
        out.append(chunk[:, : policy.config.n_action_steps, :3].numpy())
    return np.stack(out)


def error_mm(positions: np.ndarray, converged: np.ndarray) -> np.ndarray:
    """Distance of each chunk step from the converged chunk's, in mm."""
    return np.linalg.norm(positions - converged, axis=-1) * 1e3


def main() -> None:
    """Print the markdown table of the module docstring."""
    torch.set_num_threads(1)
    with contextlib.redirect_stdout(sys.stderr):  # LeRobot's loader prints; stdout is the table
        runner = PolicyRunner.from_pretrained(FIRST_SHIPPED_CHECKPOINT)
    batches = chunk_observations(runner)
    converged = chunk_positions(runner, batches, "ddim", 50)
    print(f"{len(batches)} chunk observations x {DRAWS} noise draws; error against 50-step DDIM, mm\n")
    print("| sampler | UNet calls | mean | 95th pct | max |")
    print("|---|---|---|---|---|")
    for sampler in ("ddim", "dpmsolver++"):
        for steps in (4, 6, 8, 16):
            error = error_mm(chunk_positions(runner, batches, sampler, steps), converged)
            p95 = np.percentile(error, 95)
            print(f"| {sampler} | {steps} | {error.mean():.2f} | {p95:.1f} | {error.max():.1f} |")


if __name__ == "__main__":
    main()
