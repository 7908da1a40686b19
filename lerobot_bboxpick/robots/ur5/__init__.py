"""``--robot.type=ur5``. LeRobot finds the robot class ``UR5`` here from the config's name (``UR5Config``)."""

from lerobot_bboxpick.robots.ur5.configuration_ur5 import UR5Config
from lerobot_bboxpick.robots.ur5.ur5 import UR5

__all__ = ["UR5", "UR5Config"]
