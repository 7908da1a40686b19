"""A person at a keyboard or gamepad drives the ``ur5``: LeRobot's end-effector teleoperators emit
deltas (``delta_x``, ``delta_y``, ``delta_z`` in -1..1 and ``gripper`` 0 close / 1 stay / 2 open); this
processor step integrates them into the robot's action, the absolute pose10 target, from the pose the
robot last observed. Used as ``lerobot-record``'s teleop-action processor by ``bboxpick-record-ee``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from lerobot.configs import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.processor import ProcessorStepRegistry, RobotActionProcessorStep, TransitionKey

from lerobot_bboxpick.robots.ur5.ur5 import POSE_KEYS
from lerobot_bboxpick.sim.scene import MAX_GRIPPER_WIDTH

DELTA_KEYS = ("delta_x", "delta_y", "delta_z")


@ProcessorStepRegistry.register(name="bboxpick_ee_delta_to_pose10")
@dataclass
class EEDeltaToPose10Step(RobotActionProcessorStep):
    """End-effector deltas -> the ``ur5`` absolute pose10 action (orientation held, table frame).

    ``step_m``: metres per control step at full deflection (0.01 m = 0.2 m/s at 20 Hz);
    ``gripper_step_m``: how far the fingers open or close per step while the gripper key is held.
    """

    step_m: float = 0.01
    gripper_step_m: float = 0.005

    def action(self, action: dict) -> dict:
        """The absolute target: the observed pose moved by the deltas, the width by the gripper command."""
        observation = self.transition.get(TransitionKey.OBSERVATION) or {}
        missing = [k for k in POSE_KEYS if k not in observation]
        if missing:
            raise ValueError(f"EEDeltaToPose10Step needs the ur5 observation; missing {missing}")
        unknown = [k for k in action if k not in (*DELTA_KEYS, "gripper")]
        if unknown:
            raise ValueError(f"EEDeltaToPose10Step takes {list(DELTA_KEYS)} and 'gripper', got {unknown}")
        pose = np.array([float(observation[k]) for k in POSE_KEYS])
        delta = np.clip([float(action.get(k, 0.0)) for k in DELTA_KEYS], -1.0, 1.0)
        pose[:3] += self.step_m * delta
        gripper = float(action.get("gripper", 1.0))  # 0 close, 1 stay, 2 open (LeRobot's convention)
        pose[9] = np.clip(pose[9] + self.gripper_step_m * (gripper - 1.0), 0.0, MAX_GRIPPER_WIDTH)
        return {k: float(v) for k, v in zip(POSE_KEYS, pose, strict=True)}

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        """The action features become the ur5's pose10 keys, whatever the teleoperator's were."""
        actions = features.setdefault(PipelineFeatureType.ACTION, {})
        for key in (*DELTA_KEYS, "gripper"):
            actions.pop(key, None)
        for key in POSE_KEYS:
            actions[key] = PolicyFeature(type=FeatureType.ACTION, shape=(1,))
        return features

    def get_config(self) -> dict:
        """Saved with the pipeline."""
        return {"step_m": self.step_m, "gripper_step_m": self.gripper_step_m}
