"""Per-axis perturbations of absolute action chunks, ramped in over the chunk.

A perturbation moves a chunk along one axis of the table (world) frame: ``x``, ``y``, ``z`` (metres),
``yaw`` (radians, a rotation about the world z axis through each pose's own position: for a top-down
gripper, a turn of the jaws about the tool axis) or ``gripper`` (width in metres, clipped at 0). The
offset grows along the chunk with a cosine ramp from ~0 at its first step to the full amount at its
last, so a perturbed chunk starts where the policy's does (no jump the controller's speed limits would
swallow) and ends displaced: the shape the paper's structured residuals use at a chunk's end.

Used by ``bboxpick-counterfactual`` (which candidates a branch point tries) and by the structured
reranking over per-axis grids.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lerobot_bboxpick import geometry

AXES: tuple[str, ...] = ("x", "y", "z", "yaw", "gripper")
_POSITION = {"x": 0, "y": 1, "z": 2}
GRIPPER_INDEX = 9


def cosine_ramp(horizon: int) -> np.ndarray:
    """``(horizon,)`` weights rising from ``(1 - cos(pi / horizon)) / 2`` to exactly 1 at the last step."""
    if horizon < 1:
        raise ValueError(f"horizon={horizon} must be >= 1")
    t = np.arange(1, horizon + 1) / horizon
    return (1.0 - np.cos(np.pi * t)) / 2.0


@dataclass(frozen=True)
class Perturbation:
    """``amount`` along ``axis`` (metres; radians for ``yaw``), reached at the chunk's last step."""

    axis: str
    amount: float

    def __post_init__(self) -> None:
        if self.axis not in AXES:
            raise ValueError(f"perturbation axis {self.axis!r} is not one of {', '.join(AXES)}")
        if not np.isfinite(self.amount):
            raise ValueError(f"perturbation amount {self.amount!r} along {self.axis} must be finite")

    @property
    def name(self) -> str:
        """E.g. ``x+0.030`` or ``yaw-0.350``."""
        return f"{self.axis}{self.amount:+.3f}"

    def apply(self, chunk: np.ndarray) -> np.ndarray:
        """The perturbed copy of an absolute pose10 chunk ``(H, 10)``."""
        chunk = np.asarray(chunk, dtype=np.float64)
        if chunk.ndim != 2 or chunk.shape[1] != 10:
            raise ValueError(f"chunk must have shape (H, 10) (absolute pose10), got {chunk.shape}")
        out = chunk.copy()
        offset = self.amount * cosine_ramp(len(chunk))
        if self.axis in _POSITION:
            out[:, _POSITION[self.axis]] += offset
        elif self.axis == "gripper":
            out[:, GRIPPER_INDEX] = np.maximum(out[:, GRIPPER_INDEX] + offset, 0.0)
        else:  # yaw: R' = Rz(angle) @ R, position unchanged
            c, s = np.cos(offset), np.sin(offset)
            rz = np.zeros((len(chunk), 3, 3))
            rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = c, -s, s, c, 1.0
            rotated = rz @ geometry.rot6d_to_mat(chunk[:, 3:9])
            out[:, 3:9] = geometry.mat_to_rot6d(rotated)
        return out


def parse_perturbations(spec: str, field: str = "perturbations") -> list[Perturbation]:
    """``"x:0.03,y:0.03,yaw:0.35"`` -> the +/- pair of each entry, in order (empty string: none)."""
    out: list[Perturbation] = []
    for entry in (e.strip() for e in str(spec).split(",") if e.strip()):
        axis, sep, amount = entry.partition(":")
        try:
            value = float(amount)
        except ValueError:
            value = float("nan")
        if not sep or axis.strip() not in AXES or not np.isfinite(value) or value <= 0:
            raise ValueError(
                f"{field}: entry {entry!r} must be <axis>:<amount> with axis one of {', '.join(AXES)} "
                "and a positive amount (metres; radians for yaw), e.g. 'x:0.03,yaw:0.35'"
            )
        out += [Perturbation(axis.strip(), value), Perturbation(axis.strip(), -value)]
    return out
