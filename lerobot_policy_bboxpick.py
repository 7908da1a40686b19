"""LeRobot plugin entry point.

LeRobot's CLIs import every installed distribution whose name starts with ``lerobot_policy_`` (and
the other plugin prefixes) by that exact name. Importing this module registers everything
lerobot_bboxpick contributes (the ``lego_pick`` env and the ``bbox_diffusion`` policies).
"""

import lerobot_bboxpick  # noqa: F401  (import registers the components)
