"""Where a policy's gripper is, relative to its target, when it closes: the numbers behind a miss.

A suite says *that* an episode ended Empty; the trace says why, in the target brick's terms: how far the
fingertips (the TCP) were beside and above the brick's bottom face, and how far the gripper was turned
from the brick's grasp yaw, at the first step the policy commanded the gripper shut. The expert closes
centred, 8 mm above the bottom face, turned onto the brick (``test_trace``).

    lerobot_bboxpick trace --policy examples/bbox_diffusion_lego_pick --setting random_id \
        --seeds 5001,5003 --out docs/results/trace.md
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_bboxpick.sim.expert import OPEN_WIDTH


def yaw_error_deg(tcp_rotation: np.ndarray, brick_rotation: np.ndarray) -> float:
    """The gripper's yaw minus the brick's, in degrees wrapped to [-45, 45): a quarter turn of either
    lines the fingers up with a face of the brick."""
    tcp = np.degrees(np.arctan2(tcp_rotation[1, 0], tcp_rotation[0, 0]))
    brick = np.degrees(np.arctan2(brick_rotation[1, 0], brick_rotation[0, 0]))
    return float((tcp - brick + 45.0) % 90.0 - 45.0)


@dataclass
class EpisodeTrace:
    """One episode's trace: per step, the TCP's offset from the target's bottom-face centre (m, table
    frame), the yaw error (degrees) and the commanded gripper width (m); and the episode's outcome."""

    setting: str
    seed: int
    outcome: str
    offsets: np.ndarray  # (T, 3)
    yaw_errors: np.ndarray  # (T,)
    gripper_commands: np.ndarray  # (T,)

    def close_step(self) -> int | None:
        """First step the gripper is commanded under half open (None: it never closes)."""
        closing = np.flatnonzero(self.gripper_commands < OPEN_WIDTH / 2)
        return int(closing[0]) if closing.size else None


def trace_episode(runner: Any, env: Any, setting: str, seed: int) -> EpisodeTrace:
    """Run ``runner`` (``PolicyRunner`` or ``ExpertRunner``) on scene ``seed`` of ``env``'s setting, as the
    suite runs it, recording every action with the pose it led to."""
    from lerobot_bboxpick.eval.rollout import rollout

    offsets, yaw_errors, commands = [], [], []

    def record(obs: dict, info: dict, action: np.ndarray, reward: float, next_info: dict) -> None:
        # on_step runs once the env has stepped: each action is recorded with the pose it led to
        commands.append(float(action[-1]))
        tcp, brick = env.tcp_pose(), env.brick_pose(env.target)
        offsets.append(tcp[:3, 3] - brick[:3, 3])
        yaw_errors.append(yaw_error_deg(tcp[:3, :3], brick[:3, :3]))

    result = rollout(runner, setting=setting, seed=seed, policy_seed=seed, env=env, on_step=record)
    return EpisodeTrace(
        setting, seed, result["outcome"], np.array(offsets), np.array(yaw_errors), np.array(commands)
    )


def trace_table(traces: list[EpisodeTrace]) -> str:
    """Markdown: per episode, the outcome, the yaw error after the first step, and at the close the
    TCP's distance beside the target (mm), its height above the target's bottom face (mm) and the yaw
    error (degrees)."""
    lines = [
        "| setting | seed | outcome | yaw error, step 1 (deg) | close step | beside (mm) | above (mm) "
        "| yaw error at close (deg) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for t in traces:
        k = t.close_step()
        at_close = (
            ["-", "-", "-", "-"]
            if k is None
            else [
                str(k),
                f"{1000 * np.linalg.norm(t.offsets[k, :2]):.0f}",
                f"{1000 * t.offsets[k, 2]:.0f}",
                f"{round(t.yaw_errors[k]):+d}",
            ]
        )
        row = [t.setting, str(t.seed), t.outcome, f"{round(t.yaw_errors[0]):+d}", *at_close]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def run_trace(policy: str, setting: str, seeds: list[int], num_inference_steps: int | None) -> str:
    """The trace table of ``policy`` (a checkpoint folder or ``expert``) on ``seeds`` of ``setting``."""
    import contextlib
    import io

    from lerobot_bboxpick.eval.rollout import ExpertRunner, PolicyRunner
    from lerobot_bboxpick.sim.env import LegoPickEnv

    env = LegoPickEnv(setting=setting, episode_length=300)
    try:
        if policy == "expert":
            runner: Any = ExpertRunner(env)
        else:
            with contextlib.redirect_stdout(io.StringIO()):  # LeRobot prints "Loading weights ..."
                runner = PolicyRunner.from_pretrained(policy, num_inference_steps=num_inference_steps)
        return trace_table([trace_episode(runner, env, setting, seed) for seed in seeds])
    finally:
        env.close()


def write_trace(table: str, out: Path | None) -> None:
    """Print ``table`` and write it to ``out`` too (if given)."""
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(table)
    print(table, end="")
