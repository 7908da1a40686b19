"""Names of the observation and action keys, defined once.

The env speaks gymnasium's raw keys (``pixels/wrist``, ``agent_pos``, ``bbox``); LeRobot's
``preprocess_observation`` turns them into the dataset and policy keys (``observation.images.wrist``,
``observation.state``, ``observation.bbox``). Everything else imports these names.
"""

from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

# Raw env observation keys (what LegoPickEnv.step returns).
ENV_PIXELS = "pixels"
ENV_CAMERA = "wrist"
ENV_STATE = "agent_pos"
ENV_BBOX = "bbox"

# Dataset / policy keys (LeRobot's names).
WRIST_IMAGE = f"{OBS_IMAGES}.{ENV_CAMERA}"
STATE = OBS_STATE
BBOX = f"observation.{ENV_BBOX}"

__all__ = ["ACTION", "BBOX", "ENV_BBOX", "ENV_CAMERA", "ENV_PIXELS", "ENV_STATE", "STATE", "WRIST_IMAGE"]
