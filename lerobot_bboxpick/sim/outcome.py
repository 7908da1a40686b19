"""Episode outcomes as the paper's section 5.4 defines them: pick, wrong, contact, empty.

* pick: the target is grasped (touched by both fingers) and lifted >= 5 cm above the table.
* wrong: another brick is grasped and lifted that high (and the target never was).
* contact: the gripper touched the target but never lifted it.
* empty: none of the above.
The tracker looks at every step, so an early lift counts even if the brick is dropped later.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from lerobot_bboxpick.sim.scene import N_BRICKS, SceneIds

OUTCOMES: tuple[str, ...] = ("pick", "wrong", "contact", "empty")
LIFT_HEIGHT = 0.05  # m between the table and the brick's bottom face
# A brick faster than this was not moved by the gripper (TCP < 0.5 m/s; a brick dropped from 10 cm hits
# 1.4 m/s): the contact solver blew up, e.g. after fingers were driven deep into a pile.
UNSTABLE_BRICK_SPEED = 5.0  # m/s


@dataclass
class OutcomeTracker:
    """Accumulates contacts and lifts over an episode."""

    ids: SceneIds
    target: int
    touched: np.ndarray = field(default_factory=lambda: np.zeros(N_BRICKS, dtype=bool))
    lifted: np.ndarray = field(default_factory=lambda: np.zeros(N_BRICKS, dtype=bool))
    grasped_now: np.ndarray = field(default_factory=lambda: np.zeros(N_BRICKS, dtype=bool))
    peak_brick_speed: float = 0.0  # m/s, over the episode so far

    def __post_init__(self) -> None:
        # Per-geom lookup tables: cheaper than set membership tests in a per-substep loop.
        n = len(self.ids.brick_of_geom)
        self._is_gripper = np.zeros(n, dtype=bool)
        self._is_gripper[self.ids.gripper_geoms] = True
        self._is_left = np.zeros(n, dtype=bool)
        self._is_left[self.ids.finger_geoms[0]] = True
        self._is_right = np.zeros(n, dtype=bool)
        self._is_right[self.ids.finger_geoms[1]] = True

    def update(self, data: mujoco.MjData) -> None:
        """Read the contacts and brick heights of the current state (vectorised: runs every substep).

        Once the simulation is unstable, contacts and lifts are no longer counted.
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
        self.grasped_now = by_left & by_right
        # Heights of the bricks' bottom-face centres; a grasp keeps a brick near level.
        heights = data.xpos[self.ids.brick_bodies, 2]
        self.lifted |= self.grasped_now & (heights >= LIFT_HEIGHT)

    @property
    def unstable(self) -> bool:
        """Did the simulation blow up (a brick thrown faster than ``UNSTABLE_BRICK_SPEED``)?"""
        return self.peak_brick_speed > UNSTABLE_BRICK_SPEED

    @property
    def outcome(self) -> str:
        """The episode's outcome so far."""
        if self.lifted[self.target]:
            return "pick"
        if self.lifted.any():
            return "wrong"
        if self.touched[self.target]:
            return "contact"
        return "empty"
