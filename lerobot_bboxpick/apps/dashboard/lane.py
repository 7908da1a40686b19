"""One lane of a run: one policy's episode in its own env, step by step, recorded for the page.

Side by side runs two lanes on the same scene (same setting, seed and target, so identical first
frames) and steps them in turn, once per tick. The policy's box is the drawn one on the first frame,
then the tracker's (``BboxSource("tracked")`` started from the drawn box), or the env's exact box
every frame (``oracle``, a check of the policy without the tracker's errors).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from lerobot_bboxpick.apps.dashboard.policies import PolicyChoice
from lerobot_bboxpick.apps.dashboard.views import ThirdPersonView, encode_jpeg
from lerobot_bboxpick.eval.bbox_source import BboxSource
from lerobot_bboxpick.keys import ENV_BBOX
from lerobot_bboxpick.viz import draw_bbox

BBOX_MODES: tuple[str, ...] = ("tracked", "oracle")
POLICY_BOX_COLOR = (255, 220, 0)  # yellow: the box the policy is given (the env's own box is white)


@dataclass
class StepRecord:
    """What happened at one control step: the box the policy was given and the action it returned."""

    t: int
    policy_bbox: list[float]
    action: list[float]
    env_bbox: list[float]
    bbox_visibility: str
    outcome: str

    def as_json(self) -> dict:
        """JSON form (plain floats)."""
        return {
            "t": self.t,
            "policy_bbox": self.policy_bbox,
            "action": self.action,
            "env_bbox": self.env_bbox,
            "bbox_visibility": self.bbox_visibility,
            "outcome": self.outcome,
        }


@dataclass
class Lane:
    """A policy's episode: ``start`` resets the env on the scene, each ``step`` runs one control step."""

    slot: str
    choice: PolicyChoice
    env: Any
    runner: Any
    view: ThirdPersonView
    max_steps: int
    bbox_mode: str = "tracked"
    records: list[StepRecord] = field(default_factory=list)
    frames: list[tuple[bytes, bytes]] = field(default_factory=list)  # (wrist, third person) JPEG per frame
    outcome: str = "empty"
    done: bool = False
    sim_unstable: bool = False
    seconds: float = 0.0
    _obs: dict | None = None
    _info: dict | None = None
    _source: BboxSource | None = None
    _env_box: np.ndarray | None = None

    def start(self, seed: int, target: int, drawn_box: np.ndarray, policy_seed: int = 0) -> None:
        """Reset the env on scene ``seed`` with brick ``target``; the policy's first box is ``drawn_box``."""
        if self.bbox_mode not in BBOX_MODES:
            raise ValueError(f"bbox_mode={self.bbox_mode!r} is not known; valid: {', '.join(BBOX_MODES)}")
        obs, info = self.env.reset(seed=seed, options={"target": target})
        self._source = BboxSource(self.bbox_mode)
        # The tracked source starts from the observation's box: hand it the drawn one.
        first = {**obs, ENV_BBOX: np.asarray(drawn_box, np.float32)} if self.bbox_mode == "tracked" else obs
        self._env_box = np.asarray(obs[ENV_BBOX], dtype=np.float32)  # the env's own box of the frame
        self._obs, self._info = self._source.reset(first, seed), info
        torch.manual_seed(policy_seed)
        self.runner.reset()
        self.records, self.frames = [], [self._frame()]
        self.outcome, self.done, self.sim_unstable, self.seconds = info["outcome"], False, False, 0.0

    @property
    def policy_bbox(self) -> np.ndarray:
        """The box the policy is given at the current step."""
        assert self._obs is not None, "start() the lane first"
        return np.asarray(self._obs[ENV_BBOX], dtype=np.float32)

    @property
    def steps(self) -> int:
        """Control steps taken."""
        return len(self.records)

    def step(self) -> None:
        """One control step (nothing once the episode has ended)."""
        if self.done:
            return
        assert self._obs is not None and self._info is not None and self._source is not None
        assert self._env_box is not None
        t0 = time.perf_counter()
        given = self.policy_bbox
        action = np.asarray(self.runner.act(self._obs, self._info["task"]), dtype=np.float64)
        obs, _, terminated, truncated, info = self.env.step(action)
        self.records.append(
            StepRecord(
                t=len(self.records),
                policy_bbox=[float(v) for v in given],
                action=[float(v) for v in action],
                env_bbox=[float(v) for v in self._env_box],
                bbox_visibility=self._info["bbox_visibility"],
                outcome=info["outcome"],
            )
        )
        self._env_box = np.asarray(obs[ENV_BBOX], dtype=np.float32)
        self._obs, self._info = self._source(obs), info
        self.outcome, self.sim_unstable = info["outcome"], bool(info["sim_unstable"])
        self.done = terminated or truncated or self.steps >= self.max_steps
        self.frames.append(self._frame())
        self.seconds += time.perf_counter() - t0

    def _frame(self) -> tuple[bytes, bytes]:
        image = self.env.render()
        box = self.policy_bbox
        if box[2] > box[0] and box[3] > box[1]:
            draw_bbox(image, box, color=POLICY_BOX_COLOR)
        return encode_jpeg(image), encode_jpeg(self.view.render(self.env.data))

    def summary(self) -> dict:
        """The lane's result: outcome, steps, the box statistics, and the final gripper-target distance."""
        distance = float(
            np.linalg.norm(self.env.tcp_pose()[:3, 3] - self.env.brick_pose(self.env.target)[:3, 3])
        )
        assert self._source is not None
        return {
            "slot": self.slot,
            "policy": self.choice.id,
            "label": self.choice.label,
            "path": None if self.choice.path is None else str(self.choice.path),
            "bbox_mode": self.bbox_mode,
            "outcome": self.outcome,
            "done": self.done,
            "steps": self.steps,
            "final_distance_m": distance,
            "sim_unstable": self.sim_unstable,
            "bbox_mean_iou": self._source.mean_iou,
            "bbox_lost_frames": self._source.lost_frames,
            "seconds": round(self.seconds, 3),
        }
