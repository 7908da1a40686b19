"""lerobot_bboxpick: target-specific picking for LeRobot.

Importing the package registers its components with LeRobot: the ``lego_pick`` env config.
"""

from lerobot_bboxpick.env_config import LegoPickEnvConfig

__all__ = ["LegoPickEnvConfig"]
__version__ = "0.1.0"
