"""Parts of the sampler run through ONNX Runtime (``--policy.onnx_inference=true``, the ``onnx`` extra).

This small UNet's call on a CPU is bound by per-op dispatch, not arithmetic: a TorchScript trace still
goes through PyTorch's dispatcher for each of its ops, while ONNX Runtime runs an exported graph with
its own (partly fused) kernels. The whole denoising loop (every UNet call and scheduler step of a chunk,
unrolled at its fixed timesteps) is one graph, so no Python runs between the steps; a guided loop, whose
guide is Python, runs each UNet call as its own graph (docs/benchmarks.md, "ONNX Runtime").
1-D convolutions are exported as 2-D ones over a height-1 map: ONNX Runtime's blocked (NCHWc) CPU kernels
only take 2-D convolutions (this UNet's call: 1.86 against 2.22 ms on one idle thread here, the same numbers).
A session holds a copy of the weights, so it is rebuilt when any parameter has changed in place since
the export (an EMA step, ``load_state_dict``): PyTorch bumps a tensor's version counter on every in-place
write.
"""

from __future__ import annotations

import io
import warnings
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from typing import Any

import torch
import torch.nn.functional as F
from torch import Tensor, nn


def require_onnxruntime() -> Any:
    """ONNX Runtime, after checking the extra's other half (torch's exporter writes with ``onnx``)."""
    try:
        import onnx  # noqa: F401
        import onnxruntime
    except ImportError as err:  # an optional extra: say which
        raise ImportError(
            f"onnx_inference=true needs {err.name}: pip install 'lerobot_bboxpick[onnx]'"
        ) from err
    return onnxruntime


class _Conv1dAs2d(nn.Module):
    """A 1-D (transposed) convolution computed as a 2-D one over a height-1 map (the original's weights)."""

    def __init__(self, conv: nn.Conv1d | nn.ConvTranspose1d) -> None:
        super().__init__()
        self.conv = conv

    def forward(self, x: Tensor) -> Tensor:
        c = self.conv
        weight, bias = c.weight.unsqueeze(2), c.bias
        if isinstance(c, nn.ConvTranspose1d):
            y = F.conv_transpose2d(
                x.unsqueeze(2), weight, bias, (1, c.stride[0]), (0, c.padding[0]),
                (0, c.output_padding[0]), c.groups, (1, c.dilation[0]),
            )  # fmt: skip
        else:
            y = F.conv2d(
                x.unsqueeze(2),
                weight,
                bias,
                (1, c.stride[0]),
                (0, c.padding[0]),
                (1, c.dilation[0]),
                c.groups,
            )
        return y.squeeze(2)


@contextmanager
def convolutions_as_2d(module: nn.Module) -> Iterator[nn.Module]:
    """``module`` with every zero-padded 1-D (transposed) convolution computed as a 2-D one, for the
    export; the original submodules are back on exit (the parameters are the same tensors throughout)."""
    swapped = []
    for parent in module.modules():
        for name, child in parent.named_children():
            if isinstance(child, nn.Conv1d | nn.ConvTranspose1d) and child.padding_mode == "zeros":
                swapped.append((parent, name, child))
    try:
        for parent, name, child in swapped:
            setattr(parent, name, _Conv1dAs2d(child))
        yield module
    finally:
        for parent, name, child in swapped:
            setattr(parent, name, child)


class OnnxModule:
    """``module(*inputs)`` for inputs shaped like the example ones, run by an ONNX Runtime CPU session.

    The module is traced (its Python control flow and any tensor that does not derive from the inputs
    become constants of the graph) and must return one tensor. ``convs_as_2d=False`` exports 1-D
    convolutions as they are (for comparison: docs/benchmarks/probe_onnx_conv2d.py)."""

    def __init__(self, module: nn.Module, inputs: dict[str, Tensor], *, convs_as_2d: bool = True) -> None:
        ort = require_onnxruntime()
        self._input_names = tuple(inputs)
        self._parameters = list(module.parameters())
        self._versions = self._weight_versions()
        graph = io.BytesIO()
        export_module = convolutions_as_2d(module) if convs_as_2d else nullcontext(module)
        with torch.no_grad(), warnings.catch_warnings(), export_module:
            # The TorchScript-based exporter's deprecation notice and its tracer's notes on constants.
            warnings.simplefilter("ignore")
            torch.onnx.export(
                module,
                tuple(inputs.values()),
                graph,
                input_names=list(self._input_names),
                output_names=["output"],
                dynamo=False,  # the dynamo exporter needs onnxscript, which nothing else here uses
                opset_version=17,
            )
        options = ort.SessionOptions()
        # The caller's torch thread budget (a suite worker sets 1): two pools would oversubscribe.
        options.intra_op_num_threads = torch.get_num_threads()
        options.inter_op_num_threads = 1
        # ORT's workers busy-wait between runs by default, taking the cores from the torch ops (encoder,
        # scheduler) that run between the graph's runs.
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        options.log_severity_level = 3  # errors only: no optimizer notes on the console
        self._session = ort.InferenceSession(graph.getvalue(), options, providers=["CPUExecutionProvider"])

    def _weight_versions(self) -> tuple[int, ...]:
        return tuple(p._version for p in self._parameters)

    @property
    def stale(self) -> bool:
        """Whether a parameter was written in place since the export (the session's copy is old)."""
        return self._weight_versions() != self._versions

    def __call__(self, *inputs: Tensor) -> Tensor:
        """The module's output for ``inputs`` (CPU float32/long tensors, in the example inputs' order)."""
        feeds = {name: value.detach().numpy() for name, value in zip(self._input_names, inputs, strict=True)}
        return torch.from_numpy(self._session.run(None, feeds)[0])
