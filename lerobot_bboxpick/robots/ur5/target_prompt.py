"""The target box the ``ur5`` robot reports as ``observation.bbox``, frame after frame.

The person gives the target once, on the first frame (``--robot.bbox`` or the web picker); from then on
the colour tracker (``data/tracking.BoxTracker``, the suite's ``tracked`` source) follows it. In the
simulator the ``oracle`` source reports the target's projected box instead, exactly as ``bboxpick-collect``
records it. A lost frame reports zeros (the env's "out of view"); a target lost for more than
``max_lost_frames`` consecutive frames is ``gone``: the robot then stops the arm.
"""

from __future__ import annotations

import numpy as np

from lerobot_bboxpick.data.tracking import BoxTracker

NO_BOX = np.zeros(4, dtype=np.float32)


class TargetPrompt:
    """Follows one target from its first box."""

    def __init__(self, source: str, max_lost_frames: int) -> None:
        if source not in ("oracle", "tracked"):
            raise ValueError(f"bbox_source={source!r} is not one of: oracle, tracked")
        self.source = source
        self.max_lost_frames = max_lost_frames
        self._tracker: BoxTracker | None = None
        self.first_box: np.ndarray | None = None
        self.lost_frames = 0  # consecutive

    def start(self, frame: np.ndarray, box: np.ndarray) -> None:
        """Begin following the target in ``box`` (normalised x0, y0, x1, y1) of ``frame``."""
        self.first_box = np.asarray(box, dtype=np.float32).copy()
        self.lost_frames = 0
        self._tracker = BoxTracker(frame, self.first_box) if self.source == "tracked" else None
        self._first_pending = True

    def update(self, frame: np.ndarray, oracle: np.ndarray | None = None) -> np.ndarray:
        """The box for ``frame``: the given box on the first frame, then the tracker's (or the oracle's)."""
        if self.first_box is None:
            raise RuntimeError("TargetPrompt.start(frame, box) must be called before update()")
        if self._first_pending:  # the person's box itself on the frame it was drawn on
            self._first_pending = False
            return self.first_box.copy()
        if self.source == "oracle":
            if oracle is None:
                raise ValueError("bbox_source='oracle' needs the simulator's box (robot.backend=mujoco)")
            return np.asarray(oracle, dtype=np.float32)
        assert self._tracker is not None
        box, lost = self._tracker.update(frame)
        self.lost_frames = self.lost_frames + 1 if lost else 0
        return NO_BOX.copy() if lost else np.asarray(box, dtype=np.float32)

    @property
    def gone(self) -> bool:
        """The tracker lost the target for more than ``max_lost_frames`` consecutive frames."""
        return self.lost_frames > self.max_lost_frames
