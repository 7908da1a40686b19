"""Counterfactual successes as imitation data: the honest baseline for a critic-based improvement.

``bboxpick-counterfactual --success_demos=true`` records every branch that ends in a pick, from its
branch point to the pick, as one episode of a LeRobotDataset with the collection schema
(``data.features``): the observation before each step, the action executed (the candidate's chunk,
then the policy's), the step's reward and success. Adding these episodes to the expert demos and
fine-tuning is what a critic must beat (issue 16: "compare against simply adding the counterfactual
successes to the imitation data").

Each worker writes the successes of its episode into ``<out_dir>/success_demos.parts/<episode>``;
``aggregate_success_demos`` merges them, in episode order, into ``<out_dir>/success_demos``.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

PARTS_DIR = "success_demos.parts"
DEMOS_DIR = "success_demos"
REPO_ID = "local/counterfactual_successes"

BranchHook = Callable[[np.ndarray, dict, float, dict], None]


class BranchFrames:
    """The frames of one branch, built from ``run_branch``'s step hook: frame t is the observation
    before step t (the snapshot's for t = 0), step t's action, reward and success."""

    def __init__(self, env: Any, observation: dict, task: str) -> None:
        layout = env.layout
        self.info = {
            "task": task,
            "seed": env.episode_seed,
            "setting": layout.setting,
            "target": layout.target,
        }
        self._obs = observation
        self.frames: list[dict] = []

    def hook(self, then: BranchHook | None = None) -> BranchHook:
        """A step hook that records the step, then calls ``then`` (the caller's own hook)."""
        from lerobot_bboxpick.data.collect import step_frame

        def on_step(action: np.ndarray, obs: dict, reward: float, info: dict) -> None:
            self.frames.append(step_frame(self._obs, self.info, action, reward, info))
            self._obs = obs
            if then is not None:
                then(action, obs, reward, info)

        return on_step


class SuccessDemos:
    """A LeRobotDataset of one counterfactual episode's picking branches, created at ``root`` with the
    first success (no folder when there is none)."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.dataset = None
        self.episodes = 0
        shutil.rmtree(self.root, ignore_errors=True)  # an interrupted earlier attempt

    def add(self, frames: list[dict]) -> None:
        """Save ``frames`` (a branch that picked) as one episode."""
        from lerobot_bboxpick.data.collect import close_episode
        from lerobot_bboxpick.data.features import create_dataset

        frames, _ = close_episode(frames, "pick")
        if self.dataset is None:
            self.dataset = create_dataset(REPO_ID, self.root)
        for frame in frames:
            self.dataset.add_frame(frame)
        with self._quiet():
            self.dataset.save_episode()
        self.episodes += 1

    def finalize(self) -> None:
        """Write the dataset's footers (call once, after the episode's last branch)."""
        if self.dataset is not None:
            with self._quiet():
                self.dataset.finalize()

    def _quiet(self):
        """The video encoder writes to file descriptor 2 directly: send it to a log beside the parts."""
        from lerobot_bboxpick.quiet import native_output_to

        return native_output_to(self.root.parent / "encoder.log")


def aggregate_success_demos(out_dir: Path) -> Path | None:
    """Merge every episode's part in ``out_dir`` (sorted by episode name, the order ``load_points`` reads
    branch points in; those without successes have no part) into ``out_dir/success_demos``; returns its
    path, or None if no branch picked. A resumed run that adds episodes rebuilds it from all of them."""
    from lerobot_bboxpick.data.collect import aggregate_roots
    from lerobot_bboxpick.quiet import native_output_to, quiet_libraries

    parts = sorted(p.parent for p in (Path(out_dir) / PARTS_DIR).glob("*/meta"))
    if not parts:
        return None
    dest = Path(out_dir) / DEMOS_DIR
    quiet_libraries()
    with native_output_to(Path(out_dir) / "aggregate.log"):  # LeRobot's copy bars, FFmpeg's muxer lines
        aggregate_roots(REPO_ID, parts, dest)
    return dest


def success_branches(points: Any) -> list[tuple[int, int]]:
    """``(point row, candidate)`` of every picking branch of ``points`` (a ``CounterfactualPoints`` of the
    same folder), in the order of ``success_demos``'s episodes: by episode name, point, then candidate."""
    from lerobot_bboxpick.sim.outcome import OUTCOMES

    pick = OUTCOMES.index("pick")
    rows, cols = np.nonzero(points.outcome == pick)  # row-major: point, then candidate
    return list(zip(rows.tolist(), cols.tolist(), strict=True))
