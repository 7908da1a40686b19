"""The six scene settings: where the twelve bricks go, which colours they have, which one is the target.

Every layout is a pure function of the setting and a numpy Generator; ``scene_rng(setting, seed)``
gives the Generator of one seed, so one (setting, seed) is one scene.
Positions are the centre of each brick's bottom face in the table frame (+x away from the robot,
+y to the robot's left).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lerobot_bboxpick.sim.scene import BRICK_HALF, BRICK_HEIGHT, COLOR_NAMES, N_BRICKS

SETTINGS: tuple[str, ...] = ("grid_id", "grid_ood", "pile_id", "random_id", "identical_2", "identical_4")

GRID_CENTER = np.array([0.62, 0.0])
GRID_PITCH = 0.075  # m between brick centres: room for the open fingers between neighbours
GRID_ROWS, GRID_COLS = 3, 4
OOD_SHIFT = 0.22  # grid_ood: the grid centre moves this far to the left or right
RANDOM_REGION = (np.array([0.50, -0.20]), np.array([0.74, 0.20]))
RANDOM_MIN_DISTANCE = 0.06


@dataclass(frozen=True)
class Layout:
    """One scene: brick poses, colours and the target."""

    setting: str
    positions: np.ndarray  # (12, 3) bottom-face centres
    yaws: np.ndarray  # (12,) rad about +z
    colors: tuple[str, ...]  # (12,) colour names, keys of scene.BRICK_COLORS
    target: int

    @property
    def target_color(self) -> str:
        """Colour name of the target brick."""
        return self.colors[self.target]


def check_setting(setting: str) -> str:
    """Return ``setting`` or raise a ValueError naming the valid ones."""
    if setting not in SETTINGS:
        raise ValueError(
            f"setting={setting!r} is not a lego_pick setting; valid settings: {', '.join(SETTINGS)}"
        )
    return setting


def scene_rng(setting: str, seed: int) -> np.random.Generator:
    """The random stream of scene ``seed`` of ``setting`` (layout, then appearance and start pose).

    Each setting has a stream of its own, so the same seed gives different scenes in different settings
    (grid_id and the identical settings share the grid slots, never the draw).
    """
    return np.random.default_rng([SETTINGS.index(check_setting(setting)), int(seed)])


def _grid(
    rng: np.random.Generator, center: np.ndarray, jitter: float = 0.005
) -> tuple[np.ndarray, np.ndarray]:
    rows = (np.arange(GRID_ROWS) - (GRID_ROWS - 1) / 2) * GRID_PITCH
    cols = (np.arange(GRID_COLS) - (GRID_COLS - 1) / 2) * GRID_PITCH
    xy = np.array([[center[0] + r, center[1] + c] for r in rows for c in cols])
    xy += rng.uniform(-jitter, jitter, size=xy.shape)
    yaws = rng.uniform(-np.radians(10), np.radians(10), size=N_BRICKS)
    return np.column_stack([xy, np.zeros(N_BRICKS)]), yaws


def _random(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    low, high = RANDOM_REGION
    xy: list[np.ndarray] = []
    while len(xy) < N_BRICKS:  # rejection sampling; the region holds 12 easily at this spacing
        p = rng.uniform(low, high)
        if all(np.linalg.norm(p - q) >= RANDOM_MIN_DISTANCE for q in xy):
            xy.append(p)
    yaws = rng.uniform(-np.pi / 4, np.pi / 4, size=N_BRICKS)
    return np.column_stack([np.array(xy), np.zeros(N_BRICKS)]), yaws


def _pile(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A tight 3x3 cluster of touching bricks with bricks stacked on its corners.

    Returns positions, yaws and a mask of bricks with nothing on top (the pickable ones).
    """
    pitch = 2 * BRICK_HALF[0] + 0.0015  # touching, with 1.5 mm for the jitter
    center = GRID_CENTER + rng.uniform(-0.03, 0.03, size=2)
    theta = rng.uniform(-np.pi / 4, np.pi / 4)
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    cells = np.array([[i, j] for i in (-1, 0, 1) for j in (-1, 0, 1)], dtype=float)
    n_top = N_BRICKS - len(cells)  # 3 stacked bricks
    corners = np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]], dtype=float)
    top_cells = corners[rng.choice(len(corners), size=n_top, replace=False)]
    # Stacked bricks sit half a brick inward so they bridge two bricks below, as in a real pile.
    top_local = top_cells * pitch * 0.75 + rng.uniform(-0.003, 0.003, size=(n_top, 2))
    local = np.concatenate([cells * pitch + rng.uniform(-0.0005, 0.0005, size=cells.shape), top_local])
    xy = center + local @ rot.T
    z = np.concatenate([np.zeros(len(cells)), np.full(n_top, BRICK_HEIGHT)])
    yaws = theta + np.concatenate(
        [rng.uniform(-0.02, 0.02, len(cells)), rng.uniform(-np.radians(20), np.radians(20), n_top)]
    )
    free = np.ones(N_BRICKS, dtype=bool)
    for k in range(len(cells), N_BRICKS):  # the bottom bricks under a stacked one are covered
        d = np.abs(local[: len(cells)] - local[k]).max(axis=1)
        free[: len(cells)][d < pitch] = False
    return np.column_stack([xy, z]), yaws, free


def make_layout(setting: str, rng: np.random.Generator) -> Layout:
    """The scene of ``setting`` drawn from ``rng``."""
    check_setting(setting)
    colors = list(rng.permutation(COLOR_NAMES))
    candidates = np.arange(N_BRICKS)
    if setting in ("grid_id", "identical_2", "identical_4"):
        positions, yaws = _grid(rng, GRID_CENTER)
    elif setting == "grid_ood":
        side = rng.choice([-1.0, 1.0])
        positions, yaws = _grid(rng, GRID_CENTER + np.array([0.0, side * OOD_SHIFT]))
    elif setting == "random_id":
        positions, yaws = _random(rng)
    else:  # pile_id
        positions, yaws, free = _pile(rng)
        candidates = np.flatnonzero(free)
    target = int(rng.choice(candidates))
    if setting.startswith("identical_"):
        n_same = int(setting.split("_")[1])
        others = rng.choice([i for i in range(N_BRICKS) if i != target], size=n_same - 1, replace=False)
        for i in others:
            colors[i] = colors[target]
    return Layout(setting, positions, yaws, tuple(str(c) for c in colors), target)


def describe_target(layout: Layout) -> str:
    """Language task naming the target's colour and coarse location, as the paper's VLA prompts did.

    E.g. "pick up the red block on the far left". Left/right and near/far are relative to the
    bricks' spread, from the robot's point of view (+y is left, +x is far).
    """
    xy = layout.positions[:, :2]
    t = xy[layout.target]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    span = np.maximum(hi - lo, 1e-6)
    fx, fy = (t - lo) / span
    depth = "near " if fx < 1 / 3 else "far " if fx > 2 / 3 else ""
    side = "left" if fy > 2 / 3 else "right" if fy < 1 / 3 else "middle"
    where = f"on the {depth}{side}" if side != "middle" else f"in the {depth or ''}middle".replace("  ", " ")
    return f"pick up the {layout.target_color} block {where}"
