"""Vision side of the bbox-conditioned policy: bbox -> mask, RGB+mask timm encoder, paired augmentation.

Paper section 4.1: the target bbox becomes a mask image aligned with the wrist RGB, concatenated as a
4th channel; the backbone's first conv (ViT patch embedding / CNN stem) grows from 3 to 4 input
channels with the RGB weights copied and the mask weights zero-initialised, so the expanded network
initially computes exactly what the RGB network computed ("non-disruptive").

Order of operations in the policy: ``bbox_to_mask`` at the stored image resolution (e.g. 224), then
``PairedAugment`` crops/resizes image and mask together (so the mask moves with the pixels; crop
augmentation is what broke the 4-number bbox input in the paper), then ``MaskedImageEncoder``.
"""

from __future__ import annotations

import copy
import math

import timm
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from lerobot_bboxpick.policies.bbox_diffusion.configuration_bbox_diffusion import MASK_SIZE_SCALES


def bbox_to_mask(bbox: Tensor, height: int, width: int) -> Tensor:
    """Rasterise normalised ``[x0, y0, x1, y1]`` boxes into area-coverage masks.

    Pixel ``(i, j)`` covers ``[j, j+1] x [i, i+1]`` in pixel units (``x * width`` is a pixel edge); its
    value is the fraction of that pixel covered by the box, so ``mask.sum() == box area * H * W`` for
    boxes inside the image and sub-pixel boxes stay visible. Parts outside the image are clipped; a
    zero (or empty / inverted) box gives an all-zero mask ("target not in view").

    Args:
        bbox: ``(..., 4)`` boxes in [0, 1] image coordinates.
        height: mask height in pixels.
        width: mask width in pixels.

    Returns:
        ``(..., 1, height, width)`` float mask in [0, 1] (dtype of ``bbox`` if floating, else float32).
    """
    bbox = torch.as_tensor(bbox)
    if bbox.shape[-1] != 4:
        raise ValueError(f"bbox must have shape (..., 4), got {tuple(bbox.shape)}")
    if not bbox.is_floating_point():
        bbox = bbox.float()

    def cover(lo: Tensor, hi: Tensor, n: int) -> Tensor:  # (...,) -> (..., n) per-pixel 1-D coverage
        edges = torch.arange(n, dtype=bbox.dtype, device=bbox.device)
        return (torch.minimum(hi[..., None] * n, edges + 1) - torch.maximum(lo[..., None] * n, edges)).clamp(
            0, 1
        )

    cx = cover(bbox[..., 0], bbox[..., 2], width)
    cy = cover(bbox[..., 1], bbox[..., 3], height)
    return (cy[..., :, None] * cx[..., None, :]).unsqueeze(-3)


# The log scale's offset: the size is ln(sqrt(area fraction)) + 3, clamped to +-3 (a box of 0.25% of
# the image side is -3; lego_pick's bricks seen from the wrist span about -0.8 to +0.2).
LOG_SIZE_OFFSET = 3.0


def mask_moments_dim(size_scale: str) -> int:
    """How many numbers ``mask_moments`` returns per mask for ``size_scale``: 5 with "log_wh" (width and
    height apart), else 4."""
    if size_scale not in MASK_SIZE_SCALES:
        raise ValueError(f"size_scale={size_scale!r} is not one of {', '.join(MASK_SIZE_SCALES)}")
    return 5 if size_scale == "log_wh" else 4


def _log_size(side: Tensor) -> Tensor:
    return (side.clamp(min=1e-12).log() + LOG_SIZE_OFFSET).clamp(-LOG_SIZE_OFFSET, LOG_SIZE_OFFSET)


def mask_moments(mask: Tensor, size_scale: str = "sqrt") -> Tensor:
    """Centroid, size and visibility of (augmented) masks: ``(..., 1, H, W) -> (..., 4)`` (``(..., 5)``
    with ``size_scale="log_wh"``).

    Returns ``[cx, cy, size, visible]``: the mass-weighted centre in [-1, 1] image coordinates (x right,
    y down, the convention of LeRobot's ``SpatialSoftmax`` keypoints), the size, and ``visible`` = 1 if
    the mask has any mass else -1 (then centre and sizes are 0 and -1: "target not in view", never a
    made-up position). ``size_scale`` "sqrt": ``2 * sqrt(area fraction) - 1`` in [-1, 1]; "log":
    ``ln(sqrt(area fraction)) + 3`` clamped to [-3, 3], where a box 8% nearer is 0.08 larger at any
    size (with "sqrt" a small box's whole approach spans less than 0.1, and a brick 19 mm higher than
    the table at the close differs by 0.01); "log_wh": ``[cx, cy, log width, log height, visible]``,
    each side as a fraction of the image's on the log scale, so a turned brick's wider box (its
    aspect) is told apart from a nearer brick's larger one (both sides grow alike).
    """
    n_out = mask_moments_dim(size_scale)
    h, w = mask.shape[-2:]
    m = mask[..., 0, :, :].float()
    mass = m.sum((-2, -1))
    ys = torch.linspace(-1 + 1 / h, 1 - 1 / h, h, device=m.device)  # pixel centres
    xs = torch.linspace(-1 + 1 / w, 1 - 1 / w, w, device=m.device)
    safe = mass.clamp(min=1e-6)
    col, row = m.sum(-2), m.sum(-1)  # the mass per column (along x) and per row (along y)
    cx = (col * xs).sum(-1) / safe
    cy = (row * ys).sum(-1) / safe
    visible = mass > 1e-6
    if size_scale == "log_wh":
        # A box's side from its second moment (a uniform side s has variance s^2 / 12); the pixel grid's
        # own 1/12 pixel^2 is taken off, so a box of a few pixels is not read wider than it is (after the
        # 64 px crop a 4 px box is within 7% of its side, and one 8.5% wider reads 8-12% wider).
        var_x = (col * (xs - cx[..., None]) ** 2).sum(-1) / safe
        var_y = (row * (ys - cy[..., None]) ** 2).sum(-1) / safe
        width = ((12 * var_x - (2 / w) ** 2).clamp(min=0)).sqrt() / 2
        height = ((12 * var_y - (2 / h) ** 2).clamp(min=0)).sqrt() / 2
        sizes = [_log_size(width), _log_size(height)]
    else:
        side = (mass / (h * w)).clamp(0, 1).sqrt()
        sizes = [2 * side - 1 if size_scale == "sqrt" else _log_size(side)]
    out = torch.stack([cx, cy, *sizes, visible.float() * 2 - 1], dim=-1)
    hidden = torch.tensor([0.0, 0.0] + [-1.0] * (n_out - 2), device=m.device)
    return torch.where(visible[..., None], out, hidden)


def _first_rgb_conv(model: nn.Module) -> str:
    """Name of the first 3-input-channel conv: timm's ``pretrained_cfg['first_conv']`` if valid, else
    the first ``nn.Conv2d`` with ``in_channels == 3`` in registration order."""
    first = (getattr(model, "pretrained_cfg", None) or {}).get("first_conv")
    if isinstance(first, str):
        try:
            mod = model.get_submodule(first)
        except AttributeError:
            mod = None
        if isinstance(mod, nn.Conv2d) and mod.in_channels == 3:
            return first
    for name, mod in model.named_modules():
        if isinstance(mod, nn.Conv2d) and mod.in_channels == 3:
            return name
    raise ValueError(f"no nn.Conv2d with 3 input channels found in {type(model).__name__}")


def expand_input_channels(model: nn.Module, extra: int = 1) -> nn.Module:
    """Grow the first conv of ``model`` (in place) from 3 to ``3 + extra`` input channels.

    Works for timm ViTs (``patch_embed.proj``) and CNN stems (``conv1``, ``conv1.0``, ``conv_stem``,
    ``stem.conv``...). The RGB weights and the bias are copied and the extra channels' weights are zero,
    so the output is unchanged whatever the extra channels contain. The conv class is preserved (e.g.
    timm's ``Conv2dSame``); weight-standardised convs are refused since zeros would change their
    normalisation.

    Returns:
        ``model`` itself, modified in place.
    """
    if extra <= 0:
        return model
    name = _first_rgb_conv(model)
    old = model.get_submodule(name)
    if old.groups != 1:
        raise ValueError(f"first conv '{name}' has groups={old.groups}; only groups=1 is supported")
    if "StdConv" in type(old).__name__:
        raise ValueError(f"first conv '{name}' is weight-standardised ({type(old).__name__}); not supported")
    new = copy.deepcopy(old)
    w = old.weight.detach()
    new_w = torch.cat([w, w.new_zeros(w.shape[0], extra, *w.shape[2:])], dim=1)
    new.weight = nn.Parameter(new_w, requires_grad=old.weight.requires_grad)
    new.in_channels = 3 + extra
    parent_name, _, attr = name.rpartition(".")
    setattr(model.get_submodule(parent_name) if parent_name else model, attr, new)
    return model


def _create_timm(backbone: str, pretrained: bool, image_size: int, **extra) -> nn.Module:
    """``timm.create_model`` with ``num_classes=0``; ``img_size`` is passed when the architecture takes it."""
    kwargs = {"pretrained": pretrained, "num_classes": 0, **extra}
    try:
        return timm.create_model(backbone, img_size=image_size, **kwargs)
    except TypeError as e:  # CNNs have no img_size argument (raised before any weight download)
        if "img_size" not in str(e):
            raise
        return timm.create_model(backbone, **kwargs)


POOLINGS = ("default", "spatial_softmax")


def _group_norm(num_channels: int, **kwargs) -> nn.Module:
    """GroupNorm with 16 groups (or the largest divisor of 16 that divides ``num_channels``)."""
    return timm.layers.GroupNorm(num_channels, num_groups=math.gcd(16, num_channels), **kwargs)


class SpatialSoftmaxHead(nn.Module):
    """timm CNN feature map of one stage -> LeRobot's ``SpatialSoftmax`` keypoints (x, y per keypoint).

    Global pooling throws away *where* things are; keypoints keep it with sub-cell precision, which is
    what a from-scratch encoder needs to put the gripper on a brick a few pixels wide (Diffusion
    Policy's ResNet + spatial-softmax design).
    """

    def __init__(self, feature_shape: tuple[int, int, int], num_keypoints: int) -> None:
        super().__init__()
        from lerobot.policies.diffusion.modeling_diffusion import SpatialSoftmax

        self.pool = SpatialSoftmax(feature_shape, num_kp=num_keypoints)

    def forward(self, features: list[Tensor]) -> Tensor:
        """(B, C, H, W) map (last of timm's feature list) -> (B, 2 * num_keypoints)."""
        return self.pool(features[-1]).flatten(1)


class MaskedImageEncoder(nn.Module):
    """timm backbone over RGB (+ bbox mask channel) returning one global feature per image.

    With ``pooling="default"`` the feature is timm's pooled output with ``num_classes=0``: the CLS token
    for ViTs (as in UMI), global average pooling for CNNs. With ``pooling="spatial_softmax"`` a CNN is
    cut after stage ``feature_stage`` and its map becomes keypoint coordinates. RGB is normalised with
    the backbone's own mean/std; the mask is fed unchanged (0/1 or fractional coverage).
    """

    def __init__(
        self,
        backbone: str,
        pretrained: bool,
        image_size: int,
        use_mask: bool,
        feature_dim: int | None = None,
        pooling: str = "default",
        feature_stage: int = 2,
        num_keypoints: int = 32,
        group_norm: bool = False,
    ) -> None:
        """Build the encoder.

        Args:
            backbone: timm model name, e.g. ``vit_tiny_patch16_224`` or ``resnet18``.
            pretrained: load timm's pretrained weights (needs the network or a filled HF cache). A
                failed download raises ``RuntimeError``; it never falls back to random weights.
            image_size: input side in pixels (given to ViTs as ``img_size``; CNNs take any size).
            use_mask: add the mask input channel (zero-initialised weights).
            feature_dim: if set, a linear projection to this size follows the pooled feature.
            pooling: "default" (timm's pooled output) or "spatial_softmax" (CNNs only, see
                ``SpatialSoftmaxHead``).
            feature_stage: with spatial_softmax, the timm feature stage cut at (2 = stride 8 for ResNets).
            num_keypoints: with spatial_softmax, keypoints per image (the feature has twice as many numbers).
            group_norm: replace BatchNorm by GroupNorm(16) (from-scratch CNNs: BatchNorm statistics fight
                with EMA weights and small batches; Diffusion Policy does the same).
        """
        super().__init__()
        if not timm.is_model(backbone):
            raise ValueError(f"unknown timm model '{backbone}'")
        if pooling not in POOLINGS:
            raise ValueError(f"pooling={pooling!r} is not one of {', '.join(POOLINGS)}")
        extra: dict = {}
        if pooling == "spatial_softmax":
            extra = {"features_only": True, "out_indices": (feature_stage,)}
        if group_norm:
            extra["norm_layer"] = _group_norm
        if pretrained:
            try:
                model = _create_timm(backbone, True, image_size, **extra)
            except Exception as e:  # hub/network errors come in many types (OSError, httpx, ...)
                raise RuntimeError(
                    f"could not load pretrained weights for timm backbone '{backbone}' ({type(e).__name__}: "
                    f"{e}). This machine may have no network: pre-fill the Hugging Face cache, or pass "
                    "pretrained=False to train the backbone from scratch (set HF_HUB_OFFLINE=1 to fail "
                    "fast instead of retrying)."
                ) from e
        else:
            model = _create_timm(backbone, False, image_size, **extra)
        cfg = timm.data.resolve_model_data_config(model)
        self.register_buffer("mean", torch.tensor(cfg["mean"], dtype=torch.float32).view(1, 3, 1, 1), False)
        self.register_buffer("std", torch.tensor(cfg["std"], dtype=torch.float32).view(1, 3, 1, 1), False)
        self.use_mask = use_mask
        self.image_size = image_size
        self.backbone = expand_input_channels(model, 1) if use_mask else model
        was_training = self.backbone.training
        with torch.no_grad():  # the pooled width is not always num_features (e.g. MobileNetV3 head)
            dummy = torch.zeros(1, 4 if use_mask else 3, image_size, image_size)
            out = self.backbone.eval()(dummy)
        self.backbone.train(was_training)
        if pooling == "spatial_softmax":
            self.head: nn.Module = SpatialSoftmaxHead(tuple(out[-1].shape[1:]), num_keypoints)
            width = 2 * num_keypoints
        else:
            self.head = nn.Identity()
            width = out.shape[-1]
        self.proj = nn.Linear(width, feature_dim) if feature_dim is not None else nn.Identity()
        self._out_dim = feature_dim if feature_dim is not None else width

    @property
    def out_dim(self) -> int:
        """Size ``D`` of the feature returned by ``forward``."""
        return self._out_dim

    def backbone_parameters(self) -> list[nn.Parameter]:
        """Parameters of the timm backbone (incl. the expanded first conv)."""
        return list(self.backbone.parameters())

    def parameter_groups(self) -> tuple[list[nn.Parameter], list[nn.Parameter]]:
        """``(backbone params, other params)`` so an optimizer can scale the backbone lr.

        The mask-channel weights live inside the backbone's first conv tensor, so they get the backbone lr.
        """
        return self.backbone_parameters(), [*self.head.parameters(), *self.proj.parameters()]

    def forward(self, rgb: Tensor, mask: Tensor | None = None) -> Tensor:
        """Encode images.

        Args:
            rgb: ``(..., 3, H, W)`` float in [0, 1].
            mask: ``(..., 1, H, W)`` bbox mask; required when ``use_mask``, ignored otherwise.

        Returns:
            ``(..., D)`` global features.
        """
        lead, (h, w) = rgb.shape[:-3], rgb.shape[-2:]
        x = (rgb.reshape(-1, 3, h, w) - self.mean) / self.std
        if self.use_mask:
            if mask is None:
                raise ValueError("this encoder was built with use_mask=True: pass the bbox mask")
            x = torch.cat([x, mask.reshape(-1, 1, h, w).to(x.dtype)], dim=1)
        return self.proj(self.head(self.backbone(x))).reshape(*lead, -1)


def _gray(x: Tensor) -> Tensor:
    """ITU-R 601 luma as torchvision's ``rgb_to_grayscale``: ``(..., 3, H, W) -> (..., 1, H, W)``."""
    return (0.2989 * x[..., 0:1, :, :] + 0.587 * x[..., 1:2, :, :] + 0.114 * x[..., 2:3, :, :]).clamp(0, 1)


def _shift_hue(x: Tensor, shift: Tensor) -> Tensor:
    """torchvision's ``adjust_hue`` (HSV hue rotation by ``shift`` turns) with a broadcastable ``shift``."""
    r, g, b = x.unbind(-3)
    maxc, minc = x.amax(-3), x.amin(-3)
    delta = maxc - minc
    safe = torch.where(delta > 0, delta, torch.ones_like(delta))
    h = torch.where(maxc == r, (g - b) / safe, torch.where(maxc == g, (b - r) / safe + 2, (r - g) / safe + 4))
    h = torch.remainder(h + 6 * shift.squeeze(-3), 6).unsqueeze(-3)  # hue in sextants [0, 6)
    k = torch.remainder(torch.tensor([5.0, 3.0, 1.0], dtype=x.dtype, device=x.device).view(3, 1, 1) + h, 6)
    return maxc.unsqueeze(-3) - delta.unsqueeze(-3) * torch.minimum(k, 4 - k).clamp(0, 1)


def color_jitter(x: Tensor, strength: tuple[float, float, float, float]) -> Tensor:
    """Per-sample ColorJitter, vectorised: torchvision's formulas and factor ranges, one draw per sample.

    ``x`` is ``(B, ..., 3, H, W)`` in [0, 1]; factors are drawn per sample (first dim) and shared by its
    other leading dims (frames). ``strength = (brightness, contrast, saturation, hue)`` as in
    ``v2.ColorJitter``; the order of the four ops is drawn per call (torchvision: per call too). A
    torchvision loop over samples is ~10x slower on CPU because of its HSV conversion.
    """
    bri, con, sat, hue = strength
    shape = (x.shape[0],) + (1,) * (x.ndim - 1)

    def factor(lo: float, hi: float) -> Tensor:
        return torch.empty(shape, dtype=x.dtype, device=x.device).uniform_(lo, hi)

    ops = []
    if bri > 0:
        f_b = factor(max(0.0, 1 - bri), 1 + bri)
        ops.append(lambda t: (t * f_b).clamp(0, 1))
    if con > 0:
        f_c = factor(max(0.0, 1 - con), 1 + con)
        ops.append(lambda t: (f_c * t + (1 - f_c) * _gray(t).mean((-3, -2, -1), keepdim=True)).clamp(0, 1))
    if sat > 0:
        f_s = factor(max(0.0, 1 - sat), 1 + sat)
        ops.append(lambda t: (f_s * t + (1 - f_s) * _gray(t)).clamp(0, 1))
    if hue > 0:
        f_h = factor(-hue, hue)
        ops.append(lambda t: _shift_hue(t, f_h))
    for i in torch.randperm(len(ops)).tolist():
        x = ops[i](x)
    return x


def _box_weights(offsets: Tensor, crop: int, n_in: int, n_out: int) -> Tensor:
    """Exact area (box filter) resampling of the window ``[off, off + crop)`` of ``n_in`` pixels to ``n_out``.

    Returns ``(B, n_out, n_in)`` weights: overlap of output pixel ``o`` with each input pixel / its size.
    """
    step = crop / n_out
    lo = torch.arange(n_out, dtype=torch.float32)[:, None] * step  # output pixel footprints, crop coords
    left = torch.arange(n_in, dtype=torch.float32)[None, None, :] - offsets.float()[:, None, None]
    return (torch.minimum(lo + step, left + 1) - torch.maximum(lo, left)).clamp(min=0) / step


class PairedAugment(nn.Module):
    """UMI's image augmentation applied to RGB and bbox mask together.

    Train mode: a random crop of ``crop_ratio`` of each side (UMI: 0.95), then resize to ``out_size``
    (antialiased bilinear for RGB; exact area resampling for the fractional mask, so its mass, i.e. the
    box area in pixels, is preserved and 1-2 px targets stay visible), then colour jitter on RGB
    only (UMI values, see ``color_jitter``). Eval mode (``module.eval()``): deterministic centre crop of
    the same ratio and resize, no jitter, so train and eval see the same scale.

    Crop offsets and jitter factors are drawn per sample (first dim) and shared by the frames of a
    sample when inputs are ``(B, T, C, H, W)``. Build the mask from the bbox at the input resolution
    BEFORE calling this, so the crop and resize move the mask with the pixels.
    """

    def __init__(
        self,
        crop_ratio: float = 0.95,
        color_jitter: tuple[float, float, float, float] = (0.3, 0.4, 0.5, 0.08),
    ) -> None:
        """Crop side ratio and jitter ``(brightness, contrast, saturation, hue)``; defaults: UMI."""
        super().__init__()
        self.crop_ratio = crop_ratio
        self.jitter = tuple(color_jitter)

    def forward(self, rgb: Tensor, mask: Tensor | None, out_size: int) -> tuple[Tensor, Tensor | None]:
        """Augment (train) or centre-crop (eval) and resize.

        Args:
            rgb: ``(B, 3, H, W)`` or ``(B, T, 3, H, W)`` float in [0, 1].
            mask: matching ``(B, 1, H, W)`` or ``(B, T, 1, H, W)`` mask, or None (RGB only).
            out_size: output side in pixels.

        Returns:
            ``(rgb, mask)`` with spatial size ``out_size x out_size``, leading dims unchanged (mask None
            if it was None).
        """
        lead, (h, w) = rgb.shape[:-3], rgb.shape[-2:]
        b, size = lead[0], (out_size, out_size)
        ch, cw = max(1, int(h * self.crop_ratio)), max(1, int(w * self.crop_ratio))
        if self.training:
            oy, ox = torch.randint(0, h - ch + 1, (b,)), torch.randint(0, w - cw + 1, (b,))
        else:
            oy, ox = torch.full((b,), (h - ch) // 2), torch.full((b,), (w - cw) // 2)
        y0, x0 = oy.tolist(), ox.tolist()
        crops = torch.stack([rgb[i, ..., y0[i] : y0[i] + ch, x0[i] : x0[i] + cw] for i in range(b)])
        out = F.interpolate(crops.reshape(-1, 3, ch, cw), size=size, mode="bilinear", antialias=True)
        out = out.clamp(0, 1).reshape(*lead, 3, *size)
        if self.training and any(v > 0 for v in self.jitter):
            out = color_jitter(out, self.jitter)
        if mask is not None:  # (B, n, H, W) -> (B, n, out, out) with per-sample crop windows
            wy = _box_weights(oy, ch, h, out_size).to(rgb)
            wx = _box_weights(ox, cw, w, out_size).to(rgb)
            m = mask.to(rgb.dtype).reshape(b, -1, h, w)
            mask = (wy[:, None] @ m @ wx[:, None].transpose(-1, -2)).reshape(*lead, 1, *size)
        return out, mask
