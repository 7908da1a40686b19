"""From what a person draws on the wrist image to a target: box checks, clipping, brick matching.

Boxes are normalised x0, y0, x1, y1 as the env's ``observation.bbox``: the image spans [0, 1] in
both axes (pixel edges, not centres), x to the right, y down.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from lerobot_bboxpick.apps.dashboard.errors import RequestError
from lerobot_bboxpick.data.tracking import bbox_iou

# A drawn box designates the brick whose projected box it overlaps best, if at least this much: a
# person's quick box around a 5-14 px brick is loose (the suite's "noisy" person has IoU 0.7), but a
# box mostly on the table should be refused rather than guessed.
MIN_TARGET_IOU = 0.2


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def check_box(values: Sequence[float], field: str = "box") -> np.ndarray:
    """A drawn box clipped to the image, as float32 (4,); raise ``RequestError`` naming ``field``.

    The box must be four finite numbers with x1 > x0 and y1 > y0, and must overlap the image; the part
    outside the image is cut off (what the env does to a brick's box at the image edge).
    """
    values = list(values)
    if len(values) != 4 or not all(_is_number(v) for v in values):
        raise RequestError(
            f"{field} must be 4 finite numbers x0, y0, x1, y1 in [0, 1], got {values!r}", field=field
        )
    x0, y0, x1, y1 = (float(v) for v in values)
    if not (x1 > x0 and y1 > y0):
        raise RequestError(f"{field} must have x1 > x0 and y1 > y0, got {values!r}", field=field)
    clipped = np.clip(np.array([x0, y0, x1, y1]), 0.0, 1.0)
    if not (clipped[2] > clipped[0] and clipped[3] > clipped[1]):
        raise RequestError(
            f"{field}={values!r} lies outside the image: a box must overlap [0, 1] x [0, 1]", field=field
        )
    return clipped.astype(np.float32)


def check_point(values: Sequence[float], field: str = "point") -> tuple[float, float]:
    """A clicked point (x, y) inside the image [0, 1) x [0, 1); raise ``RequestError`` naming ``field``."""
    values = list(values)
    if len(values) != 2 or not all(_is_number(v) for v in values):
        raise RequestError(f"{field} must be 2 finite numbers x, y in [0, 1), got {values!r}", field=field)
    x, y = (float(v) for v in values)
    if not (0.0 <= x < 1.0 and 0.0 <= y < 1.0):
        raise RequestError(
            f"{field}={values!r} lies outside the image: x and y must be in [0, 1)", field=field
        )
    return x, y


def match_brick(box: np.ndarray, brick_boxes: np.ndarray, field: str = "box") -> tuple[int, float]:
    """The brick (index, IoU) whose projected box ``brick_boxes[i]`` overlaps ``box`` best.

    Raise ``RequestError`` when no brick reaches ``MIN_TARGET_IOU`` (bricks out of view have an
    all-zero box and never match).
    """
    ious = bbox_iou(np.asarray(box)[None], np.asarray(brick_boxes))
    best = int(np.argmax(ious))
    if ious[best] < MIN_TARGET_IOU:
        raise RequestError(
            f"{field} does not outline a brick: its best overlap is IoU {ious[best]:.2f} with brick {best}, "
            f"below {MIN_TARGET_IOU}; draw the box around one brick",
            field=field,
        )
    return best, float(ious[best])


def brick_at(point: tuple[float, float], masks: np.ndarray, field: str = "point") -> int:
    """Index of the brick under a normalised point in an (H, W) brick-index mask (-1 = no brick)."""
    h, w = masks.shape
    x, y = point
    index = int(masks[min(int(y * h), h - 1), min(int(x * w), w - 1)])
    if index < 0:
        raise RequestError(f"{field}={[x, y]!r} is not on a brick: click a brick or drag a box", field=field)
    return index
