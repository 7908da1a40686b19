"""The checkpoint shipped under examples/ loads through LeRobot's own loader and picks in closed loop."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from lerobot_bboxpick.eval.rollout import PolicyRunner, rollout
from lerobot_bboxpick.shipped_checkpoints import SHIPPED_CHECKPOINT

CHECKPOINT = Path(__file__).resolve().parents[1] / SHIPPED_CHECKPOINT
# A test scene the shipped checkpoint picks in its suite table (examples/.../README.md), with the
# suite's policy seed and thread count, so the episode is the table's own.
SETTING, SEED = "grid_id", 10000


def test_the_shipped_checkpoint_is_small_and_inference_only():
    config = json.loads((CHECKPOINT / "config.json").read_text())
    assert config["type"] == "bbox_diffusion" and config["use_ema"] is False
    size_mb = (CHECKPOINT / "model.safetensors").stat().st_size / 1e6
    assert size_mb < 12, size_mb


@pytest.mark.slow
def test_the_shipped_checkpoint_picks_a_test_scene_in_closed_loop():
    torch.set_num_threads(1)  # as in the suite's workers: the same floating-point sums
    runner = PolicyRunner.from_pretrained(CHECKPOINT)  # LeRobot's get_policy_class + processors
    assert next(runner.policy.parameters()).dtype == torch.float32  # float16 file, float32 model
    result = rollout(runner, setting=SETTING, seed=SEED, policy_seed=SEED)
    assert result["outcome"] == "pick", result
    assert result["final_distance_m"] < 0.05
