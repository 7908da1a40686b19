"""Suite outcomes by how far the target brick is turned off the grid axes.

The grid layouts turn each brick by at most 10 degrees, the random and pile layouts by up to 45. A
policy that never turns its gripper, or judges a brick's height by its apparent size, fails only the
turned bricks, and a per-setting table hides that behind a pooled rate. The yaw is the scene's own
(``make_layout`` at the episode's seed, no physics), so any suite's ``episodes.jsonl`` can be broken
down after the fact: ``bboxpick-compare --by=target_yaw``.
"""

from __future__ import annotations

import numpy as np

from lerobot_bboxpick.eval.suite import wilson_interval
from lerobot_bboxpick.sim.layouts import SETTINGS, make_layout, scene_rng

Scene = tuple[str, int]  # (setting, seed)
# Degrees off the nearest grid axis; a brick is symmetric under quarter turns for this purpose.
YAW_BINS: tuple[tuple[float, float], ...] = ((0.0, 15.0), (15.0, 30.0), (30.0, 45.0))


def target_yaw_off_axis(setting: str, seed: int) -> float:
    """Degrees [0, 45] the target of scene ``seed`` of ``setting`` is turned off the nearest grid axis."""
    layout = make_layout(setting, scene_rng(setting, seed))
    yaw = float(np.degrees(layout.yaws[layout.target])) % 90.0
    return min(yaw, 90.0 - yaw)


def yaw_bin(degrees: float) -> int:
    """Index in ``YAW_BINS`` of a yaw off the axis (45 itself falls in the last bin)."""
    for i, (_, high) in enumerate(YAW_BINS):
        if degrees < high:
            return i
    return len(YAW_BINS) - 1


def _cell(outcomes: list[str]) -> str:
    if not outcomes:
        return "-"
    pick, n = outcomes.count("pick"), len(outcomes)
    low, high = wilson_interval(pick, n)
    return f"{pick}/{n} [{100 * low:.0f}-{100 * high:.0f}%]"


def target_yaw_table(runs: dict[str, dict[Scene, str]]) -> str:
    """Markdown table: for each run and setting, Pick count / scenes [Wilson 95%] per yaw bin of the
    target, and the setting's empty and contact misses of turned targets (>= 15 degrees), the failure
    modes the breakdown is for."""
    yaws: dict[Scene, float] = {}  # each scene's yaw, computed once for all runs
    heads = [f"{low:.0f}-{high:.0f} deg" for low, high in YAW_BINS]
    lines = [
        "| policy | setting | " + " | ".join(heads) + " | turned misses: empty / contact |",
        "|---|---|" + "---|" * (len(heads) + 1),
    ]
    for name, outcomes in runs.items():
        present = {s for s, _ in outcomes}
        for setting in [s for s in SETTINGS if s in present]:
            bins: list[list[str]] = [[] for _ in YAW_BINS]
            for (s, seed), outcome in outcomes.items():
                if s != setting:
                    continue
                if (s, seed) not in yaws:
                    yaws[(s, seed)] = target_yaw_off_axis(s, seed)
                bins[yaw_bin(yaws[(s, seed)])].append(outcome)
            turned = [o for b in bins[1:] for o in b]
            misses = f"{turned.count('empty')} / {turned.count('contact')}"
            lines.append(f"| {name} | {setting} | " + " | ".join(map(_cell, bins)) + f" | {misses} |")
    return "\n".join(lines) + "\n"
