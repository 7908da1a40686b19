"""The target view: a magnified crop of the wrist image around the target's box, as a second image input.

At the start of an episode a brick spans 2-3 px of the 64-96 px policy image, so the yaw the grasp needs
is visible only late in the descent (docs/results.md). The box says where the target is; this module
cuts a square window ``context`` times the box's longer side around its centre (at least ``min_side`` of
the image), resamples it to ``crop_size`` px from the stored full-resolution frame and encodes it with a
second small RGB encoder of the same architecture. The window follows the box, so the crop is the
target's own neighbourhood at several times the main image's resolution whatever the layout.

Training jitters the window (shift and scale, as a person's or a tracker's box would) and the colours;
evaluation uses the exact window. A zero box ("target not in view") gives the whole image.
"""

import math

import torch
from torch import Tensor, nn
from torchvision.ops import roi_align

from lerobot_bboxpick.policies.bbox_diffusion.encoder import MaskedImageEncoder, color_jitter


def target_windows(bboxes: Tensor, height: int, width: int, context: float, min_side: float) -> Tensor:
    """Square windows (in pixels) centred on normalised ``[x0, y0, x1, y1]`` boxes: ``(N, 4) -> (N, 4)``.

    The side is ``context`` times the box's longer side in pixels, at least ``min_side`` times the
    image's shorter side; an empty box (zero area) gives the whole image. Windows may reach past the
    image's edges (``crop_windows`` fills the outside with zeros) so the target stays at the centre.
    """
    if bboxes.shape[-1] != 4:
        raise ValueError(f"bboxes must have shape (N, 4), got {tuple(bboxes.shape)}")
    scale = bboxes.new_tensor([width, height, width, height])
    px = bboxes.float() * scale
    w, h = px[:, 2] - px[:, 0], px[:, 3] - px[:, 1]
    side = torch.maximum(context * torch.maximum(w, h), px.new_tensor(min_side * min(height, width)))
    cx, cy = (px[:, 0] + px[:, 2]) / 2, (px[:, 1] + px[:, 3]) / 2
    windows = torch.stack([cx - side / 2, cy - side / 2, cx + side / 2, cy + side / 2], dim=-1)
    whole = px.new_tensor([0.0, 0.0, width, height]).expand_as(windows)
    empty = (w <= 0) | (h <= 0)
    return torch.where(empty[:, None], whole, windows)


def jitter_windows(windows: Tensor, shift: float, scale: float) -> Tensor:
    """Random windows near ``windows`` ``(N, 4)``: centres moved by up to ``shift`` of the side on each
    axis, sides scaled by a factor in ``[1 / scale, scale]`` (log-uniform)."""
    side = (windows[:, 2:] - windows[:, :2]).clamp(min=1e-6)
    centre = (windows[:, 2:] + windows[:, :2]) / 2
    centre = centre + (torch.rand_like(centre) * 2 - 1) * shift * side
    log_s = math.log(scale)
    side = side * torch.empty_like(side[:, :1]).uniform_(-log_s, log_s).exp()
    return torch.cat([centre - side / 2, centre + side / 2], dim=-1)


def crop_windows(images: Tensor, windows: Tensor, out_size: int) -> Tensor:
    """Resample pixel windows ``(N, 4)`` of images ``(N, 3, H, W)`` to ``(N, 3, out_size, out_size)``.

    torchvision's ``roi_align`` with as many samples per output pixel as the window has input pixels
    (an area average when shrinking, bilinear when magnifying); outside the image it reads zeros.
    """
    index = torch.arange(len(windows), device=images.device, dtype=images.dtype)[:, None]
    rois = torch.cat([index, windows.to(images)], dim=1)
    return roi_align(images, rois, output_size=out_size, spatial_scale=1.0, sampling_ratio=-1, aligned=True)


class TargetView(nn.Module):
    """Crop around the target's box + its own RGB encoder: ``(B, T, 3, H, W), (B, T, 4) -> (B, T, D)``."""

    def __init__(
        self,
        crop_size: int,
        context: float,
        min_side: float,
        encoder_options: dict,
        color_jitter: tuple[float, float, float, float],
        window_shift: float = 0.1,
        window_scale: float = 1.15,
    ) -> None:
        """Build the view.

        Args:
            crop_size: side of the resampled crop in pixels.
            context: window side over the box's longer side.
            min_side: smallest window side as a fraction of the image.
            encoder_options: ``MaskedImageEncoder`` keywords (backbone, pooling...) without ``image_size``
                and ``use_mask``: the crop is encoded by the main encoder's architecture, RGB only.
            color_jitter: training colour jitter ``(brightness, contrast, saturation, hue)``.
            window_shift: training jitter of the window's centre, a fraction of its side.
            window_scale: training jitter of the window's side, a factor.
        """
        super().__init__()
        self.crop_size, self.context, self.min_side = crop_size, context, min_side
        self.jitter = tuple(color_jitter)
        self.window_shift, self.window_scale = window_shift, window_scale
        self.encoder = MaskedImageEncoder(image_size=crop_size, use_mask=False, **encoder_options)

    @property
    def out_dim(self) -> int:
        """Width of the feature per frame."""
        return self.encoder.out_dim

    def crops(self, images: Tensor, bboxes: Tensor) -> Tensor:
        """The (augmented, in train mode) crops ``(B, T, 3, crop_size, crop_size)`` in [0, 1]."""
        lead, (h, w) = images.shape[:-3], images.shape[-2:]
        flat_images = images.reshape(-1, 3, h, w).float()
        windows = target_windows(bboxes.reshape(-1, 4), h, w, self.context, self.min_side)
        if self.training and (self.window_shift > 0 or self.window_scale > 1):
            windows = jitter_windows(windows, self.window_shift, self.window_scale)
        out = crop_windows(flat_images, windows, self.crop_size).clamp(0, 1)
        out = out.reshape(*lead, 3, self.crop_size, self.crop_size)
        if self.training and any(v > 0 for v in self.jitter):
            out = color_jitter(out, self.jitter)
        return out

    def forward(self, images: Tensor, bboxes: Tensor) -> Tensor:
        """Features ``(B, T, D)`` of the target's crops."""
        return self.encoder(self.crops(images, bboxes))
