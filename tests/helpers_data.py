"""Test helpers: small real datasets recorded from the scripted expert in the MuJoCo env."""

from __future__ import annotations

from pathlib import Path

from lerobot.datasets.lerobot_dataset import LeRobotDataset

import lerobot_bboxpick  # noqa: F401  (sets MUJOCO_GL before MuJoCo loads)
from lerobot_bboxpick.data.collect import record_episode
from lerobot_bboxpick.data.features import create_dataset
from lerobot_bboxpick.sim.env import LegoPickEnv


def record_expert_episode(env: LegoPickEnv, seed: int) -> list[dict]:
    """One scripted-expert episode as a list of ``make_frame`` dicts (every control step kept).

    Frame t holds the observation before step t, the action of step t and step t's reward/done/success.
    """
    return record_episode(env, seed)[0]


def make_expert_dataset(
    root: Path, seeds: list[int], setting: str = "grid_id", repo_id: str = "test/expert"
) -> LeRobotDataset:
    """A finalized video LeRobotDataset at ``root`` with one expert episode per seed (fps 20)."""
    env = LegoPickEnv(setting=setting, terminate_on_lift=False)
    ds = create_dataset(repo_id, root)
    try:
        for seed in seeds:
            for frame in record_expert_episode(env, seed):
                ds.add_frame(frame)
            ds.save_episode()
    finally:
        ds.finalize()
        env.close()
    return LeRobotDataset(repo_id, root=root)
