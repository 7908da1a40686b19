"""``--policy.sampler``: DPM-Solver++ integrates the same sampling ODE as DDIM with another integrator."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from lerobot_bboxpick.eval.rollout import PolicyRunner
from lerobot_bboxpick.eval.sampler_error import chunk_positions, error_mm
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.shipped_checkpoints import FIRST_SHIPPED_CHECKPOINT
from lerobot_bboxpick.sim.env import LegoPickEnv

CHECKPOINT = Path(__file__).resolve().parents[1] / FIRST_SHIPPED_CHECKPOINT


def test_dpm_solver_converges_but_errs_more_than_ddim_at_few_steps():
    """The shipped policy's chunks against its 50-step DDIM chunk from the same noise, on four validation
    scenes' first observations (docs/benchmarks.md): DPM-Solver++ converges with more calls, yet at 6 calls
    it lands further off than DDIM, which is why the shipped config keeps DDIM."""
    torch.set_num_threads(1)
    runner = PolicyRunner.from_pretrained(CHECKPOINT)
    batches = []
    for setting, seed in (("random_id", 5000), ("grid_ood", 5001), ("pile_id", 5002), ("identical_4", 5003)):
        env = LegoPickEnv(setting=setting)
        observation, info = env.reset(seed=seed)
        batches.append(runner.observation_batch(observation, info["task"]))
        env.close()
    converged = chunk_positions(runner, batches, "ddim", 50)
    error = {
        (sampler, steps): error_mm(chunk_positions(runner, batches, sampler, steps), converged).mean()
        for sampler in ("ddim", "dpmsolver++")
        for steps in (6, 16)
    }
    assert error["dpmsolver++", 16] < 0.3 * error["dpmsolver++", 6], error  # measured 0.42 vs 2.0
    assert error["dpmsolver++", 6] > 1.5 * error["ddim", 6], error  # measured 2.0 vs 0.93


def test_an_unknown_sampler_names_the_field_and_the_choices():
    assert BboxDiffusionConfig().sampler == "ddim"
    with pytest.raises(ValueError, match="sampler='euler' is not one of ddim, dpmsolver\\+\\+"):
        BboxDiffusionConfig(sampler="euler")
