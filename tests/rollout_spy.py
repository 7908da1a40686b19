"""Run LeRobot's own ``lerobot-rollout`` entry point with a spy on what the robot reported and what the
bbox_diffusion policy received. A test helper: ``python tests/rollout_spy.py SPY_FILE <rollout args>``.

Each line of SPY_FILE is one event: ``{"robot_box": [...]}`` after every ``UR5.get_observation`` and
``{"policy_box": [...], "policy_state": [...]}`` for every batch the policy's ``select_action`` got (after
the checkpoint's preprocessor), so a test can check the policy saw the robot's box and pose.
"""

import json
import sys

import lerobot_bboxpick  # noqa: F401  (registration, as LeRobot's plugin import would do)
from lerobot_bboxpick.policies.bbox_diffusion.modeling_bbox_diffusion import BboxDiffusionPolicy
from lerobot_bboxpick.robots.ur5.ur5 import BBOX_KEYS, POSE_KEYS, UR5

spy_path = sys.argv.pop(1)
spy = open(spy_path, "a", buffering=1)  # noqa: SIM115  (open for the process's lifetime)

robot_observation = UR5.get_observation
policy_select_action = BboxDiffusionPolicy.select_action


def get_observation(self):
    obs = robot_observation(self)
    record = {"robot_box": [obs[k] for k in BBOX_KEYS], "robot_pose": [obs[k] for k in POSE_KEYS]}
    spy.write(json.dumps(record) + "\n")
    return obs


def select_action(self, batch, *args, **kwargs):
    box, state = batch.get("observation.bbox"), batch["observation.state"]
    record = {
        "policy_box": None if box is None else box.reshape(-1, box.shape[-1])[-1].tolist(),
        "policy_state": state.reshape(-1, state.shape[-1])[-1].tolist(),
    }
    spy.write(json.dumps(record) + "\n")
    return policy_select_action(self, batch, *args, **kwargs)


UR5.get_observation = get_observation
BboxDiffusionPolicy.select_action = select_action

from lerobot.scripts.lerobot_rollout import main  # noqa: E402

main()
