"""Where an evaluated policy's bbox comes from: the simulator, a person, or a tracker.

* ``oracle``: the env's exact projected box of the target, every frame.
* ``noisy``: the oracle box with a per-episode offset and scale, as a person drawing the box would
  give it: a random direction of offset (in box sizes) and log-scale, whose magnitude is solved so the
  first frame's box has IoU ``iou`` with the oracle box; the same relative error then follows the box
  every frame. Seeded by the episode seed.
* ``tracked``: the first frame's oracle box, then ``data.tracking.BoxTracker`` follows it on the wrist
  images the policy sees; a lost track gives the env's ``none`` visibility (an all-zero box).
"""

from __future__ import annotations

import numpy as np

from lerobot_bboxpick.data.tracking import BoxTracker, bbox_iou
from lerobot_bboxpick.keys import ENV_BBOX, ENV_CAMERA, ENV_PIXELS

BBOX_SOURCES: tuple[str, ...] = ("oracle", "noisy", "tracked")
DEFAULT_NOISY_IOU = 0.7


def check_bbox_source(name: str) -> str:
    """Return ``name`` or raise a ValueError naming the valid sources."""
    if name not in BBOX_SOURCES:
        raise ValueError(f"bbox_source={name!r} is not known; valid sources: {', '.join(BBOX_SOURCES)}")
    return name


def _visible(box: np.ndarray) -> bool:
    return bool(box[2] > box[0] and box[3] > box[1])


def perturb_box(box: np.ndarray, offset: np.ndarray, log_scale: np.ndarray) -> np.ndarray:
    """Shift a normalised box's centre by ``offset`` box sizes and scale its sides by
    ``exp(log_scale)``; clipped to the image."""
    box = np.asarray(box, dtype=np.float64)
    size = box[2:] - box[:2]
    centre = (box[:2] + box[2:]) / 2 + offset * size
    half = size * np.exp(log_scale) / 2
    return np.clip(np.concatenate([centre - half, centre + half]), 0.0, 1.0).astype(np.float32)


def noise_for_iou(box: np.ndarray, iou: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random (offset, log_scale) whose perturbed ``box`` has IoU ``iou`` with ``box`` (bisection on
    the magnitude of a random direction; IoU falls monotonically along it)."""
    if not 0.0 < iou <= 1.0:
        raise ValueError(f"noisy_iou={iou!r} must be in (0, 1]")
    direction = rng.normal(size=4)
    direction /= np.linalg.norm(direction)
    offset_dir, scale_dir = direction[:2], direction[2:]
    if iou >= 1.0 or not _visible(box):
        return np.zeros(2), np.zeros(2)
    lo, hi = 0.0, 4.0
    for _ in range(50):
        mid = (lo + hi) / 2
        if bbox_iou(perturb_box(box, mid * offset_dir, mid * scale_dir), box) > iou:
            lo = mid
        else:
            hi = mid
    m = (lo + hi) / 2
    return m * offset_dir, m * scale_dir


class BboxSource:
    """Replaces ``obs["bbox"]`` with the box this source would give; call ``reset`` per episode."""

    def __init__(self, name: str = "oracle", noisy_iou: float = DEFAULT_NOISY_IOU) -> None:
        self.name = check_bbox_source(name)
        if not 0.0 < noisy_iou <= 1.0:
            raise ValueError(f"noisy_iou={noisy_iou!r} must be in (0, 1]")
        self.noisy_iou = noisy_iou
        self._tracker: BoxTracker | None = None
        self._noise: tuple[np.ndarray, np.ndarray] | None = None
        self.ious: list[float] = []  # IoU of each given box with the oracle box (frames where visible)
        self.lost_frames = 0

    def reset(self, observation: dict, seed: int) -> dict:
        """Start an episode at its first observation; returns the observation with this source's box."""
        self._tracker, self._noise, self.ious, self.lost_frames = None, None, [], 0
        oracle = np.asarray(observation[ENV_BBOX], dtype=np.float32)
        if self.name == "noisy":
            # Its own stream (not the scene's): the same seed gives the same error under any policy.
            self._noise = noise_for_iou(oracle, self.noisy_iou, np.random.default_rng([7919, seed]))
        elif self.name == "tracked" and _visible(oracle):
            self._tracker = BoxTracker(observation[ENV_PIXELS][ENV_CAMERA], oracle)
        return self._give(observation, oracle, first=True)

    def __call__(self, observation: dict) -> dict:
        """The observation of a later step with this source's box."""
        return self._give(observation, np.asarray(observation[ENV_BBOX], dtype=np.float32), first=False)

    def _give(self, observation: dict, oracle: np.ndarray, first: bool) -> dict:
        if self.name == "oracle":
            box = oracle
        elif self.name == "noisy":
            assert self._noise is not None
            box = perturb_box(oracle, *self._noise) if _visible(oracle) else np.zeros(4, np.float32)
        else:
            if self._tracker is None:  # the target was not visible on the first frame: nothing to track
                box = np.zeros(4, np.float32)
            elif first:
                box = self._tracker.last
            else:
                box, lost = self._tracker.update(observation[ENV_PIXELS][ENV_CAMERA])
                if lost:
                    self.lost_frames += 1
                    box = np.zeros(4, np.float32)
        if _visible(oracle):
            self.ious.append(float(bbox_iou(box, oracle)))
        return {**observation, ENV_BBOX: np.asarray(box, dtype=np.float32)}

    @property
    def mean_iou(self) -> float | None:
        """Mean IoU with the oracle box over the episode's frames where the target was visible."""
        return float(np.mean(self.ious)) if self.ious else None
