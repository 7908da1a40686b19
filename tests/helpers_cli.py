"""Test helpers for LeRobot's CLIs in subprocesses: their environment and a tiny bbox_diffusion."""

from __future__ import annotations

import os

TINY_BBOX_DIFFUSION = [  # a policy small enough to train a few steps in seconds on a CPU
    "--policy.type=bbox_diffusion",
    "--policy.device=cpu",
    "--policy.backbone=resnet10t",
    "--policy.image_size=64",
    "--policy.down_dims=[32,64]",
    "--policy.diffusion_step_embed_dim=32",
    "--policy.num_inference_steps=4",
]


def cli_env() -> dict:
    """The environment of a CLI subprocess: headless rendering, no Hub access, two threads."""
    return {**os.environ, "MUJOCO_GL": "egl", "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "2"}
