"""The scripted expert (``sim/expert.ScriptedExpert``) behind LeRobot's ``Teleoperator`` interface.

It reads the simulator of a ``--robot.type=ur5 --robot.backend=mujoco`` robot connected in the same
process (``robots/ur5/sim_link``) and returns the ``ur5`` action: the absolute pose10 target. It plans a
pick of the scene's target when a scene starts, and re-plans from the arm's current state whenever it
takes over after a pause (DAgger: the person takes over from the policy), so its corrections start where
the policy went wrong. Planning is seeded by the scene's seed, as ``bboxpick-collect``'s is.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import cached_property

import numpy as np
from lerobot.teleoperators.teleoperator import Teleoperator

from lerobot_bboxpick.robots.ur5 import sim_link
from lerobot_bboxpick.robots.ur5.ur5 import POSE_KEYS
from lerobot_bboxpick.sim.expert import ScriptedExpert
from lerobot_bboxpick.teleoperators.bboxpick_expert.configuration_bboxpick_expert import BboxpickExpertConfig


class BboxpickExpert(Teleoperator):
    """Scripted-expert teleoperator for the simulated ``ur5``."""

    config_class = BboxpickExpertConfig
    name = "bboxpick_expert"

    def __init__(self, config: BboxpickExpertConfig, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(config)
        self.config = config
        self._clock = clock
        self._connected = False
        self._expert: ScriptedExpert | None = None
        self._planned_scene: int | None = None
        self._last_call: float | None = None
        self.plans = 0  # how many times it planned (scenes + takeovers)

    @cached_property
    def action_features(self) -> dict[str, type]:
        """The ``ur5`` action: absolute pose10."""
        return dict.fromkeys(POSE_KEYS, float)

    @cached_property
    def feedback_features(self) -> dict:
        """No feedback (it reads the simulator directly)."""
        return {}

    @property
    def is_connected(self) -> bool:
        """Whether ``connect`` was called."""
        return self._connected

    @property
    def is_calibrated(self) -> bool:
        """Nothing to calibrate."""
        return True

    def connect(self, calibrate: bool = True) -> None:
        """Nothing to open: the simulator is looked up at each action (the robot may connect later)."""
        self._connected = True

    def calibrate(self) -> None:
        """No-op."""

    def configure(self) -> None:
        """No-op."""

    def get_action(self) -> dict[str, float]:
        """The expert's next absolute pose10 target for the simulated arm."""
        arm = sim_link.find(self.config.robot_id)
        env = arm.env
        assert env is not None
        now = self._clock()
        took_over = self._last_call is not None and now - self._last_call > self.config.takeover_gap_s
        if self._expert is None or self._planned_scene != arm.scene_index or took_over:
            self._expert = ScriptedExpert(np.random.default_rng(arm.seed), vary=self.config.vary)
            self._expert.reset(env)  # plans from the current TCP pose and gripper width
            self._planned_scene = arm.scene_index
            self.plans += 1
        self._last_call = now
        action = self._expert.act()
        return {k: float(v) for k, v in zip(POSE_KEYS, action, strict=True)}

    def send_feedback(self, feedback: dict) -> None:
        """No-op."""

    def disconnect(self) -> None:
        """Forget the plan."""
        self._connected = False
        self._expert = None
