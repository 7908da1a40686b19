"""All drawing code: annotated wrist frames, contact sheets, videos, result charts."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def label(image: np.ndarray, text: str) -> np.ndarray:
    """Write ``text`` in the top-left corner of an RGB image (in place), with a dark outline."""
    for color, thickness in (((0, 0, 0), 3), ((255, 255, 255), 1)):
        cv2.putText(image, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, color, thickness, cv2.LINE_AA)
    return image


def contact_sheet(tiles: list[np.ndarray], columns: int, scale: int = 1) -> np.ndarray:
    """Grid of equally sized RGB tiles (missing cells black), optionally upscaled (nearest)."""
    h, w = tiles[0].shape[:2]
    rows = -(-len(tiles) // columns)
    sheet = np.zeros((rows * h, columns * w, 3), dtype=np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, columns)
        sheet[r * h : (r + 1) * h, c * w : (c + 1) * w] = tile
    if scale != 1:
        sheet = cv2.resize(sheet, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    return sheet


def save_png(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an RGB image as PNG (creating the folder)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), rgb[..., ::-1]):
        raise OSError(f"could not write {path}")
    return path


def save_mp4(path: str | Path, frames: list[np.ndarray], fps: int) -> Path:
    """Write RGB frames as an H.264 MP4 with LeRobot's own writer (PyAV)."""
    from lerobot.utils.io_utils import write_video

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_video(path, frames, fps)
    return path


def draw_bbox(
    image: np.ndarray, bbox: np.ndarray, color: tuple[int, int, int] = (255, 255, 255)
) -> np.ndarray:
    """Draw a normalised bbox on an RGB image in place (and return it)."""
    h, w = image.shape[:2]
    x0, y0, x1, y1 = (np.asarray(bbox) * [w, h, w, h]).round().astype(int)
    cv2.rectangle(image, (int(x0), int(y0)), (int(x1) - 1, int(y1) - 1), color, 1)
    return image


THUMBNAIL_PX = 112  # side of the final-frame thumbnails in outcome sheets


def outcome_sheet(tiles: list[tuple[np.ndarray, str, str]], columns: int = 8) -> np.ndarray:
    """Contact sheet of episode thumbnails, each labelled with its caption and framed in its outcome's
    colour (pick green, wrong red, contact orange, empty grey): ``tiles`` is (image, caption, outcome)."""
    colors = {"pick": (40, 200, 60), "wrong": (230, 40, 40), "contact": (255, 150, 0)}
    framed = []
    for image, caption, outcome in tiles:
        tile = cv2.resize(image, (THUMBNAIL_PX, THUMBNAIL_PX), interpolation=cv2.INTER_AREA)
        tile = cv2.copyMakeBorder(
            tile, 3, 3, 3, 3, cv2.BORDER_CONSTANT, value=colors.get(outcome, (120,) * 3)
        )
        framed.append(label(tile, caption))
    return contact_sheet(framed, columns=min(columns, len(framed)))


def outcome_bars(rows: list[dict], outcomes: tuple[str, ...], path: Path) -> Path:
    """Grouped bars: one panel per outcome, settings on the x axis, one bar per policy, Wilson error bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    policies = list(dict.fromkeys(r["policy"] for r in rows))
    settings = list(dict.fromkeys(r["setting"] for r in rows))
    fig, axes = plt.subplots(1, len(outcomes), figsize=(4 * len(outcomes), 3.6), sharey=True)
    width = 0.8 / len(policies)
    x = np.arange(len(settings))
    for ax, outcome in zip(axes, outcomes, strict=True):
        for i, policy in enumerate(policies):
            sel = [next(r for r in rows if r["policy"] == policy and r["setting"] == s) for s in settings]
            rate = np.array([100 * r[f"{outcome}_rate"] for r in sel])
            err = np.array(
                [
                    [rate[j] - 100 * r[f"{outcome}_ci_low"], 100 * r[f"{outcome}_ci_high"] - rate[j]]
                    for j, r in enumerate(sel)
                ]
            ).T
            ax.bar(x + (i - (len(policies) - 1) / 2) * width, rate, width, yerr=err, capsize=2, label=policy)
        ax.set_title(outcome.capitalize())
        ax.set_xticks(x, settings, rotation=35, ha="right", fontsize=8)
        ax.set_ylim(0, 105)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("% of episodes (Wilson 95% CI)")
    axes[-1].legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def outcome_stats_figure(episodes: list[dict], outcomes: tuple[str, ...], path: Path) -> Path:
    """A dataset's statistics (the paper's figure 6): episodes per outcome in each setting (left) and the
    histogram of episode lengths per outcome (right). ``episodes``: dicts with setting, outcome, length."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    settings = list(dict.fromkeys(e["setting"] for e in episodes))
    shown = [o for o in (*outcomes, "unknown") if any(e["outcome"] == o for e in episodes)]
    fig, (bars, hist) = plt.subplots(1, 2, figsize=(11, 3.8))
    x = np.arange(len(settings))
    width = 0.8 / max(1, len(shown))
    lengths = [e["length"] for e in episodes]
    bins = np.linspace(0, max(lengths, default=1), 21)
    for i, outcome in enumerate(shown):
        counts = [sum(e["setting"] == s and e["outcome"] == outcome for e in episodes) for s in settings]
        offset = (i - (len(shown) - 1) / 2) * width
        drawn = bars.bar(x + offset, counts, width, label=outcome)
        bars.bar_label(drawn, fontsize=7)
        mine = [e["length"] for e in episodes if e["outcome"] == outcome]
        hist.hist(mine, bins=bins, histtype="step", linewidth=1.5, label=f"{outcome} (n={len(mine)})")
    bars.set_xticks(x, settings, rotation=35, ha="right", fontsize=8)
    bars.set_ylabel("episodes")
    bars.set_title(f"Episodes per outcome and setting ({len(episodes)} episodes)")
    hist.set_xlabel("episode length (steps)")
    hist.set_ylabel("episodes")
    hist.set_title("Episode length per outcome")
    for ax in (bars, hist):
        ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))  # counts
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
