"""Test helpers: small real datasets recorded from the scripted expert in the MuJoCo env."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset

import lerobot_bboxpick  # noqa: F401  (sets MUJOCO_GL before MuJoCo loads)
from lerobot_bboxpick.data.features import FPS, ROBOT_TYPE, dataset_features, make_frame
from lerobot_bboxpick.expert import ScriptedExpert
from lerobot_bboxpick.sim.env import LegoPickEnv


def record_expert_episode(env: LegoPickEnv, seed: int) -> list[dict]:
    """One scripted-expert episode as a list of ``make_frame`` dicts (every control step kept).

    Frame t holds the observation before step t, the action of step t and step t's reward/done/success.
    """
    obs, info = env.reset(seed=seed)
    expert = ScriptedExpert(np.random.default_rng(seed))
    expert.reset(env)
    steps = []
    while not expert.done:
        action = expert.act()
        next_obs, reward, _, _, info = env.step(action)
        steps.append((obs, action, reward, info["is_success"]))
        obs = next_obs
    return [
        make_frame(
            o["pixels"]["wrist"],
            o["agent_pos"],
            o["bbox"],
            a,
            env.task_description,
            reward=r,
            done=i == len(steps) - 1,
            success=s,
            seed=seed,
            setting=env.options.setting,
            target=env.target,
            outcome=info["outcome"],
        )
        for i, (o, a, r, s) in enumerate(steps)
    ]


def make_expert_dataset(
    root: Path, seeds: list[int], setting: str = "grid_id", repo_id: str = "test/expert"
) -> LeRobotDataset:
    """A finalized video LeRobotDataset at ``root`` with one expert episode per seed (fps 20)."""
    env = LegoPickEnv(setting=setting, terminate_on_lift=False)
    ds = LeRobotDataset.create(repo_id, FPS, dataset_features(), root=root, robot_type=ROBOT_TYPE)
    try:
        for seed in seeds:
            for frame in record_expert_episode(env, seed):
                ds.add_frame(frame)
            ds.save_episode()
    finally:
        ds.finalize()
        env.close()
    return LeRobotDataset(repo_id, root=root)
