"""The LeRobotDataset schema every lerobot_bboxpick dataset uses (simulated, mirrored, imported UMI).

Poses are absolute TCP poses in the table frame (position, rot6d = first two rows of R, gripper
width), the same representation as the env's ``agent_pos`` and action. Per-episode facts (setting,
seed, target, outcome) are stored as constant per-frame integer columns so that they survive every
LeRobot dataset operation (aggregation, splitting, editing) without side files.
"""

from __future__ import annotations

import numpy as np

from lerobot_bboxpick.keys import ACTION, BBOX, STATE, WRIST_IMAGE
from lerobot_bboxpick.sim.layouts import SETTINGS
from lerobot_bboxpick.sim.outcome import OUTCOMES

POSE10_NAMES = ["x", "y", "z", "r00", "r01", "r02", "r10", "r11", "r12", "gripper_width"]
# Per-episode columns; the integer codes index SETTINGS and OUTCOMES (-1: not known, e.g. real data).
EPISODE_SEED = "episode.seed"
EPISODE_SETTING = "episode.setting"
EPISODE_TARGET = "episode.target"
EPISODE_OUTCOME = "episode.outcome"
FPS = 20
ROBOT_TYPE = "ur5e_umi"


def dataset_features(image_size: int = 224, use_video: bool = True) -> dict[str, dict]:
    """LeRobotDataset ``features`` of a lerobot_bboxpick dataset."""
    scalar = {"shape": (1,), "names": None}
    return {
        WRIST_IMAGE: {
            "dtype": "video" if use_video else "image",
            "shape": (image_size, image_size, 3),
            "names": ["height", "width", "channels"],
        },
        STATE: {"dtype": "float32", "shape": (10,), "names": POSE10_NAMES},
        BBOX: {"dtype": "float32", "shape": (4,), "names": ["x0", "y0", "x1", "y1"]},
        ACTION: {"dtype": "float32", "shape": (10,), "names": POSE10_NAMES},
        "next.reward": {"dtype": "float32", **scalar},
        "next.done": {"dtype": "bool", **scalar},
        "next.success": {"dtype": "bool", **scalar},
        EPISODE_SEED: {"dtype": "int64", **scalar},
        EPISODE_SETTING: {"dtype": "int64", **scalar},
        EPISODE_TARGET: {"dtype": "int64", **scalar},
        EPISODE_OUTCOME: {"dtype": "int64", **scalar},
    }


def create_dataset(repo_id: str, root, image_size: int = 224):
    """A new, empty LeRobotDataset with this schema at ``root`` (video, 20 fps, robot ``ur5e_umi``)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset.create(
        repo_id, FPS, dataset_features(image_size), root=root, robot_type=ROBOT_TYPE, use_videos=True
    )


def setting_code(setting: str | None) -> int:
    """Integer code of a setting name (-1 for None)."""
    return -1 if setting is None else SETTINGS.index(setting)


def outcome_code(outcome: str | None) -> int:
    """Integer code of an outcome name (-1 for None)."""
    return -1 if outcome is None else OUTCOMES.index(outcome)


def make_frame(
    image: np.ndarray,
    state: np.ndarray,
    bbox: np.ndarray,
    action: np.ndarray,
    task: str,
    *,
    reward: float = 0.0,
    done: bool = False,
    success: bool = False,
    seed: int = -1,
    setting: str | None = None,
    target: int = -1,
    outcome: str | None = None,
) -> dict:
    """One ``LeRobotDataset.add_frame`` dict with the exact dtypes and shapes of ``dataset_features``."""
    return {
        WRIST_IMAGE: np.asarray(image, dtype=np.uint8),
        STATE: np.asarray(state, dtype=np.float32).reshape(10),
        BBOX: np.asarray(bbox, dtype=np.float32).reshape(4),
        ACTION: np.asarray(action, dtype=np.float32).reshape(10),
        "next.reward": np.array([reward], dtype=np.float32),
        "next.done": np.array([done], dtype=bool),
        "next.success": np.array([success], dtype=bool),
        EPISODE_SEED: np.array([seed], dtype=np.int64),
        EPISODE_SETTING: np.array([setting_code(setting)], dtype=np.int64),
        EPISODE_TARGET: np.array([target], dtype=np.int64),
        EPISODE_OUTCOME: np.array([outcome_code(outcome)], dtype=np.int64),
        "task": task,
    }
