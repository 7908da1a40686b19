"""Episode outcomes, the paper's section 5.4 made measurable: pick, wrong, contact, empty.

The paper's words: *Pick*: the robot grasps and lifts the correct target block. *Wrong*: the robot
grasps and lifts a non-target block. *Contact*: the robot contacts or partially grasps the correct
target but does not lift it successfully. *Empty*: the robot closes on empty space or fails to make
meaningful contact. Measured here, at the end of every 20 Hz control step:

* a brick is **held** in a step when both fingers touch it during the step, its bottom is at least
  ``LIFT_HEIGHT`` (5 cm) above **its own resting height** (so a brick stacked in a pile needs the same
  5 cm as one on the table), and no other brick is more than ``OTHER_LIFT_HEIGHT`` above its rest
  (lifting the target together with a neighbour is not a pick of the target);
* **pick**: the target is held for ``HOLD_STEPS`` (20, i.e. 1 s) consecutive steps;
* **wrong**: another brick is held that long first;
* **contact**: neither, and a gripper geom touched the target at some point;
* **empty**: none of the above.
The first brick held for a full second decides pick or wrong for good, so the four are mutually
exclusive; a brick lifted and dropped within the second is no pick (it is contact, if it was the target).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from lerobot_bboxpick.sim.scene import N_BRICKS, SceneIds

OUTCOMES: tuple[str, ...] = ("pick", "wrong", "contact", "empty")
LIFT_HEIGHT = 0.05  # m above the brick's own resting height (bottom face)
# Another brick this far above its rest is lifted too. Above a tipped-over brick's bottom-face centre
# (15.9 mm) and a brick knocked onto a neighbour (19.2 mm), below a brick carried along by the grasp.
OTHER_LIFT_HEIGHT = 0.03
HOLD_STEPS = 20  # control steps (1 s at 20 Hz) a grasp has to hold
# A brick faster than this was not moved by the gripper (TCP < 0.5 m/s; a brick dropped from 10 cm hits
# 1.4 m/s): the contact solver blew up, e.g. after fingers were driven deep into a pile.
UNSTABLE_BRICK_SPEED = 5.0  # m/s


@dataclass
class OutcomeTracker:
    """Accumulates contacts and holds over an episode.

    ``update`` reads contacts at every physics stage within a control step; ``end_step`` closes the
    step, counting holds.
    """

    ids: SceneIds
    target: int
    rest_heights: np.ndarray  # (N_BRICKS,) bottom-face heights once the scene settled
    touched: np.ndarray = field(default_factory=lambda: np.zeros(N_BRICKS, dtype=bool))
    hold_steps: np.ndarray = field(default_factory=lambda: np.zeros(N_BRICKS, dtype=int))
    max_rise: np.ndarray = field(default_factory=lambda: np.zeros(N_BRICKS))  # m above rest, so far
    decided: int | None = None  # index of the first brick held for HOLD_STEPS
    peak_brick_speed: float = 0.0  # m/s, over the episode so far

    def __post_init__(self) -> None:
        self.rest_heights = np.asarray(self.rest_heights, dtype=float).copy()
        if self.rest_heights.shape != (N_BRICKS,):
            raise ValueError(f"rest_heights must have shape ({N_BRICKS},), got {self.rest_heights.shape}")
        # Per-geom lookup tables: cheaper than set membership tests in a per-substep loop.
        n = len(self.ids.brick_of_geom)
        self._is_gripper = np.zeros(n, dtype=bool)
        self._is_gripper[self.ids.gripper_geoms] = True
        self._is_left = np.zeros(n, dtype=bool)
        self._is_left[self.ids.finger_geoms[0]] = True
        self._is_right = np.zeros(n, dtype=bool)
        self._is_right[self.ids.finger_geoms[1]] = True
        self._grasped_in_step = np.zeros(N_BRICKS, dtype=bool)

    def update(self, data: mujoco.MjData) -> None:
        """Read the contacts of the current state (vectorised: runs at every ramp stage).

        Once the simulation is unstable, contacts and holds are no longer counted.
        """
        speeds = np.linalg.norm(data.cvel[self.ids.brick_bodies, 3:], axis=1)
        self.peak_brick_speed = max(self.peak_brick_speed, float(speeds.max()))
        if self.unstable:
            return
        pairs = np.asarray(data.contact.geom[: data.ncon]).reshape(-1, 2)
        pairs = np.concatenate([pairs, pairs[:, ::-1]])  # both orders: (gripper geom, brick geom)
        bricks = self.ids.brick_of_geom[pairs[:, 1]]
        on_brick = bricks >= 0
        self.touched[bricks[on_brick & self._is_gripper[pairs[:, 0]]]] = True
        by_left = np.zeros(N_BRICKS, dtype=bool)
        by_right = np.zeros(N_BRICKS, dtype=bool)
        by_left[bricks[on_brick & self._is_left[pairs[:, 0]]]] = True
        by_right[bricks[on_brick & self._is_right[pairs[:, 0]]]] = True
        self._grasped_in_step |= by_left & by_right

    def end_step(self, data: mujoco.MjData) -> None:
        """Close a control step: which brick is held now, and for how many steps in a row."""
        grasped, self._grasped_in_step = self._grasped_in_step, np.zeros(N_BRICKS, dtype=bool)
        if self.unstable:
            return
        rise = data.xpos[self.ids.brick_bodies, 2] - self.rest_heights
        self.max_rise = np.maximum(self.max_rise, rise)
        raised = rise >= OTHER_LIFT_HEIGHT
        others_raised = raised.sum() - raised  # for each brick: how many *other* bricks are up
        held = grasped & (rise >= LIFT_HEIGHT) & (others_raised == 0)
        self.hold_steps = np.where(held, self.hold_steps + 1, 0)
        if self.decided is None and (self.hold_steps >= HOLD_STEPS).any():
            self.decided = int(np.argmax(self.hold_steps))

    @property
    def unstable(self) -> bool:
        """Did the simulation blow up (a brick thrown faster than ``UNSTABLE_BRICK_SPEED``)?"""
        return self.peak_brick_speed > UNSTABLE_BRICK_SPEED

    @property
    def outcome(self) -> str:
        """The episode's outcome so far."""
        if self.decided is not None:
            return "pick" if self.decided == self.target else "wrong"
        if self.touched[self.target]:
            return "contact"
        return "empty"
