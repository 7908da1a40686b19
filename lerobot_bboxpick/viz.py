"""Pictures a person looks at: annotated wrist frames, contact sheets, videos."""

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
