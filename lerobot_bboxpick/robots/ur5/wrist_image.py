"""A capture-card frame of the wrist GoPro -> the datasets' 224x224 wrist image.

UMI resizes the GoPro frame to height 224 and centre-crops the width (FACTS.md section 2); the simulated
lens (``sim/camera.gopro_hero10_umi_lens``) is calibrated for exactly that crop, so the real frames go
through the same two steps.
"""

from __future__ import annotations

import cv2
import numpy as np

IMAGE_SIZE = 224


def umi_wrist_crop(frame: np.ndarray, size: int = IMAGE_SIZE) -> np.ndarray:
    """Resize an RGB frame (H, W, 3) to height ``size`` (same aspect), then centre-crop it ``size`` wide."""
    frame = np.asarray(frame)
    if frame.ndim != 3 or frame.shape[2] != 3:
        raise ValueError(f"wrist frame must be (H, W, 3) RGB, got shape {frame.shape}")
    h, w = frame.shape[:2]
    new_w = max(size, round(w * size / h))
    resized = cv2.resize(frame, (new_w, size), interpolation=cv2.INTER_AREA)
    x0 = (new_w - size) // 2
    return np.ascontiguousarray(resized[:, x0 : x0 + size])
