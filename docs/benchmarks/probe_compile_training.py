"""Probe (2026-12-06): does torch.compile, or the encoder in channels-last layout, speed up the CPU preset's
float32 training step?

``python docs/benchmarks/probe_compile_training.py eager unet unet_encoder eager`` (or ``eager channels_last
eager``): the preset (96 px,
batch 32, random tensors, as ``bench --policies``) trained 12 steps per mode, eager first and last to
bracket the machine's drift; prints the first step (compilation) and the median of the last 10.
"""

import sys
import time

import numpy as np
import torch

from lerobot_bboxpick.apps.bench import _policy_features, _preset_optimizer, random_training_batch
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy

BATCH = 32


def train_rate(mode: str) -> None:
    """Print the first step's seconds and the median samples/s of the preset trained with ``mode``."""
    torch.manual_seed(0)
    inputs, outputs = _policy_features()
    batch = random_training_batch(BATCH)
    config = BboxDiffusionConfig(device="cpu", input_features=inputs, output_features=outputs, image_size=96)
    policy = BboxDiffusionPolicy(config)
    if mode in ("unet", "unet_encoder"):
        policy.model.unet = torch.compile(policy.model.unet)
    if mode == "unet_encoder":
        policy.model.encoder = torch.compile(policy.model.encoder)
    if mode == "channels_last":  # oneDNN's convolutions in NHWC: the backbone's weights and its input
        backbone = policy.model.encoder.backbone.to(memory_format=torch.channels_last)
        backbone.register_forward_pre_hook(
            lambda _, args: (args[0].contiguous(memory_format=torch.channels_last),)
        )
    optimiser = _preset_optimizer(policy)
    policy.train()
    times = []
    for _ in range(12):
        t0 = time.perf_counter()
        loss, _ = policy.forward(batch)
        loss.backward()
        optimiser.step()
        optimiser.zero_grad()
        policy.update()
        times.append(time.perf_counter() - t0)
    print(f"{mode}: first step {times[0]:.1f} s, {BATCH / np.median(times[2:]):.1f} samples/s", flush=True)


if __name__ == "__main__":
    for name in sys.argv[1:]:
        train_rate(name)
