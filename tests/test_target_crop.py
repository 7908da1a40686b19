"""The target view: windows around the box, magnified crops, jitter bounds, and the policy with it."""

import pytest
import torch

from lerobot_bboxpick.apps.bench import _policy_features
from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import BboxDiffusionConfig
from lerobot_bboxpick.policies.bbox_diffusion.encoder import PairedAugment
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy
from lerobot_bboxpick.policies.bbox_diffusion.target_crop import (
    TargetView,
    crop_windows,
    target_windows,
)
from lerobot_bboxpick.rl.modeling_iql_critic import PolicyObservationEncoder

SIZE = 224
BOX = torch.tensor([[100 / SIZE, 100 / SIZE, 110 / SIZE, 106 / SIZE]])  # 10 x 6 px around (105, 103)
OPTIONS = {"backbone": "resnet18", "pretrained": False, "pooling": "spatial_softmax", "group_norm": True}


def _scene_with_a_red_patch() -> torch.Tensor:
    """A grey 224 px image with a red 10 x 6 px patch exactly under ``BOX``."""
    image = torch.full((1, 3, SIZE, SIZE), 0.5)
    image[:, :, 100:106, 100:110] = torch.tensor([1.0, 0.0, 0.0])[:, None, None]
    return image


def _red(crop: torch.Tensor) -> torch.Tensor:
    """Where a crop ``(..., 3, h, w)`` is mostly red: ``(..., h, w)`` bool."""
    return (crop[..., 0, :, :] > 0.75) & (crop[..., 1, :, :] < 0.25)


def test_windows_are_context_times_the_longer_side_centred_on_the_box():
    windows = target_windows(
        torch.cat([BOX, torch.zeros(1, 4), torch.tensor([[0.5, 0.5, 0.501, 0.501]])]), SIZE, SIZE, 3.0, 0.1
    )
    # 3 x 10 px around the box's centre (105, 103).
    assert torch.allclose(windows[0], torch.tensor([90.0, 88.0, 120.0, 118.0]), atol=1e-4)
    # An empty box ("not in view") gives the whole image.
    assert torch.allclose(windows[1], torch.tensor([0.0, 0.0, SIZE, SIZE]))
    # A sub-pixel box gets the minimum side: 0.1 of 224 px.
    assert windows[2, 2] - windows[2, 0] == pytest.approx(22.4, abs=1e-3)


def test_the_crop_magnifies_the_target_where_the_policy_image_cannot_resolve_it():
    """At 48 px the 10 px patch (a third of the 30 px window) spans 16 px: 4.8x its size in the 224 px
    frame and 14x its size in the 64 px policy image, where it is 3 px wide."""
    image = _scene_with_a_red_patch()
    windows = target_windows(BOX, SIZE, SIZE, 3.0, 0.1)
    crop = crop_windows(image, windows, 48)[0]
    cols = _red(crop).any(0).nonzero().flatten()
    rows = _red(crop).any(1).nonzero().flatten()
    assert cols.max() - cols.min() + 1 == pytest.approx(16, abs=1)
    assert rows.max() - rows.min() + 1 == pytest.approx(9.6, abs=1)
    assert (cols.float().mean() - 23.5).abs() <= 0.5  # centred
    small, _ = PairedAugment(color_jitter=(0, 0, 0, 0)).eval()(image, None, out_size=64)
    assert _red(small[0]).any(0).sum() <= 3


def test_training_jitter_keeps_the_target_near_the_centre_and_eval_is_exact():
    view = TargetView(48, 3.0, 0.1, OPTIONS, color_jitter=(0.0, 0.0, 0.0, 0.0))
    images = _scene_with_a_red_patch()[:, None].expand(64, 1, 3, SIZE, SIZE)
    boxes = BOX[:, None].expand(64, 1, 4)
    view.eval()
    assert torch.equal(view.crops(images, boxes), view.crops(images, boxes))
    view.train()
    crops = view.crops(images, boxes)[:, 0]
    red = _red(crops).float()
    xs = torch.arange(48.0)
    centre_x = (red.sum(1) * xs).sum(1) / red.sum((1, 2))
    widths = red.any(1).sum(1).float()
    # Shift <= 10% of the side (4.8 px of 48), scale within 1.15x (16 px -> 13.9-18.4 px).
    assert (centre_x - 23.5).abs().max() <= 4.8 + 1.0
    assert widths.min() >= 13 and widths.max() <= 19.5
    assert widths.std() > 0.5 and centre_x.std() > 0.5  # it does jitter


def _policy(**overrides) -> BboxDiffusionPolicy:
    torch.manual_seed(0)
    inputs, outputs = _policy_features(image_size=96)
    small = {"image_size": 64, "n_obs_steps": 1}
    config = BboxDiffusionConfig(
        device="cpu", input_features=inputs, output_features=outputs, **small, **overrides
    )
    return BboxDiffusionPolicy(config)


def _batch(b: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    return {
        "observation.images.wrist": torch.rand(b, 1, 3, 96, 96, generator=g),
        "observation.state": torch.rand(b, 1, 10, generator=g),
        "observation.bbox": torch.tensor([0.3, 0.3, 0.4, 0.36]).expand(b, 1, 4),
        "action": torch.rand(b, 16, 10, generator=g),
    }


def test_the_policy_conditions_on_the_target_view_and_trains_it_with_the_backbone_lr():
    plain, viewed = _policy(), _policy(target_crop_size=48)
    extra = viewed.model.target_view.out_dim
    assert extra == 64  # 32 spatial-softmax keypoints
    batch = _batch(2)
    inputs = viewed.model._inputs(batch)
    width = plain.model.global_condition(*inputs).shape[-1]
    assert viewed.model.global_condition(*inputs).shape[-1] == width + extra
    # Pixels inside the target's window change the condition; pixels far from it reach only the main image.
    viewed.eval()
    ref = viewed.model.global_condition(*inputs)
    near = {k: v.clone() for k, v in batch.items()}
    near["observation.images.wrist"][..., 30:33, 30:36] = 1.0
    far = {k: v.clone() for k, v in batch.items()}
    far["observation.images.wrist"][..., 80:83, 80:86] = 1.0
    view_part = slice(viewed.model.encoder.out_dim, viewed.model.encoder.out_dim + extra)

    def view_delta(changed: dict) -> torch.Tensor:
        return (viewed.model.global_condition(*viewed.model._inputs(changed)) - ref)[:, view_part]

    near_delta, far_delta = view_delta(near), view_delta(far)
    assert near_delta.abs().max() > 1e-3 and far_delta.abs().max() == 0
    # The view's backbone trains in the backbone group (encoder_lr_scale applies to it).
    viewed.train()
    loss, _ = viewed.forward(batch)
    loss.backward()
    view_params = viewed.model.target_view.encoder.backbone_parameters()
    assert sum(p.grad.abs().sum() for p in view_params if p.grad is not None) > 0
    backbone_group = {id(p) for p in viewed.get_optim_params()[0]["params"]}
    assert all(id(p) in backbone_group for p in view_params)


def test_the_critic_encodes_observations_through_the_same_target_view(tmp_path):
    policy = _policy(target_crop_size=48).eval()
    batch = {k: v for k, v in _batch(3).items() if k != "action"}
    encoder = PolicyObservationEncoder(policy.model).eval()
    expected = policy.model.global_condition(*policy.model._inputs(batch))
    assert encoder.out_dim == expected.shape[-1]
    assert torch.equal(encoder(batch), expected)
    # A saved checkpoint loads with its target view's weights: the same chunk from the same noise.
    policy.save_pretrained(tmp_path)
    loaded = BboxDiffusionPolicy.from_pretrained(tmp_path).eval()
    assert loaded.config.target_crop_size == 48
    g1, g2 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    chunk = policy.predict_action_chunk(batch, generator=g1)
    assert torch.allclose(loaded.predict_action_chunk(batch, generator=g2), chunk, atol=1e-5)


def test_bad_target_view_options_name_the_field():
    with pytest.raises(ValueError, match="target_crop_size=8 must be 0 \\(off\\) or in \\[16, 512\\]"):
        BboxDiffusionConfig(target_crop_size=8)
    with pytest.raises(ValueError, match="bbox_mode must be 'mask' or 'lowdim'"):
        BboxDiffusionConfig(target_crop_size=48, bbox_mode="none")
    with pytest.raises(ValueError, match="target_crop_context=0.5 must be >= 1"):
        BboxDiffusionConfig(target_crop_context=0.5)
