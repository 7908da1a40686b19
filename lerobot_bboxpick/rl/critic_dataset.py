"""A LeRobotDataset with outcome labels (our schema) -> IQL transitions over action chunks.

One transition per frame ``t`` of an episode, up to its terminal frame ``T``:

* state: the observation at ``t`` with the policy's history (``n_obs_steps`` frames ending at ``t``,
  the first frame repeated at an episode's start, as LeRobot pads);
* action: the dataset's absolute actions ``t .. t + horizon - 1`` (the last one repeated past the end),
  made relative to the TCP pose observed at ``t`` with ``geometry.relative_pose10`` (the policy's space);
* next state: the observation at ``t + stride`` (``stride``: the steps the policy executes per chunk);
* reward: sparse and terminal (paper section 4.2): the episode's outcome reward when ``T`` falls inside
  the chunk's ``stride`` steps (``done``), else 0. Outcomes map to groups ``pick -> success``,
  ``contact``/``empty -> miss``, ``wrong -> wrong``. The terminal frame of a success is the first frame
  whose ``next.success`` is set (what follows is carrying the brick away); a failure ends at its last
  frame. With ``discount_per_step`` (Q-chunking) the reward is discounted by ``gamma ** (T - t)`` and
  the bootstrap by ``gamma ** stride``; otherwise by 1 and ``gamma`` per chunk.

The dataset's own ``next.reward`` column is not used: the env writes 1 on every step after a pick.
The validation split holds out whole episodes (stratified by outcome group).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch
from torch import Tensor
from tqdm import tqdm

from lerobot_bboxpick.data.features import EPISODE_OUTCOME
from lerobot_bboxpick.geometry import relative_pose10
from lerobot_bboxpick.keys import ACTION, BBOX, STATE, WRIST_IMAGE
from lerobot_bboxpick.sim.outcome import OUTCOMES

OUTCOME_GROUPS: tuple[str, ...] = ("success", "miss", "wrong")
GROUP_OF_OUTCOME = {"pick": "success", "contact": "miss", "empty": "miss", "wrong": "wrong"}
PHASES: tuple[str, ...] = ("start", "mid", "near_terminal", "terminal")
SUCCESS = "next.success"
DEFAULT_TOLERANCE_S = 1e-4  # LeRobotDataset's default timestamp tolerance


@dataclass
class CriticDataConfig:
    """Which dataset, and how its episodes become transitions."""

    repo_id: str = "local/critic"
    # Local dataset folder (None: LeRobot's cache for repo_id).
    root: Path | None = None
    # Env steps between a transition's state and its next state; None: the policy's n_action_steps
    # (Q then values exactly what the policy executes before it predicts again).
    chunk_stride: int | None = None
    # Terminal rewards per outcome group. A wrong pick is scored below a miss: it moves a brick the
    # user did not ask for (the paper's ordering test expects success > miss > wrong).
    success_reward: float = 1.0
    miss_reward: float = 0.0
    wrong_reward: float = -1.0
    discount_per_step: bool = True
    terminal_at_success: bool = True
    # Fraction of episodes held out (per outcome group), and the seed that picks them.
    val_fraction: float = 0.1
    split_seed: int = 0
    # Phases for the diagnostics, in env steps: "start" = the first start_steps frames; "near_terminal"
    # = the near_terminal_steps before the final chunk; "terminal" = transitions whose chunk ends it.
    start_steps: int = 20
    near_terminal_steps: int = 40
    # Frames of a success this many steps before the gripper is commanded closed are "pre-grasp".
    pregrasp_steps: int = 40

    def __post_init__(self) -> None:
        self.root = Path(self.root) if self.root is not None else None
        if self.chunk_stride is not None and self.chunk_stride < 1:
            raise ValueError(f"chunk_stride={self.chunk_stride} must be >= 1 (or None: the policy's)")
        if not 0.0 <= self.val_fraction < 1.0:
            raise ValueError(f"val_fraction={self.val_fraction} must be in [0, 1)")
        for name in ("start_steps", "near_terminal_steps", "pregrasp_steps"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name}={getattr(self, name)} must be >= 0")

    def reward_of(self, group: str) -> float:
        """Terminal reward of an outcome group."""
        if group not in OUTCOME_GROUPS:
            raise ValueError(f"outcome group {group!r} is not one of {', '.join(OUTCOME_GROUPS)}")
        return {"success": self.success_reward, "miss": self.miss_reward, "wrong": self.wrong_reward}[group]


@dataclass
class FrameTable:
    """The dataset's low-dimensional columns, one row per frame (rows of ``hf_dataset``)."""

    state: np.ndarray  # (F, 10) absolute TCP pose10
    bbox: np.ndarray  # (F, 4)
    action: np.ndarray  # (F, 10) absolute
    success: np.ndarray  # (F,) next.success
    outcome: np.ndarray  # (F,) episode.outcome codes (index into OUTCOMES)
    episode_bounds: np.ndarray  # (E, 2) [start row, end row) of each episode
    episode_ids: np.ndarray  # (E,) the dataset's episode_index

    @property
    def num_frames(self) -> int:
        """Rows."""
        return len(self.state)


def load_frame_table(dataset) -> FrameTable:
    """Read the columns the critic needs from a ``LeRobotDataset`` (no video decoding)."""
    required = [STATE, BBOX, ACTION, SUCCESS, EPISODE_OUTCOME, WRIST_IMAGE]
    missing = [k for k in required if k not in dataset.features]
    if missing:
        raise ValueError(
            f"dataset {dataset.repo_id} lacks the feature(s) {missing}: the critic needs a dataset with "
            "lerobot_bboxpick's schema (lerobot_bboxpick.data.features) and outcome labels"
        )
    cols = dataset.hf_dataset.select_columns([STATE, BBOX, ACTION, SUCCESS, EPISODE_OUTCOME, "episode_index"])
    cols = cols.with_format("numpy")[:]
    ep = cols["episode_index"].reshape(-1)
    if len(ep) and np.any(np.diff(ep) < 0):
        raise ValueError("dataset rows are not grouped by episode (episode_index decreases)")
    change = np.flatnonzero(np.diff(ep)) + 1
    starts = np.concatenate([[0], change]).astype(int)
    ends = np.concatenate([change, [len(ep)]]).astype(int)
    return FrameTable(
        state=cols[STATE].reshape(-1, 10).astype(np.float64),
        bbox=cols[BBOX].reshape(-1, 4).astype(np.float32),
        action=cols[ACTION].reshape(-1, 10).astype(np.float64),
        success=cols[SUCCESS].reshape(-1).astype(bool),
        outcome=cols[EPISODE_OUTCOME].reshape(-1).astype(int),
        episode_bounds=np.stack([starts, ends], axis=1),
        episode_ids=ep[starts],
    )


@dataclass
class Transitions:
    """Chunk transitions (numpy, one row each); rows index ``FrameTable`` rows."""

    obs_row: np.ndarray  # (N,) frame t
    next_row: np.ndarray  # (N,) frame t + stride (= t where done; then unused)
    actions: np.ndarray  # (N, H, 10) float32 chunk relative to the pose at t
    base_pose: np.ndarray  # (N, 10) float64 absolute TCP pose at t (the chunk's base)
    reward: np.ndarray  # (N,) float32
    done: np.ndarray  # (N,) bool
    discount: np.ndarray  # (N,) float32
    group: np.ndarray  # (N,) index into OUTCOME_GROUPS
    phase: np.ndarray  # (N,) index into PHASES
    episode: np.ndarray  # (N,) position of the episode in FrameTable.episode_bounds
    progress: np.ndarray  # (N,) (t - start) / (T - start) in [0, 1]
    steps_to_end: np.ndarray  # (N,) T - t
    pregrasp: np.ndarray  # (N,) bool: a success frame shortly before the gripper closes
    is_val: np.ndarray  # (N,) bool: the episode is held out

    def __len__(self) -> int:
        return len(self.obs_row)

    def subset(self, mask: np.ndarray) -> Transitions:
        """The rows where ``mask`` (bool or indices) selects."""
        return Transitions(**{f.name: getattr(self, f.name)[mask] for f in fields(self)})


def episode_group(table: FrameTable, e: int) -> str:
    """Outcome group of episode ``e``; a clear error when the episode has no (valid) outcome label."""
    a, b = table.episode_bounds[e]
    codes = np.unique(table.outcome[a:b])
    if len(codes) != 1 or not 0 <= codes[0] < len(OUTCOMES):
        raise ValueError(
            f"episode {table.episode_ids[e]} has episode.outcome {codes.tolist()}: the critic needs one "
            f"outcome label per episode, an index into {list(OUTCOMES)} (-1 means unlabelled)"
        )
    return GROUP_OF_OUTCOME[OUTCOMES[codes[0]]]


def split_episodes(groups: list[str], val_fraction: float, seed: int) -> np.ndarray:
    """Held-out mask over episodes: ``round(val_fraction * n)`` of each outcome group, at least one
    episode overall when there are two or more and ``val_fraction > 0``."""
    rng = np.random.default_rng(seed)
    groups_arr = np.asarray(groups)
    is_val = np.zeros(len(groups), dtype=bool)
    for g in OUTCOME_GROUPS:
        idx = np.flatnonzero(groups_arr == g)
        n_val = int(np.floor(val_fraction * len(idx) + 0.5))
        is_val[rng.permutation(idx)[:n_val]] = True
    if val_fraction > 0 and len(groups) >= 2 and not is_val.any():
        is_val[rng.integers(len(groups))] = True
    return is_val


def build_transitions(
    table: FrameTable, cfg: CriticDataConfig, horizon: int, stride: int, gamma: float
) -> Transitions:
    """All transitions of ``table`` (see the module docstring)."""
    if stride < 1 or horizon < 1:
        raise ValueError(f"stride={stride} and horizon={horizon} must be >= 1")
    groups = [episode_group(table, e) for e in range(len(table.episode_bounds))]
    val_episodes = split_episodes(groups, cfg.val_fraction, cfg.split_seed)
    out: dict[str, list] = {f.name: [] for f in fields(Transitions)}
    for e, (a, b) in enumerate(table.episode_bounds):
        group = groups[e]
        hits = np.flatnonzero(table.success[a:b])
        T = a + int(hits[0]) if group == "success" and cfg.terminal_at_success and len(hits) else b - 1
        t = np.arange(a, T + 1)
        steps_to_end = T - t
        done = steps_to_end < stride
        reward_scale = gamma**steps_to_end if cfg.discount_per_step else np.ones(len(t))
        reward = np.where(done, cfg.reward_of(group) * reward_scale, 0.0)
        chunk_rows = np.minimum(t[:, None] + np.arange(horizon)[None, :], b - 1)
        base = table.state[t]
        rel = relative_pose10(table.action[chunk_rows], base[:, None, :])
        phase = np.where(
            done,
            PHASES.index("terminal"),
            np.where(
                steps_to_end < stride + cfg.near_terminal_steps,
                PHASES.index("near_terminal"),
                np.where(t - a < cfg.start_steps, PHASES.index("start"), PHASES.index("mid")),
            ),
        )
        pregrasp = np.zeros(len(t), dtype=bool)
        if group == "success":
            width = table.action[a : T + 1, 9]
            closing = np.flatnonzero(width < 0.5 * width.max())
            if len(closing):
                g = a + int(closing[0])
                pregrasp = (t >= g - cfg.pregrasp_steps) & (t < g)
        out["obs_row"].append(t)
        out["next_row"].append(np.where(done, t, np.minimum(t + stride, b - 1)))
        out["actions"].append(rel.astype(np.float32))
        out["base_pose"].append(base)
        out["reward"].append(reward.astype(np.float32))
        out["done"].append(done)
        out["discount"].append(np.full(len(t), gamma**stride if cfg.discount_per_step else gamma, np.float32))
        out["group"].append(np.full(len(t), OUTCOME_GROUPS.index(group)))
        out["phase"].append(phase)
        out["episode"].append(np.full(len(t), e))
        out["progress"].append((t - a) / max(T - a, 1))
        out["steps_to_end"].append(steps_to_end)
        out["pregrasp"].append(pregrasp)
        out["is_val"].append(np.full(len(t), val_episodes[e]))
    return Transitions(**{k: np.concatenate(v) for k, v in out.items()})


# --------------------------------------------------------------------------- observations
def obs_window_rows(rows: np.ndarray, table: FrameTable, n_obs_steps: int) -> np.ndarray:
    """(N,) frame rows -> (N, n_obs_steps) rows of their observation history, clamped to the episode."""
    rows = np.asarray(rows)
    starts = table.episode_bounds[:, 0]
    ep_start = starts[np.searchsorted(starts, rows, side="right") - 1]
    window = rows[:, None] + np.arange(1 - n_obs_steps, 1)[None, :]
    return np.maximum(window, ep_start[:, None])


def iter_episode_images(dataset, table: FrameTable, progress: bool = True) -> Iterator[tuple[int, Tensor]]:
    """``(first row, images (n, 3, H, W) float in [0, 1])`` per episode, decoded once each.

    Video datasets are decoded one episode at a time with LeRobot's ``decode_video_frames`` at the
    frames' timestamps (what ``LeRobotDataset.__getitem__`` does frame by frame, several times faster);
    image datasets go through ``dataset[i]``.
    """
    bounds = table.episode_bounds
    bar = tqdm(
        total=int(bounds[-1, 1] - bounds[0, 0]), desc="decoding frames", unit="frame", disable=not progress
    )
    is_video = WRIST_IMAGE in getattr(dataset.meta, "video_keys", [])
    timestamps = dataset.hf_dataset.select_columns(["timestamp"]).with_format("numpy")[:]["timestamp"]
    for e, (a, b) in enumerate(bounds):
        if is_video:
            from lerobot.datasets.video_utils import decode_video_frames

            ep_index = int(table.episode_ids[e])
            ep = dataset.meta.episodes[ep_index]
            offset = float(ep[f"videos/{WRIST_IMAGE}/from_timestamp"])
            path = Path(dataset.root) / dataset.meta.get_video_file_path(ep_index, WRIST_IMAGE)
            ts = (timestamps[a:b].astype(np.float64) + offset).tolist()
            images = decode_video_frames(path, ts, DEFAULT_TOLERANCE_S, None)
        else:
            images = torch.stack([dataset[int(i)][WRIST_IMAGE] for i in range(a, b)])
        bar.update(b - a)
        yield int(a), images
    bar.close()


def obs_batch(
    rows: np.ndarray, table: FrameTable, images_of: Callable[[np.ndarray], Tensor], n_obs_steps: int
) -> dict[str, Tensor]:
    """The policy's observation batch for frame ``rows``: ``(N, n_obs, ...)`` images, states, bboxes."""
    window = obs_window_rows(rows, table, n_obs_steps)
    return {
        WRIST_IMAGE: images_of(window),
        STATE: torch.from_numpy(table.state[window]).float(),
        BBOX: torch.from_numpy(table.bbox[window]).float(),
    }


@torch.no_grad()
def compute_embeddings(
    encode: Callable[[dict[str, Tensor]], Tensor],
    dataset,
    table: FrameTable,
    n_obs_steps: int,
    batch_size: int = 32,
    progress: bool = True,
) -> Tensor:
    """State features ``(F, D)`` of every frame (with its history), episode by episode."""
    out: list[Tensor] = []
    for a, images in iter_episode_images(dataset, table, progress):
        n = len(images)
        for i in range(0, n, batch_size):
            rows = np.arange(a + i, a + min(i + batch_size, n))
            batch = obs_batch(
                rows, table, lambda w, a=a, images=images: images[torch.from_numpy(w - a)], n_obs_steps
            )
            out.append(encode(batch).float().cpu())
    return torch.cat(out)


def load_all_images(dataset, table: FrameTable, progress: bool = True) -> Tensor:
    """Every frame as uint8 ``(F, 3, H, W)`` (for training an unfrozen encoder; ~150 kB per frame)."""
    return torch.cat(
        [(im * 255).round().to(torch.uint8) for _, im in iter_episode_images(dataset, table, progress)]
    )
