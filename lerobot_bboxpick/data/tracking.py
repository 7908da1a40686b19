"""Propagate a first-frame target box through a wrist-camera episode (for imported UMI data).

Tracker choice (opencv-python-headless 4.13, no contrib: no CSRT/KCF/MedianFlow, no ``cv2.legacy``).
Its trackers are MIL, and GOTURN/DaSiamRPN/Nano/Vit, which need DNN weight files nothing here ships.
Measured on simulated grid_id expert episodes (5-14 px bricks in 224 px frames): ``TrackerMIL`` gave
a mean IoU of 0.01-0.05 at native size and 0.19-0.23 on 4x upscaled frames, at 30-50 s per
150-frame episode; a pyramidal Lucas-Kanade median-flow tracker on 1-4x upscaled grey frames,
0.11-0.69 (a brick a few pixels across has too little texture). DUPLO bricks are saturated
single-colour blobs, so we track by colour (the CamShift recipe): a hue-saturation-value histogram
ratio of the first box (centre-weighted) against a ring around it, back-projected in a
motion-predicted search window; the 8-connected component (``cv2.connectedComponentsWithStats``)
of the model's dominant colours that best overlaps the prediction, gated by size, grown by one
pixel onto any target colour (hysteresis, so a finger pad or neighbouring brick in the first box
cannot merge in). The box of a component's pixels is what the simulator's ground truth (and an
annotator) measures, so we work at native resolution: upscaling adds interpolated pixels, not
information, to a colour mask. Mean IoU per episode: 0.81-0.93 on 33 of 34 simulated episodes (16 to
tune, 18 held out) of all settings; one held-out pile episode: 0.45 (a brick inside a pile).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

_BINS = (30, 16, 8)  # hue (0-180), saturation, value (0-256): value tells white from black
_KERNEL_SIGMA = 0.7  # first colour model: Gaussian weights, sigma in box half-sizes
_CORE_FRACTION = 0.2  # core colours: at least this fraction of the model's most common colour
_GROW_PX = 1  # a core's box grows by up to this many pixels onto any target-coloured pixel


@dataclass(frozen=True)
class TrackResult:
    """Tracked boxes ``(T, 4)`` normalised x0, y0, x1, y1 (float32) and a ``(T,)`` lost mask.

    On a lost frame the box is the last one found (the target was not found in that frame).
    """

    boxes: np.ndarray
    lost: np.ndarray

    @property
    def lost_fraction(self) -> float:
        """Fraction of frames on which the target was lost."""
        return float(self.lost.mean()) if len(self.lost) else 0.0


def bbox_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of boxes ``(..., 4)`` x0, y0, x1, y1 (broadcast over leading dims); 0 for empty unions."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape[-1] != 4 or b.shape[-1] != 4:
        raise ValueError(f"boxes must have shape (..., 4), got {a.shape} and {b.shape}")
    iw = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    ih = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = iw * ih

    def area(x: np.ndarray) -> np.ndarray:
        return np.clip(x[..., 2] - x[..., 0], 0, None) * np.clip(x[..., 3] - x[..., 1], 0, None)

    union = area(a) + area(b) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def _quantise(rgb: np.ndarray) -> np.ndarray:
    """(H, W) flat colour-bin index of each pixel."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV).astype(np.int64)
    h = hsv[..., 0] * _BINS[0] // 180
    s = hsv[..., 1] * _BINS[1] // 256
    v = hsv[..., 2] * _BINS[2] // 256
    return (h * _BINS[1] + s) * _BINS[2] + v


def _hist(bins: np.ndarray, weights: np.ndarray) -> np.ndarray:
    # numpy, not cv2.calcHist/calcBackProject: a 3-d histogram round-trips through numpy as a 2-d
    # multi-channel Mat and back-projects to zeros.
    n = int(np.prod(_BINS))
    h = np.bincount(bins.ravel(), weights.ravel().astype(float), minlength=n).reshape(_BINS)
    h = gaussian_filter(h, 0.8, mode=("wrap", "nearest", "nearest"))  # a few pixels leave gaps between bins
    return h.reshape(-1) / max(float(h.sum()), 1e-9)


def _box_mask(shape: tuple[int, int], box: np.ndarray, grow: float = 0.0) -> np.ndarray:
    h, w = shape
    x0, y0, x1, y1 = np.round(box + np.array([-grow, -grow, grow, grow])).astype(int)
    m = np.zeros((h, w), np.uint8)
    m[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = 1
    return m


def _components(mask: np.ndarray, offset: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (n, 4) x0, y0, x1, y1 of the 8-connected components of ``mask`` and the label image."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    xy = stats[1:, :2].astype(np.float64) + offset
    return np.concatenate([xy, xy + stats[1:, 2:4]], axis=1), labels


class BoxTracker:
    """Follows a target from its first box, one frame at a time (``update``).

    Used closed loop (the suite's ``tracked`` bbox source) and offline (:func:`track_bbox`).
    ``threshold`` is the foreground probability of a pixel's colour above which it counts as the
    target; ``adapt_rate`` blends each found box's colours into the model; a component counts as the
    target only if its area is within [min_area_ratio, max_area_ratio] of the previous box's.
    """

    def __init__(
        self,
        first_frame: np.ndarray,
        first_box: np.ndarray,
        *,
        threshold: float = 0.5,
        adapt_rate: float = 0.03,
        min_area_ratio: float = 0.35,
        max_area_ratio: float = 3.0,
    ) -> None:
        frame = _check_frame(first_frame, "first_frame")
        b0 = np.clip(np.asarray(first_box, dtype=np.float64).reshape(-1), 0, 1)
        if b0.shape != (4,) or not (b0[2] > b0[0] and b0[3] > b0[1]):
            raise ValueError(
                "first_box must be a normalised (4,) x0, y0, x1, y1 with x1 > x0, y1 > y0 inside the "
                f"image, got {first_box!r}"
            )
        self.threshold, self.adapt_rate = threshold, adapt_rate
        self.min_area_ratio, self.max_area_ratio = min_area_ratio, max_area_ratio
        self.H, self.W = frame.shape[:2]
        self.scale = np.array([self.W, self.H, self.W, self.H], dtype=np.float64)
        self.box = b0 * self.scale  # pixels
        self.last = b0.astype(np.float32)  # normalised, the last box found
        H, W, box = self.H, self.W, self.box
        q = _quantise(frame)
        # Centre-weighted first model: the target fills the box centre, occluders and neighbours its rim.
        yy, xx = np.mgrid[0:H, 0:W] + 0.5
        c, half = (box[:2] + box[2:]) / 2, (box[2:] - box[:2]) / 2
        kernel = np.exp(
            -0.5
            * (
                ((xx - c[0]) / (_KERNEL_SIGMA * half[0])) ** 2
                + ((yy - c[1]) / (_KERNEL_SIGMA * half[1])) ** 2
            )
        )
        self.fg, self.bg = self._model(q, box, kernel * _box_mask((H, W), box))
        self.velocity = np.zeros(2)
        self.n_lost = 0

    def _model(self, q: np.ndarray, b: np.ndarray, fg_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        size = max(b[2] - b[0], b[3] - b[1])
        ring = _box_mask((self.H, self.W), b, grow=max(2 * size, 12)) & (
            1 - _box_mask((self.H, self.W), b, grow=1)
        )
        return _hist(q, fg_weights), _hist(q, ring)

    def update(self, frame: np.ndarray) -> tuple[np.ndarray, bool]:
        """The target's normalised box in ``frame`` and whether it was lost (then: the last box found)."""
        frame = _check_frame(frame, "frame")
        H, W, box = self.H, self.W, self.box
        q = _quantise(frame)
        fg, bg = self.fg, self.bg
        # Any colour likelier on the target than around it; its core: the model's dominant colours
        # (a finger pad or a neighbour brick in the first box is a minor colour, and left out).
        loose = fg / (fg + bg + 1e-12)
        core = np.where(fg >= _CORE_FRACTION * fg.max(), loose, 0.0)
        size = box[2:] - box[:2]
        pred = box + np.tile(self.velocity, 2)
        margin = (max(size) + 6) * (1 + 0.5 * min(self.n_lost, 6))  # search wider the longer it is lost
        x0, y0 = np.maximum(np.floor(pred[:2] - margin), 0).astype(int)
        x1, y1 = np.minimum(np.ceil(pred[2:] + margin), [W, H]).astype(int)
        best = None
        if x1 > x0 and y1 > y0:
            qw = q[y0:y1, x0:x1]
            for lut in (core, loose):  # the core first; any target colour when no core is found
                cand, labels = _components(lut[qw] >= self.threshold, (x0, y0))
                area_ratio = np.prod(cand[:, 2:] - cand[:, :2], axis=1) / max(np.prod(size), 1.0)
                # Overlap with the predicted box, or (when lost) closeness of centres.
                centre_d = np.linalg.norm((cand[:, :2] + cand[:, 2:] - pred[:2] - pred[2:]) / 2, axis=1)
                score = bbox_iou(cand, pred) + (self.n_lost > 0) * 0.5 / (1 + centre_d / max(size))
                score[(area_ratio < self.min_area_ratio) | (area_ratio > self.max_area_ratio)] = 0
                if len(score) and score.max() > 0.1:
                    k = int(np.argmax(score))
                    best, best_score, fg_mask = cand[k], float(score[k]), labels == k + 1
                    break
        if best is None:
            self.n_lost += 1
            self.velocity *= 0.8
            return self.last.copy(), True
        # Hysteresis: the core's box grows by a pixel onto edge pixels of any target colour.
        g = np.clip(np.round(best + np.array([-1, -1, 1, 1]) * _GROW_PX).astype(int), 0, [W, H, W, H])
        ys, xs = np.nonzero(loose[q[g[1] : g[3], g[0] : g[2]]] >= self.threshold)
        if len(xs):
            best = np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], float) + np.tile(g[:2], 2)
        step = (best[:2] + best[2:] - box[:2] - box[2:]) / 2
        self.velocity = step if self.n_lost else 0.5 * self.velocity + 0.5 * step
        self.box, self.n_lost = best, 0
        self.last = (best / self.scale).astype(np.float32)
        if self.adapt_rate > 0 and best_score > 0.3:
            full = np.zeros((H, W), np.uint8)
            full[y0:y1, x0:x1] = fg_mask
            fg_new, bg_new = self._model(q, best, full)
            self.fg = (1 - self.adapt_rate) * fg + self.adapt_rate * fg_new
            self.bg = (1 - self.adapt_rate) * bg + self.adapt_rate * bg_new
        return self.last.copy(), False


def _check_frame(frame: np.ndarray, name: str) -> np.ndarray:
    frame = np.asarray(frame)
    if frame.ndim != 3 or frame.shape[-1] != 3 or frame.dtype != np.uint8:
        raise ValueError(f"{name} must be (H, W, 3) uint8 RGB, got {frame.shape} {frame.dtype}")
    return frame


def track_bbox(frames: np.ndarray, first_box: np.ndarray, **options: float) -> TrackResult:
    """Propagate the normalised box ``first_box`` on ``frames[0]`` through ``frames`` (T, H, W, 3) RGB.

    ``options`` are :class:`BoxTracker`'s: ``threshold`` is the foreground probability of a pixel's
    colour above which it counts as the target; ``adapt_rate`` blends each found box's colours into
    the model; a component counts as the target only if its area is within [``min_area_ratio``,
    ``max_area_ratio``] of the previous box's.
    """
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be (T, H, W, 3) uint8 RGB, got {frames.shape} {frames.dtype}")
    T = frames.shape[0]
    boxes = np.zeros((T, 4), np.float32)
    lost = np.zeros(T, bool)
    if T == 0:
        return TrackResult(boxes, lost)
    tracker = BoxTracker(frames[0], first_box, **options)
    boxes[0] = tracker.last
    for t in range(1, T):
        boxes[t], lost[t] = tracker.update(frames[t])
    return TrackResult(boxes, lost)
