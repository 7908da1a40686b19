"""``--robot.backend=mujoco``: the ``lego_pick`` twin behind the ``ur5`` robot.

The arm, the fingers and the wrist GoPro are the env's (one ``LegoPickEnv.step`` per command, i.e. the
same mink IK, speed limits and physics as ``lerobot-eval``). Unlike a gym env, a robot has no reset: the
world changes on its own, as a person resets a real table. A scene lasts ``scene_time_s`` of wall-clock
time from its first observation; the next observation after that starts scene ``k + 1`` (seed
``seed + k + 1``). Each scene's outcome (``pick``, ``wrong``, ...) is logged when it ends.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from lerobot_bboxpick import geometry
from lerobot_bboxpick.robots.ur5.backend import ArmBackend
from lerobot_bboxpick.sim.env import LegoPickEnv

log = logging.getLogger(__name__)
# Frames of episode length the env is given: scenes end on the clock, not on the env's truncation.
_UNBOUNDED_STEPS = 10**9


class MujocoArm(ArmBackend):
    """A ``LegoPickEnv`` as an arm with a gripper and a wrist camera."""

    def __init__(
        self,
        setting: str,
        seed: int,
        scene_time_s: float,
        domain_randomization: bool = True,
        max_tcp_speed: float = 0.5,
        max_tcp_angular_speed: float = 1.5,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.setting, self.first_seed, self.scene_time_s = setting, seed, scene_time_s
        self._env_options = {
            "setting": setting,
            "episode_length": _UNBOUNDED_STEPS,
            "terminate_on_lift": False,
            "domain_randomization": domain_randomization,
            "max_tcp_speed": max_tcp_speed,
            "max_tcp_angular_speed": max_tcp_angular_speed,
        }
        self._clock = clock
        self.env: LegoPickEnv | None = None
        self.scene_index = -1
        self.scene_started: float | None = None  # clock time of the scene's first observation
        self.observation: dict | None = None
        self.info: dict | None = None
        self.outcomes: list[dict] = []  # one record per finished scene
        self._target_override: int | None = None

    # ------------------------------------------------------------------ ArmBackend
    def connect(self) -> None:
        """Build the simulator and load the first scene."""
        self.env = LegoPickEnv(**self._env_options)
        self._load_scene(0)

    def disconnect(self) -> None:
        """Log the current scene's outcome and free the renderer."""
        if self.env is not None:
            self._finish_scene()
            self.env.close()
            self.env = None

    @property
    def is_connected(self) -> bool:
        """Whether the simulator is built."""
        return self.env is not None

    def tcp_pose(self) -> np.ndarray:
        """The TCP pose of the simulated arm (4x4, table frame)."""
        return self._live().tcp_pose()

    def gripper_width(self) -> float:
        """The simulated finger distance (m)."""
        return self._live().gripper_width()

    def command(self, T: np.ndarray, width: float) -> None:
        """One 20 Hz env step toward ``T`` and ``width``."""
        action = np.concatenate([geometry.mat_to_pose9(T), [width]])
        self.observation, _, _, _, self.info = self._live().step(action)

    def stop(self) -> None:
        """Hold still: command the measured pose (the sim has no momentum to brake)."""
        env = self._live()
        self.command(env.tcp_pose(), env.gripper_width())

    # ------------------------------------------------------------------ simulator extras
    def poll_scene(self) -> bool:
        """Start the next scene if the current one has lasted ``scene_time_s``; True if it did.

        Called at every observation; the first observation of a scene starts its clock.
        """
        now = self._clock()
        if self.scene_started is None:
            self.scene_started = now
            return False
        if now - self.scene_started < self.scene_time_s:
            return False
        self._finish_scene()
        self._load_scene(self.scene_index + 1)
        self.scene_started = now
        return True

    def camera_frame(self) -> np.ndarray:
        """The wrist image after the last step (224x224x3 uint8, the GoPro fisheye as UMI crops it)."""
        assert self.observation is not None
        return self.observation["pixels"]["wrist"]

    def oracle_bbox(self) -> np.ndarray:
        """The target's projected box in the last image (zeros when out of view), as the datasets hold it."""
        assert self.observation is not None
        return np.asarray(self.observation["bbox"], dtype=np.float32)

    def designate(self, bbox: np.ndarray, min_covered: float = 0.5) -> int:
        """Make the brick that best matches ``bbox`` (normalised, in the current image) the target.

        A person's box is often loose around a small brick, so the candidates are the bricks with at
        least ``min_covered`` of their own box inside it, and the best IoU among them wins. The scene is
        reloaded with that target (same seed, so the same bricks); returns its index. Raises ValueError
        naming robot.bbox when no brick is covered enough.
        """
        from lerobot_bboxpick.data.tracking import bbox_iou
        from lerobot_bboxpick.sim.scene import N_BRICKS

        env = self._live()
        boxes = np.array([env.brick_box(i).bbox for i in range(N_BRICKS)], dtype=np.float64)
        ious = bbox_iou(boxes, bbox)
        inside = np.clip(np.minimum(boxes[:, 2:], bbox[2:]) - np.maximum(boxes[:, :2], bbox[:2]), 0, None)
        areas = np.prod(boxes[:, 2:] - boxes[:, :2], axis=1)
        covered = np.where(areas > 0, np.prod(inside, axis=1) / np.where(areas > 0, areas, 1.0), 0.0)
        ious = np.where(covered >= min_covered, ious, -1.0)
        best = int(np.argmax(ious))
        if ious[best] < 0:
            raise ValueError(
                f"robot.bbox={np.round(bbox, 3).tolist()} covers no brick of scene {self.scene_index} "
                f"(at most {covered.max():.0%} of one is inside it; {min_covered:.0%} needed): draw it "
                "around one brick"
            )
        self._target_override = best
        self._load_scene(self.scene_index, keep_target=True)
        return best

    @property
    def seed(self) -> int:
        """Seed of the current scene."""
        return self.first_seed + self.scene_index

    def _load_scene(self, index: int, keep_target: bool = False) -> None:
        if not keep_target:
            self._target_override = None
        options = {} if self._target_override is None else {"target": self._target_override}
        self.scene_index = index
        self.observation, self.info = self._live().reset(seed=self.seed, options=options)
        log.info("scene %d: %s seed %d, %s", index, self.setting, self.seed, self.info["task"])

    def _finish_scene(self) -> None:
        if self.info is None:
            return
        record = {"scene": self.scene_index, "seed": self.seed, "outcome": self.info["outcome"]}
        self.outcomes.append(record)
        log.info("scene %d (seed %d) ended: %s", self.scene_index, self.seed, self.info["outcome"])

    def _live(self) -> LegoPickEnv:
        if self.env is None:
            raise RuntimeError("the mujoco backend is not connected: call robot.connect() first")
        return self.env
