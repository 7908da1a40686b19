"""``--teleop.type=bboxpick_expert``. LeRobot finds ``BboxpickExpert`` here from ``BboxpickExpertConfig``."""

from lerobot_bboxpick.teleoperators.bboxpick_expert.bboxpick_expert import BboxpickExpert
from lerobot_bboxpick.teleoperators.bboxpick_expert.configuration_bboxpick_expert import BboxpickExpertConfig

__all__ = ["BboxpickExpert", "BboxpickExpertConfig"]
