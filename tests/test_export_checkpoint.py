"""bboxpick-export: the inference checkpoint holds the EMA weights (not the trained ones), loads through
LeRobot's loader unchanged, and float16 storage changes a chunk by well under a millimetre."""

import json

import pytest
import torch
from lerobot.policies.factory import make_pre_post_processors

from lerobot_bboxpick.apps.bench import _policy_features
from lerobot_bboxpick.apps.export_checkpoint import ExportConfig, export
from lerobot_bboxpick.eval.rollout import PolicyRunner
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A checkpoint whose trained weights differ from their EMA copy (as after training)."""
    torch.manual_seed(0)
    inputs, outputs = _policy_features()
    config = BboxDiffusionConfig(
        device="cpu", input_features=inputs, output_features=outputs, image_size=64, n_obs_steps=1
    )
    policy = BboxDiffusionPolicy(config)
    with torch.no_grad():
        for p in policy.model.parameters():
            p.add_(0.05 * torch.randn_like(p))
    path = tmp_path_factory.mktemp("ckpt") / "pretrained_model"
    policy.save_pretrained(path)
    pre, post = make_pre_post_processors(config, dataset_stats=None)
    pre.save_pretrained(path)
    post.save_pretrained(path)
    return path


def _chunk(path) -> torch.Tensor:
    policy = PolicyRunner.from_pretrained(path).policy
    g = torch.Generator().manual_seed(0)
    batch = {
        "observation.images.wrist": torch.rand(1, 1, 3, 224, 224, generator=g),
        "observation.state": torch.rand(1, 1, 10, generator=g),
        "observation.bbox": torch.tensor([[[0.4, 0.4, 0.5, 0.5]]]),
    }
    return policy.predict_action_chunk(batch, generator=torch.Generator().manual_seed(1))


def test_export_keeps_the_ema_weights_and_halves_storage(trained, tmp_path):
    full = export(ExportConfig(src=trained, dst=tmp_path / "fp32"))
    half = export(ExportConfig(src=trained, dst=tmp_path / "fp16", half=True))
    original = (trained / "model.safetensors").stat().st_size
    assert abs(full.stat().st_size / original - 0.5) < 0.01  # the EMA copy only
    assert abs(half.stat().st_size / original - 0.25) < 0.01
    config = json.loads((tmp_path / "fp16" / "config.json").read_text())
    assert config["use_ema"] is False and config["use_amp"] is False and config["pretrained_path"] is None

    reference = _chunk(trained)  # inference of the trained checkpoint uses its EMA weights
    assert torch.equal(_chunk(tmp_path / "fp32"), reference)
    assert (_chunk(tmp_path / "fp16") - reference)[..., :3].abs().max() < 1e-3  # metres
    raw = BboxDiffusionPolicy.from_pretrained(trained)  # the trained (non-EMA) weights differ
    pairs = zip(raw.model.parameters(), raw.ema_model.parameters(), strict=True)
    assert not all(torch.equal(a, b) for a, b in pairs)


def test_bad_sources_are_refused(tmp_path, trained):
    with pytest.raises(ValueError, match="is not a checkpoint folder"):
        ExportConfig(src=tmp_path, dst=tmp_path / "x")
    with pytest.raises(ValueError, match="must differ from src"):
        ExportConfig(src=trained, dst=trained)
    with pytest.raises(ValueError, match="num_inference_steps=0"):
        ExportConfig(src=trained, dst=tmp_path / "x", num_inference_steps=0)


def test_export_writes_a_given_step_count_and_keeps_the_trained_one_otherwise(trained, tmp_path):
    trained_steps = json.loads((trained / "config.json").read_text())["num_inference_steps"]
    export(ExportConfig(src=trained, dst=tmp_path / "kept"))
    export(ExportConfig(src=trained, dst=tmp_path / "more", num_inference_steps=trained_steps + 3))
    kept = BboxDiffusionPolicy.from_pretrained(tmp_path / "kept").config.num_inference_steps
    more = BboxDiffusionPolicy.from_pretrained(tmp_path / "more").config.num_inference_steps
    assert (kept, more) == (trained_steps, trained_steps + 3)
