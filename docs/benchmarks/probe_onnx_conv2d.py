"""Probe: one UNet call of the shipped design through ONNX Runtime, exported with 1-D convolutions as they
are and as 2-D ones over a height-1 map (what ``OnnxModule`` exports), timed alternately on one thread.

    python docs/benchmarks/probe_onnx_conv2d.py   # on an idle machine
"""

import io
import time
import warnings

import numpy as np
import onnxruntime as ort
import torch

from lerobot_bboxpick.apps.bench import _lever_policy
from lerobot_bboxpick.policies.bbox_diffusion.onnx_runtime import convolutions_as_2d

torch.set_num_threads(1)
policy = _lever_policy({"image_size": 64, "n_obs_steps": 1}).eval()
model = policy.ema_model
obs = {"observation.images.wrist": torch.rand(1, 1, 3, 224, 224), "observation.state": torch.rand(1, 1, 10)}
obs["observation.bbox"] = torch.tensor([[[0.4, 0.4, 0.5, 0.5]]])
with torch.no_grad():
    cond = model.global_condition(*model._inputs(obs))
inputs = (torch.randn(1, model.config.horizon, 10), torch.tensor([45]), cond)


def session(as_2d: bool) -> ort.InferenceSession:
    graph = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if as_2d:
            with convolutions_as_2d(model.unet):
                torch.onnx.export(model.unet, inputs, graph, input_names=["s", "t", "c"], dynamo=False)
        else:
            torch.onnx.export(model.unet, inputs, graph, input_names=["s", "t", "c"], dynamo=False)
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.log_severity_level = 3
    return ort.InferenceSession(graph.getvalue(), options, providers=["CPUExecutionProvider"])


sessions = {"1-D convolutions": session(False), "2-D convolutions": session(True)}
feeds = dict(zip(["s", "t", "c"], (x.numpy() for x in inputs), strict=True))
outs = [s.run(None, feeds)[0] for s in sessions.values()]
print(f"largest difference between the two graphs: {np.abs(outs[0] - outs[1]).max():.1e}")
times: dict[str, list[float]] = {name: [] for name in sessions}
for _ in range(300):
    for name, s in sessions.items():
        t0 = time.perf_counter()
        s.run(None, feeds)
        times[name].append(time.perf_counter() - t0)
for name, t in times.items():
    print(f"{name}: {1000 * np.median(t):.2f} ms per UNet call (median of 300)")
