"""How much of the demo's turn a policy reproduces on the demos' own frames (teacher forcing).

A trace shows a policy's gripper arriving unturned at a turned brick; this asks whether the policy learned
the turn at all: fed the observation of a training frame, does its chunk turn the gripper as the demo's
chunk from that frame does? Per frame it measures the yaw change (degrees, about the vertical) from the
observed pose to the chunk's last pose, for the demo and for one sampled chunk.

    lerobot_bboxpick turn-fit --policy outputs/train/checkpoints/last/pretrained_model \
        --dataset outputs/data --settings random_id,pile_id --frames 0,16,32
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_bboxpick.data.features import EPISODE_SETTING
from lerobot_bboxpick.geometry import pose9_to_mat
from lerobot_bboxpick.sim.expert import tcp_yaw
from lerobot_bboxpick.sim.layouts import SETTINGS, check_setting


@dataclass(frozen=True)
class ChunkTurn:
    """One frame's turn over a chunk: the demo's and the policy's (degrees, signed)."""

    episode: int
    setting: str
    frame: int
    demo_deg: float
    policy_deg: float


def yaw_change_deg(pose10: np.ndarray, start_pose10: np.ndarray) -> float:
    """The yaw of ``pose10`` minus that of ``start_pose10`` (each about the vertical from the top-down
    pose, as the expert turns), degrees wrapped to [-180, 180)."""

    def yaw(p: np.ndarray) -> float:
        return float(np.degrees(tcp_yaw(pose9_to_mat(np.asarray(p[:9], dtype=np.float64)))))

    return (yaw(pose10) - yaw(start_pose10) + 180.0) % 360.0 - 180.0


def chunk_turns(
    predict: Callable[[dict[str, Any]], np.ndarray],
    dataset: Any,
    settings: Sequence[str],
    frames: Sequence[int],
) -> list[ChunkTurn]:
    """Turns over the chunk from ``frames`` (offsets into each episode) of the episodes of ``settings``.

    ``dataset`` is a LeRobotDataset whose ``action`` is a window of chunk length; ``predict`` maps one of
    its items to the policy's absolute chunk (horizon, 10).
    """
    for setting in settings:
        check_setting(setting)
    starts = dataset.meta.episodes["dataset_from_index"]
    ends = dataset.meta.episodes["dataset_to_index"]
    turns = []
    for episode in range(dataset.meta.total_episodes):
        first, length = int(starts[episode]), int(ends[episode]) - int(starts[episode])
        setting = SETTINGS[int(dataset.hf_dataset[first][EPISODE_SETTING])]  # the column: no video decode
        if setting not in settings:
            continue
        for frame in frames:
            if frame >= length:
                continue
            item = dataset[first + frame]
            state = item["observation.state"].numpy()
            demo = item["action"].numpy()
            turns.append(
                ChunkTurn(
                    episode,
                    setting,
                    frame,
                    yaw_change_deg(demo[-1], state),
                    yaw_change_deg(np.asarray(predict(item))[-1], state),
                )
            )
    return turns


def turn_summary(turns: Sequence[ChunkTurn], min_turn_deg: float = 3.0) -> str:
    """Markdown: per frame offset and over all, on the frames whose demo turns more than
    ``min_turn_deg``: the mean |turn| of demo and policy, their ratio and correlation."""
    header = (
        f"| frame | frames | demo turns > {min_turn_deg:g} deg | mean demo turn (deg) "
        "| mean policy turn (deg) | policy / demo | correlation |\n|---|---|---|---|---|---|---|"
    )
    groups = [(str(f), [t for t in turns if t.frame == f]) for f in sorted({t.frame for t in turns})]
    lines = [header]
    for label, group in [*groups, ("all", list(turns))]:
        turning = [t for t in group if abs(t.demo_deg) > min_turn_deg]
        if not turning:
            lines.append(f"| {label} | {len(group)} | 0 | - | - | - | - |")
            continue
        demo = np.array([t.demo_deg for t in turning])
        policy = np.array([t.policy_deg for t in turning])
        corr = np.corrcoef(demo, policy)[0, 1] if len(turning) > 1 and policy.std() > 0 else float("nan")
        demo_mean, policy_mean = np.abs(demo).mean(), np.abs(policy).mean()
        lines.append(
            f"| {label} | {len(group)} | {len(turning)} | {demo_mean:.1f} | {policy_mean:.1f} "
            f"| {policy_mean / demo_mean:.2f} | {corr:.2f} |"
        )
    return "\n".join(lines) + "\n"


def run_turn_fit(
    policy: str | Path,
    dataset_root: str | Path,
    settings: Sequence[str],
    frames: Sequence[int],
    num_inference_steps: int | None = None,
    seed: int = 0,
) -> str:
    """The turn table of the checkpoint ``policy`` on the dataset at ``dataset_root`` (one sampled chunk
    per frame, from a generator seeded by ``seed``)."""
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    from lerobot_bboxpick.eval.rollout import PolicyRunner

    runner = PolicyRunner.from_pretrained(policy, num_inference_steps=num_inference_steps)
    horizon = runner.policy.config.horizon
    fps = LeRobotDatasetMetadata("local/turn_fit", root=dataset_root).fps
    dataset = LeRobotDataset(
        "local/turn_fit", root=dataset_root, delta_timestamps={"action": [i / fps for i in range(horizon)]}
    )
    generator = torch.Generator().manual_seed(seed)

    @torch.no_grad()
    def predict(item: dict[str, Any]) -> np.ndarray:
        observation = {k: v.unsqueeze(0) for k, v in item.items() if k.startswith("observation.")}
        observation["task"] = [item["task"]]
        runner.reset()
        batch = {
            k: v
            for k, v in runner.preprocessor(observation).items()
            if k.startswith("observation.") and torch.is_tensor(v)
        }
        chunk = runner.policy.predict_action_chunk(batch, generator=generator)
        return runner.postprocessor(chunk)[0].cpu().numpy().astype(np.float64)

    return turn_summary(chunk_turns(predict, dataset, settings, frames))
