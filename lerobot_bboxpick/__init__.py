"""lerobot_bboxpick: target-specific picking for LeRobot.

Importing the package registers its components with LeRobot: the ``lego_pick`` env config, the
``bbox_diffusion`` policy config, the ``ur5`` robot and the ``bboxpick_expert`` teleoperator.
"""

import os

# Headless rendering with Mesa's EGL (FACTS.md section 3). It must be set before mujoco is first
# imported anywhere in the process, and every sim module is reached through this package.
os.environ.setdefault("MUJOCO_GL", "egl")

from lerobot_bboxpick.policies.bbox_diffusion import BboxDiffusionConfig  # noqa: E402
from lerobot_bboxpick.robots.ur5 import UR5Config  # noqa: E402
from lerobot_bboxpick.sim.env_config import LegoPickEnvConfig  # noqa: E402
from lerobot_bboxpick.teleoperators.bboxpick_expert import BboxpickExpertConfig  # noqa: E402

__all__ = ["BboxDiffusionConfig", "BboxpickExpertConfig", "LegoPickEnvConfig", "UR5Config"]
__version__ = "0.1.0"
