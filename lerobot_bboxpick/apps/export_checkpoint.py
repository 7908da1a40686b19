"""``bboxpick-export``: a small inference checkpoint from a ``lerobot-train`` one (EMA weights only).

    bboxpick-export --src <run>/checkpoints/last/pretrained_model --dst examples/bbox_diffusion_lego_pick
    bboxpick-export ... --half=true        # weights stored as float16 (loaded back into float32)
    bboxpick-export ... --num_inference_steps=4   # the sampling its suite table was measured with

A trained ``bbox_diffusion`` checkpoint holds the trained weights *and* their EMA copy, which is what
inference uses. The export keeps only the EMA weights, written as the policy's own weights with
``use_ema=false`` in its config, so LeRobot's loader (``--policy.path``) runs it unchanged; the
processors (the saved ``ProcessorStep`` pipelines) are copied as they are. ``--half`` halves the file
again: float16 storage, loaded into the float32 model (PyTorch's ``load_state_dict`` casts), so inference
is unchanged apart from the rounding, which the suite table of the export checks.
"""

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import draccus
import torch
from safetensors.torch import load_file, save_file

WEIGHTS = "model.safetensors"
EMA_PREFIX = "ema_model."
MODEL_PREFIX = "model."


@dataclass
class ExportConfig:
    """Options of ``bboxpick-export``."""

    # A ``pretrained_model`` folder written by lerobot-train (config.json, model.safetensors, processors).
    src: Path = Path("outputs/train/checkpoints/last/pretrained_model")
    dst: Path = Path("outputs/export")
    # Store the weights as float16 (half the size); they load back into float32.
    half: bool = False
    # DDIM steps per chunk written into the export's config (the step count its table was measured at, when
    # the suite sampled with another than training's); None keeps the trained config's.
    num_inference_steps: int | None = None

    def __post_init__(self) -> None:
        self.src, self.dst = Path(self.src), Path(self.dst)
        if self.num_inference_steps is not None and self.num_inference_steps < 1:
            raise ValueError(f"num_inference_steps={self.num_inference_steps} must be a positive step count")
        if not (self.src / "config.json").is_file() or not (self.src / WEIGHTS).is_file():
            raise ValueError(f"src={self.src} is not a checkpoint folder (config.json and {WEIGHTS})")
        if self.dst.resolve() == self.src.resolve():
            raise ValueError(f"dst={self.dst} must differ from src (the export never overwrites its source)")


def ema_state_dict(weights: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The EMA weights renamed to the policy's own (``ema_model.x`` -> ``model.x``); a checkpoint trained
    without EMA keeps its ``model.x`` weights."""
    ema = {MODEL_PREFIX + k[len(EMA_PREFIX) :]: v for k, v in weights.items() if k.startswith(EMA_PREFIX)}
    return ema or {k: v for k, v in weights.items() if k.startswith(MODEL_PREFIX)}


def export(cfg: ExportConfig) -> Path:
    """Write the export into ``cfg.dst``; returns its weights file."""
    config = json.loads((cfg.src / "config.json").read_text())
    if not str(config.get("type", "")).startswith("bbox_diffusion"):
        raise ValueError(
            f"src={cfg.src} holds a {config.get('type')!r} policy; bboxpick-export takes bbox_diffusion"
        )
    weights = ema_state_dict(load_file(cfg.src / WEIGHTS))
    if cfg.half:
        weights = {k: v.half() if v.is_floating_point() else v for k, v in weights.items()}
    cfg.dst.mkdir(parents=True, exist_ok=True)
    for f in cfg.src.iterdir():  # processors and their state; the training config stays behind
        if f.is_file() and f.name not in (WEIGHTS, "config.json", "train_config.json"):
            shutil.copy2(f, cfg.dst / f.name)
    config["use_ema"] = False  # the EMA weights *are* the weights now
    # Training-only facts: bf16 autocast (lerobot-eval would open it around inference, ~70x slower on a
    # CPU that emulates bf16) and the folder it was loaded from on the training machine.
    config["use_amp"] = False
    config["pretrained_path"] = None
    if cfg.num_inference_steps is not None:
        config["num_inference_steps"] = cfg.num_inference_steps
    (cfg.dst / "config.json").write_text(json.dumps(config, indent=4))
    out = cfg.dst / WEIGHTS
    save_file({k: v.contiguous() for k, v in weights.items()}, out)
    return out


@draccus.wrap()
def main(cfg: ExportConfig) -> None:
    """Entry point of ``bboxpick-export``."""
    out = export(cfg)
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB); run it with --policy.path={cfg.dst}")
