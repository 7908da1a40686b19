"""Vision side of bbox_diffusion: bbox masks, the non-disruptive 4th channel, paired augmentation."""

import copy
import math

import huggingface_hub.constants
import pytest
import timm
import torch
import torch.nn.functional as F
from torchvision.transforms.v2 import functional as TF

from lerobot_bboxpick.policies.bbox_diffusion.encoder import (
    MaskedImageEncoder,
    PairedAugment,
    _first_rgb_conv,
    _gray,
    _shift_hue,
    bbox_to_mask,
    color_jitter,
    expand_input_channels,
    mask_moments,
)

BACKBONES = [("vit_tiny_patch16_224", {"img_size": 96}), ("resnet10t", {})]  # resnet10t: nested stem conv1.0


@pytest.mark.parametrize(("name", "kwargs"), BACKBONES)
def test_expand_is_non_disruptive(name: str, kwargs: dict) -> None:
    torch.manual_seed(0)
    rgb_model = timm.create_model(name, pretrained=False, num_classes=0, **kwargs).eval()
    conv_name = _first_rgb_conv(rgb_model)
    old = rgb_model.get_submodule(conv_name)
    model = expand_input_channels(copy.deepcopy(rgb_model), extra=1)
    conv = model.get_submodule(conv_name)
    assert type(conv) is type(old) and conv.in_channels == 4 and conv.weight.shape[1] == 4
    assert torch.equal(conv.weight[:, :3], old.weight) and not conv.weight[:, 3:].any()
    assert (conv.bias is None and old.bias is None) or torch.equal(conv.bias, old.bias)

    rgb, mask = torch.randn(2, 3, 96, 96), torch.rand(2, 1, 96, 96)
    with torch.no_grad():
        ref = rgb_model(rgb)
        out = model(torch.cat([rgb, mask], 1))
        assert torch.allclose(out, ref, atol=1e-6)
        conv.weight[:, 3:] = 0.05 * torch.randn_like(conv.weight[:, 3:])  # a trained mask channel matters
        assert not torch.allclose(model(torch.cat([rgb, mask], 1)), ref, atol=1e-3)


def test_encoder_mask_channel_starts_neutral_and_shapes() -> None:
    torch.manual_seed(0)
    enc3 = MaskedImageEncoder("vit_tiny_patch16_224", pretrained=False, image_size=96, use_mask=False).eval()
    torch.manual_seed(0)
    enc4 = MaskedImageEncoder("vit_tiny_patch16_224", pretrained=False, image_size=96, use_mask=True).eval()
    rgb, mask = torch.rand(2, 2, 3, 96, 96), (torch.rand(2, 2, 1, 96, 96) > 0.5).float()
    with torch.no_grad():
        out = enc4(rgb, mask)
        assert out.shape == (2, 2, enc4.out_dim) and enc4.out_dim == 192
        assert torch.allclose(out, enc3(rgb), atol=1e-6)
    with pytest.raises(ValueError, match="mask"):
        enc4(rgb)

    enc = MaskedImageEncoder("resnet10t", pretrained=False, image_size=64, use_mask=True, feature_dim=32)
    assert enc(torch.rand(3, 3, 64, 64), torch.zeros(3, 1, 64, 64)).shape == (3, 32) and enc.out_dim == 32
    backbone, other = enc.parameter_groups()
    assert len(other) == 2 and {id(p) for p in backbone}.isdisjoint(id(p) for p in other)
    assert len(backbone) + len(other) == len(list(enc.parameters()))


def test_pretrained_offline_error_is_clear(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)  # read once at import
    try:
        enc = MaskedImageEncoder("resnet10t", pretrained=True, image_size=64, use_mask=True)
    except RuntimeError as e:
        assert "pretrained=False" in str(e) and "resnet10t" in str(e)
    else:  # weights were in the local cache
        assert enc.out_dim == 512


def test_bbox_to_mask_area_edges_and_shapes() -> None:
    torch.manual_seed(0)
    h, w = 48, 96  # non-square: catches swapped axes
    lo = torch.rand(5, 3, 2, dtype=torch.float64) * 0.7
    boxes = torch.cat([lo, lo + torch.rand(5, 3, 2, dtype=torch.float64) * 0.3], -1)
    mask = bbox_to_mask(boxes, h, w)
    assert mask.shape == (5, 3, 1, h, w) and mask.dtype == torch.float64
    area = (boxes[..., 2] - boxes[..., 0]) * (boxes[..., 3] - boxes[..., 1])
    assert torch.allclose(mask.sum((-3, -2, -1)), area * h * w, atol=1e-4)
    assert mask.min() >= 0 and mask.max() <= 1

    # A 3 px box at sub-pixel offsets keeps its full area (fractional edge pixels).
    tiny = bbox_to_mask(torch.tensor([10.3, 20.6, 13.3, 23.6]) / 96, 96, 96)[0]
    assert abs(tiny.sum().item() - 9.0) < 1e-4 and abs(tiny[20, 10].item() - 0.4 * 0.7) < 1e-5
    # Pixel-edge convention: x * width is a pixel edge, so an aligned box gives exactly those pixels.
    aligned = bbox_to_mask(torch.tensor([0.25, 0.5, 0.5, 0.75]), 8, 8)[0]
    expected = torch.zeros(8, 8)
    expected[4:6, 2:4] = 1
    assert torch.equal(aligned, expected)
    assert not bbox_to_mask(torch.zeros(2, 4), 32, 32).any()  # target not in view
    assert torch.equal(bbox_to_mask(torch.tensor([0.0, 0.0, 1.0, 1.0]), 7, 5), torch.ones(1, 7, 5))
    corner = bbox_to_mask(torch.tensor([0.9, 0.95, 1.0, 1.0]), 20, 10)[0]
    assert corner[19, 9] == 1 and abs(corner.sum().item() - 1.0) < 1e-5
    clipped = bbox_to_mask(torch.tensor([-0.1, 0.9, 0.2, 1.3]), 10, 10)[0]  # parts outside are cut
    assert abs(clipped.sum().item() - 2.0) < 1e-5


def _scene(n: int, size: int = 224) -> tuple[torch.Tensor, torch.Tensor]:
    """Grey images, each with one saturated square (a brick, 8-14 px); every 5th touches the border."""
    g = torch.Generator().manual_seed(1)
    colours = torch.tensor([[0.9, 0.1, 0.1], [0.1, 0.8, 0.2], [0.1, 0.2, 0.9], [0.9, 0.8, 0.1]])
    rgb = torch.full((n, 3, size, size), 0.5)
    boxes = torch.zeros(n, 4)
    for i in range(n):
        side = int(torch.randint(8, 15, (1,), generator=g))
        x0, y0 = (int(v) for v in torch.randint(0, size - side + 1, (2,), generator=g))
        if i % 5 == 0:
            x0 = 0 if i % 10 == 0 else size - side
        rgb[i, :, y0 : y0 + side, x0 : x0 + side] = colours[i % 4].view(3, 1, 1)
        boxes[i] = torch.tensor([x0, y0, x0 + side, y0 + side]) / size
    return rgb, boxes


def test_augment_keeps_mask_on_target() -> None:
    torch.manual_seed(0)
    rgb, boxes = _scene(50)
    mask = bbox_to_mask(boxes, 224, 224)
    aug = PairedAugment()
    out, out_mask = aug(rgb, mask, out_size=96)  # 50 independent crop and jitter draws
    assert out.shape == (50, 3, 96, 96) and out_mask.shape == (50, 1, 96, 96)
    # Jitter keeps grey grey and scales the square's chroma; resampling blends it with the background
    # (chroma ~ coverage), and the antialias kernel leaks at most 1/8 of it beyond the mask's support.
    chroma = out.amax(1, keepdim=True) - out.amin(1, keepdim=True)
    target = chroma > 0.15 * chroma.amax((1, 2, 3), keepdim=True).clamp(min=1e-3)
    seen = target.any(3).any(2).any(1)  # border squares may be cropped out entirely
    assert seen.sum() >= 45 and not out_mask[~seen].any()
    covered = (out_mask > 0) & target
    assert covered.sum() / target.sum() >= 0.99
    near = F.max_pool2d(target.float(), 5, stride=1, padding=2) > 0  # within 2 px of the target
    assert not out_mask[~near].any()  # the mask does not spill over the image
    scale = 96 / int(224 * 0.95)
    area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]) * (224 * scale) ** 2
    inside = (boxes[:, 0] > 0.06) & (boxes[:, 2] < 0.94) & (boxes[:, 1] > 0.06) & (boxes[:, 3] < 0.94)
    assert torch.allclose(out_mask.sum((1, 2, 3))[inside], area[inside], rtol=1e-4)  # exact area resampling
    background = out[:, :, :4, :4]  # jitter differs between samples
    assert not torch.allclose(background[:10], background[10:20])


def test_mask_moments_follow_the_crop() -> None:
    """The centroid of the augmented mask sits on the target's augmented pixels (crop-consistent), where
    the raw bbox centre is off by the crop shift (what broke the 4-number input in paper Exp. 6)."""
    torch.manual_seed(0)
    rgb, boxes = _scene(50)
    inside = (boxes[:, 0] > 0.06) & (boxes[:, 2] < 0.94) & (boxes[:, 1] > 0.06) & (boxes[:, 3] < 0.94)
    rgb, boxes = rgb[inside], boxes[inside]
    out, out_mask = PairedAugment()(rgb, bbox_to_mask(boxes, 224, 224), out_size=96)
    moments = mask_moments(out_mask)
    chroma = out.amax(1) - out.amin(1)  # (B, 96, 96): the coloured square, blurred by resampling
    weight = chroma / chroma.sum((1, 2), keepdim=True)
    centres = torch.linspace(-1 + 1 / 96, 1 - 1 / 96, 96)
    seen_x, seen_y = (weight.sum(1) * centres).sum(1), (weight.sum(2) * centres).sum(1)
    px = 2 / 96  # one output pixel in [-1, 1] units
    assert (moments[:, 0] - seen_x).abs().max() < 0.5 * px
    assert (moments[:, 1] - seen_y).abs().max() < 0.5 * px
    raw_x = boxes[:, 0] + boxes[:, 2] - 1  # the un-augmented bbox centre in [-1, 1]
    assert (raw_x - seen_x).abs().max() > 2 * px  # the crop moved the target, the raw numbers did not
    assert (moments[:, 3] == 1).all()
    area = ((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])) / 0.95**2
    assert torch.allclose((moments[:, 2] + 1) / 2, area.sqrt(), rtol=0.02)
    empty = mask_moments(torch.zeros(2, 1, 96, 96))
    assert empty.tolist() == [[0.0, 0.0, -1.0, -1.0]] * 2  # "not in view", never a made-up position


def test_augment_eval_deterministic_and_frames_share_draws() -> None:
    rgb, boxes = _scene(4)
    mask = bbox_to_mask(boxes, 224, 224)
    aug = PairedAugment().eval()
    a, b = aug(rgb, mask, 96), aug(rgb, mask, 96)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    crop = int(224 * 0.95)
    off = (224 - crop) // 2
    ref = F.interpolate(
        rgb[..., off : off + crop, off : off + crop], size=(96, 96), mode="bilinear", antialias=True
    )
    assert torch.allclose(a[0], ref.clamp(0, 1), atol=1e-6)
    moved = ((boxes * 224 - off) / crop).clamp(0, 1)  # the box through the centre crop
    assert torch.allclose(a[1], bbox_to_mask(moved, 96, 96), atol=1e-5)
    assert aug(rgb, None, 112)[1] is None

    aug.train()  # (B, T, ...) frames of one sample share the crop and the jitter
    frames, fmask = aug(rgb[:, None].expand(4, 2, 3, 224, 224), mask[:, None].expand(4, 2, 1, 224, 224), 96)
    assert frames.shape == (4, 2, 3, 96, 96) and fmask.shape == (4, 2, 1, 96, 96)
    assert torch.equal(frames[:, 0], frames[:, 1]) and torch.equal(fmask[:, 0], fmask[:, 1])


def test_color_jitter_matches_torchvision_ops() -> None:
    torch.manual_seed(0)
    x = torch.rand(4, 3, 16, 16)
    for shift in (0.05, -0.08, 0.5):
        assert torch.allclose(
            _shift_hue(x, torch.tensor(shift).view(1, 1, 1)), TF.adjust_hue(x, shift), atol=1e-5
        )
    assert torch.allclose(_gray(x), TF.rgb_to_grayscale(x), atol=1e-6)
    same = color_jitter(x[:1].expand(6, 3, 16, 16), (0.3, 0.4, 0.5, 0.08))  # per-sample factors
    assert all(not torch.allclose(same[0], same[i]) for i in range(1, 6))
    assert same.min() >= 0 and same.max() <= 1


def test_cpu_preset_encoder_keypoints_are_non_disruptive_and_follow_the_mask() -> None:
    """ResNet-18 stage 2 + GroupNorm + spatial softmax (the cpu preset): 4-channel == 3-channel output at
    init; the keypoints are image coordinates, so a trained mask channel moves them with the box."""
    kwargs = dict(
        pretrained=False, image_size=96, pooling="spatial_softmax", feature_stage=2, group_norm=True
    )
    torch.manual_seed(0)
    enc3 = MaskedImageEncoder("resnet18", use_mask=False, **kwargs).eval()
    torch.manual_seed(0)
    enc4 = MaskedImageEncoder("resnet18", use_mask=True, **kwargs).eval()
    assert enc4.out_dim == 64 and not any(isinstance(m, torch.nn.BatchNorm2d) for m in enc4.modules())
    rgb = torch.rand(2, 3, 96, 96)
    mask = bbox_to_mask(torch.tensor([[0.1, 0.1, 0.2, 0.2], [0.7, 0.6, 0.8, 0.7]]), 96, 96)
    with torch.no_grad():
        assert torch.allclose(enc4(rgb, mask), enc3(rgb), atol=1e-6)
        # Make the mask channel dominate: the expected keypoint positions then sit on the box.
        conv = enc4.backbone.get_submodule("conv1")  # expanded: now 4 input channels
        conv.weight[:, 3:] = 50.0
        keypoints = enc4(torch.zeros_like(rgb), mask).view(2, -1, 2).mean(1)  # (x, y) in [-1, 1]
    centres = torch.tensor([[0.15, 0.15], [0.75, 0.65]]) * 2 - 1
    assert (keypoints[1] - keypoints[0]).dot(centres[1] - centres[0]) > 0  # they move the way the box does
    with pytest.raises(ValueError, match="pooling"):
        MaskedImageEncoder("resnet18", pretrained=False, image_size=96, use_mask=True, pooling="max")


def test_log_mask_size_keeps_a_small_box_distance_apart() -> None:
    """A stacked pile brick at the close is 8% larger in the wrist image than one on the table (its top is
    19 mm nearer a camera ~220 mm away). After the 64 px eval crop the log size keeps that as ln(1.085),
    the sqrt size squeezes it below 0.015, and an unknown scale names the allowed ones."""
    centre, side = 0.5, 0.060  # the brick's box at the close: sqrt(area) 6% of the image side
    boxes = torch.tensor(
        [[centre - s / 2, centre - s / 2, centre + s / 2, centre + s / 2] for s in (side, side * 1.085)]
    )
    _, mask = PairedAugment().eval()(torch.zeros(2, 3, 224, 224), bbox_to_mask(boxes, 224, 224), out_size=64)
    log_size = mask_moments(mask, "log")[:, 2]
    sqrt_size = mask_moments(mask, "sqrt")[:, 2]
    assert (log_size[1] - log_size[0]).item() == pytest.approx(0.0816, abs=0.002)
    assert 0 < (sqrt_size[1] - sqrt_size[0]).item() < 0.015
    # ln(0.060 / 0.95) + 3: the crop keeps 95% of the side, so the box fills 6.3% of it
    assert log_size[0].item() == pytest.approx(0.238, abs=0.005)
    assert torch.equal(
        mask_moments(torch.zeros(1, 1, 64, 64), "log")[0], torch.tensor([0.0, 0.0, -1.0, -1.0])
    )
    with pytest.raises(ValueError, match=r"size_scale='area' is not one of sqrt, log, log_wh"):
        mask_moments(mask, "area")


def test_log_width_and_height_tell_a_turned_box_from_a_nearer_one() -> None:
    """A nearer brick's box grows on both sides alike, a turned brick's box grows wider than tall: with
    "log_wh" both sides are measured apart after the 64 px eval crop (within 7% of the drawn side at
    6% of the image), so the 8.5% nearer box moves both by about ln(1.085) and a 2:1 box of the same area
    moves them apart by about ln(2); an empty mask says "not in view"."""

    def box(width: float, height: float) -> list[float]:
        return [0.5 - width / 2, 0.5 - height / 2, 0.5 + width / 2, 0.5 + height / 2]

    side = 0.060
    boxes = torch.tensor(
        [box(side, side), box(side * 1.085, side * 1.085), box(side * 2**0.5, side / 2**0.5)]
    )
    _, mask = PairedAugment().eval()(torch.zeros(3, 3, 224, 224), bbox_to_mask(boxes, 224, 224), out_size=64)
    moments = mask_moments(mask, "log_wh")
    assert moments.shape == (3, 5)
    sides = (moments[:, 2:4] - 3).exp() * 0.95  # back to fractions of the uncropped image's side
    assert sides[0].tolist() == pytest.approx([side, side], rel=0.07)
    nearer = (moments[1, 2:4] - moments[0, 2:4]).tolist()
    assert nearer == pytest.approx([0.0816, 0.0816], abs=0.02)
    assert (moments[2, 2] - moments[2, 3]).item() == pytest.approx(math.log(2), abs=0.15)
    assert moments[:, 4].tolist() == [1.0, 1.0, 1.0]
    hidden = mask_moments(torch.zeros(1, 1, 64, 64), "log_wh")[0]
    assert hidden.tolist() == [0.0, 0.0, -1.0, -1.0, -1.0]
