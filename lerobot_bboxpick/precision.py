"""Which training precision pays on this machine: bf16 autocast only where the CPU runs bf16 natively.

On CPUs with native bf16 (AVX512-BF16 or AMX) ``--policy.use_amp=true`` trains this policy ~2.5x
faster; on CPUs without it (e.g. a Zen 3 EPYC: AVX2, no AVX-512) oneDNN emulates bf16 and a bf16 matmul
is ~70x slower than float32 (FACTS.md section 7), so autocast there turns a 15-minute run into hours.
The main job, the recipe script and the benchmark all ask this module.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PrecisionChoice:
    """The decision and the reason, printed by the callers."""

    use_amp: bool
    reason: str

    @property
    def name(self) -> str:
        """``bf16 autocast`` or ``float32``."""
        return "bf16 autocast" if self.use_amp else "float32"


def cpu_has_native_bf16() -> bool:
    """Does oneDNN run bf16 natively on this CPU (``torch.ops.mkldnn._is_mkldnn_bf16_supported``)?"""
    import torch

    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):  # a torch build without oneDNN: no native bf16 path
        return False


def choose_precision(requested: bool | None = None, device: str = "cpu") -> PrecisionChoice:
    """``requested`` None: bf16 autocast where native, else float32; True/False: the user's choice
    (with a warning in the reason when bf16 is asked for on a CPU that emulates it)."""
    if device != "cpu":
        use = True if requested is None else requested
        return PrecisionChoice(use, f"device {device}: {'autocast' if use else 'float32'} as asked")
    native = cpu_has_native_bf16()
    capability = _cpu_capability()
    if requested is None:
        if native:
            return PrecisionChoice(True, f"this CPU runs bf16 natively ({capability}): bf16 autocast")
        return PrecisionChoice(
            False, f"this CPU has no native bf16 ({capability}): bf16 would be emulated, far slower; float32"
        )
    if requested and not native:
        return PrecisionChoice(
            True, f"bf16 autocast as asked, although this CPU emulates bf16 ({capability})"
        )
    return PrecisionChoice(bool(requested), f"{'bf16 autocast' if requested else 'float32'} as asked")


def _cpu_capability() -> str:
    import torch

    try:
        return f"torch CPU capability {torch.backends.cpu.get_cpu_capability()}"
    except AttributeError:
        return "torch CPU capability unknown"
