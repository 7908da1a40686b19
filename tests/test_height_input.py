"""The height input (``height_input``): the gripper's height above the table reaches the policy's condition,
which UMI's relative poses alone cannot carry for a one-frame policy."""

import numpy as np
import pytest
import torch

from lerobot_bboxpick.apps.bench import _lever_policy
from lerobot_bboxpick.geometry import mat_to_pose9
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig


def _model(**overrides):
    """A randomly initialised one-frame 64 px policy's model (the shipped design), in eval mode."""
    return _lever_policy({"image_size": 64, "n_obs_steps": 1, **overrides}).eval().model


def _condition(model, tcp_z: float) -> torch.Tensor:
    """The global condition of one observation: the same picture and box, the TCP at ``tcp_z`` metres."""
    pose = np.eye(4)
    pose[:3, 3] = (0.45, 0.0, tcp_z)
    state = torch.tensor([*mat_to_pose9(pose), 0.08], dtype=torch.float32).view(1, 1, 10)
    image = torch.rand(1, 1, 3, 64, 64, generator=torch.Generator().manual_seed(2))
    bbox = torch.tensor([0.4, 0.4, 0.6, 0.6]).view(1, 1, 4)
    with torch.no_grad():
        return model.global_condition(image, state, bbox)


def test_height_reaches_the_condition_only_with_height_input():
    """Without it, a one-frame policy's condition is the same 2 cm and 20 cm above the table (its poses are
    relative to the current one); with it, one entry differs by the height change over the scale."""
    plain = _model()
    assert (_condition(plain, 0.02) - _condition(plain, 0.20)).abs().max() == 0
    model = _model(height_input=True, table_height=0.01, height_input_scale=0.15)
    low, high = _condition(model, 0.02), _condition(model, 0.20)
    assert low.shape[1] == _condition(plain, 0.02).shape[1] + 1
    differs = (low - high).abs() > 1e-6
    assert differs.sum() == 1
    assert float((high - low)[differs]) == pytest.approx(0.18 / 0.15, abs=1e-5)
    assert float(low[differs]) == pytest.approx((0.02 - 0.01) / 0.15, abs=1e-5)


def test_a_non_positive_height_scale_names_the_field():
    with pytest.raises(ValueError, match=r"height_input_scale=0\.0 must be > 0"):
        BboxDiffusionConfig(height_input=True, height_input_scale=0.0)


def test_mask_size_scale_reaches_the_condition_and_checks_its_value():
    """``mask_size_scale`` changes only the size entry of the condition (the box's other numbers and the
    picture's features stay); checkpoints saved before it existed load with "sqrt"; a wrong value names
    the field and the allowed values."""
    sqrt_cond = _condition(_model(height_input=True), 0.1)
    log_cond = _condition(_model(height_input=True, mask_size_scale="log"), 0.1)
    changed = torch.nonzero((sqrt_cond - log_cond).abs()[0] > 1e-6).flatten().tolist()
    assert len(changed) == 1  # the size of the same mask: ln(side) + 3 against 2 * side - 1
    side = (sqrt_cond[0, changed[0]].item() + 1) / 2
    assert side == pytest.approx(0.2 / 0.95, rel=0.02)  # the 0.2 box after the 95% centre crop
    assert log_cond[0, changed[0]].item() == pytest.approx(np.log(side) + 3, abs=1e-5)
    # The first shipped checkpoint's config predates the option.
    first = BboxDiffusionConfig.from_pretrained("examples/bbox_diffusion_lego_pick")
    assert first.mask_size_scale == "sqrt"
    with pytest.raises(ValueError, match=r"mask_size_scale='area' is not one of sqrt, log, log_wh"):
        BboxDiffusionConfig(mask_size_scale="area")


def test_log_width_and_height_add_one_entry_to_the_condition():
    """With "log_wh" the box's one size becomes two (its width and height on the log scale): the
    condition is one entry wider, and for the square 0.2 box both equal the "log" size."""
    log_cond = _condition(_model(height_input=True, mask_size_scale="log"), 0.1)
    wh_cond = _condition(_model(height_input=True, mask_size_scale="log_wh"), 0.1)
    assert wh_cond.shape[1] == log_cond.shape[1] + 1
    # the box's numbers end the condition: cx, cy, the size(s), visible (after the pose and the height)
    log_size = log_cond[0, -2].item()
    assert wh_cond[0, -3:-1].tolist() == pytest.approx([log_size, log_size], abs=0.03)
    assert wh_cond[0, -5:-3].tolist() == pytest.approx(log_cond[0, -4:-2].tolist(), abs=1e-6)  # the centre
    assert wh_cond[0, -1].item() == log_cond[0, -1].item() == 1.0  # visible
