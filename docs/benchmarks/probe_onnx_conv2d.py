"""Probe: one UNet call of the shipped design through ONNX Runtime, exported with 1-D convolutions as they
are and as 2-D ones over a height-1 map (what ``OnnxModule`` exports), timed alternately on one thread.

    python docs/benchmarks/probe_onnx_conv2d.py   # on an idle machine
"""

import time

import numpy as np
import torch

from lerobot_bboxpick.apps.bench import _lever_policy
from lerobot_bboxpick.policies.bbox_diffusion.onnx_runtime import OnnxModule

torch.set_num_threads(1)  # OnnxModule's session takes torch's thread count
policy = _lever_policy({"image_size": 64, "n_obs_steps": 1}).eval()
model = policy.ema_model
obs = {"observation.images.wrist": torch.rand(1, 1, 3, 224, 224), "observation.state": torch.rand(1, 1, 10)}
obs["observation.bbox"] = torch.tensor([[[0.4, 0.4, 0.5, 0.5]]])
with torch.no_grad():
    cond = model.global_condition(*model._inputs(obs))
noise = torch.randn(1, model.config.horizon, 10)
inputs = {"sample": noise, "timestep": torch.tensor([45]), "global_cond": cond}
sessions = {
    "1-D convolutions": OnnxModule(model.unet, inputs, convs_as_2d=False),
    "2-D convolutions": OnnxModule(model.unet, inputs),
}
outs = [s(*inputs.values()) for s in sessions.values()]
print(f"largest difference between the two graphs: {(outs[0] - outs[1]).abs().max():.1e}")
times: dict[str, list[float]] = {name: [] for name in sessions}
for _ in range(300):
    for name, s in sessions.items():
        t0 = time.perf_counter()
        s(*inputs.values())
        times[name].append(time.perf_counter() - t0)
for name, t in times.items():
    print(f"{name}: {1000 * np.median(t):.2f} ms per UNet call (median of 300)")
