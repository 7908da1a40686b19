"""Open-loop replay of recorded episodes, and pictures of a dataset's frames.

Replay proves the action representation before anyone trains on it: the recorded absolute TCP
actions, sent to a fresh env reset with the episode's seed, must pick the target again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm import tqdm

from lerobot_bboxpick.data.features import (
    ACTION,
    BBOX,
    EPISODE_SEED,
    EPISODE_SETTING,
    EPISODE_TARGET,
    STATE,
    WRIST_IMAGE,
)
from lerobot_bboxpick.sim.layouts import SETTINGS


def load_dataset(repo_id: str, root: str | Path):
    """A local LeRobotDataset (no Hub access)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(repo_id, root=root)


def episode_arrays(dataset, episode_index: int) -> dict[str, np.ndarray | int]:
    """Low-dimensional columns of one episode as numpy arrays, plus its seed/setting/target."""
    ep = dataset.meta.episodes[episode_index]
    rows = dataset.hf_dataset.select(range(ep["dataset_from_index"], ep["dataset_to_index"]))
    cols = rows.with_format("numpy")[:]
    return {
        "actions": np.asarray(cols[ACTION], dtype=np.float64),
        "states": np.asarray(cols[STATE], dtype=np.float64),
        "bboxes": np.asarray(cols[BBOX], dtype=np.float64),
        "seed": int(np.asarray(cols[EPISODE_SEED]).ravel()[0]),
        "setting": int(np.asarray(cols[EPISODE_SETTING]).ravel()[0]),
        "target": int(np.asarray(cols[EPISODE_TARGET]).ravel()[0]),
        "from": int(ep["dataset_from_index"]),
        "to": int(ep["dataset_to_index"]),
    }


def replay_dataset(repo_id: str, root: str | Path, episodes: list[int] | None = None) -> list[dict]:
    """Replay episodes open loop in fresh envs (same seed and setting); one record per episode."""
    from lerobot_bboxpick.sim.env import LegoPickEnv

    dataset = load_dataset(repo_id, root)
    episodes = list(range(dataset.num_episodes)) if episodes is None else episodes
    envs: dict[str, LegoPickEnv] = {}
    records = []
    for e in tqdm(episodes, desc="open-loop replay", unit="ep"):
        arrays = episode_arrays(dataset, e)
        setting = SETTINGS[arrays["setting"]]
        env = envs.setdefault(setting, LegoPickEnv(setting=setting, terminate_on_lift=False))
        env.reset(seed=arrays["seed"])
        if env.target != arrays["target"]:
            raise RuntimeError(
                f"episode {e}: seed {arrays['seed']} gives target {env.target}, "
                f"dataset says {arrays['target']} (env changed since recording?)"
            )
        info: dict = {}
        for a in arrays["actions"]:
            _, _, _, _, info = env.step(a)
        records.append({"episode": e, "seed": arrays["seed"], "setting": setting, "outcome": info["outcome"]})
    for env in envs.values():
        env.close()
    return records


def frame_image(dataset, index: int) -> np.ndarray:
    """The wrist image of a dataset frame as HWC uint8 RGB."""
    image = dataset[index][WRIST_IMAGE]
    return np.ascontiguousarray((image.permute(1, 2, 0).numpy() * 255).round().clip(0, 255).astype(np.uint8))


def dataset_sheet(repo_id: str, root: str | Path, episodes: list[int]) -> np.ndarray:
    """First and last frame of each episode with its recorded bbox drawn, two columns a row."""
    from lerobot_bboxpick.viz import contact_sheet, draw_bbox, label

    dataset = load_dataset(repo_id, root)
    tiles = []
    for e in episodes:
        arrays = episode_arrays(dataset, e)
        for name, idx in (("first", arrays["from"]), ("last", arrays["to"] - 1)):
            image = frame_image(dataset, idx)
            draw_bbox(image, arrays["bboxes"][idx - arrays["from"]])
            tiles.append(label(image, f"ep {e} {name} ({SETTINGS[arrays['setting']]})"))
    return contact_sheet(tiles, columns=4, scale=1)
