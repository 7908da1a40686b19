"""What the page shows besides the wrist image: a third-person view, JPEG frames, video frames.

The scene has no fixed world camera, so the third-person view is a free ``mjvCamera`` looking at
the table, rendered small (224 x 300) so that two lanes still stream above 10 frames per second.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import mujoco
import numpy as np

from lerobot_bboxpick.viz import label

THIRD_PERSON_SIZE = (224, 300)  # height, width: the wrist view's height, so lanes line up
JPEG_QUALITY = 85


class ThirdPersonView:
    """A free camera looking at the table from the front left, over the bricks toward the arm."""

    def __init__(
        self,
        model: mujoco.MjModel,
        size: tuple[int, int] = THIRD_PERSON_SIZE,
        lookat: Sequence[float] = (0.48, 0.0, 0.1),
        distance: float = 1.05,
        azimuth: float = -150.0,
        elevation: float = -30.0,
    ) -> None:
        self._renderer = mujoco.Renderer(model, height=size[0], width=size[1])
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.camera.lookat[:] = lookat
        self.camera.distance = distance
        self.camera.azimuth = azimuth
        self.camera.elevation = elevation

    def render(self, data: mujoco.MjData) -> np.ndarray:
        """The (H, W, 3) uint8 RGB view of the current state."""
        self._renderer.update_scene(data, camera=self.camera)
        return self._renderer.render()

    def close(self) -> None:
        """Free the GL context."""
        self._renderer.close()


def encode_jpeg(rgb: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """JPEG bytes of an RGB image."""
    ok, buffer = cv2.imencode(
        ".jpg", np.ascontiguousarray(rgb[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality]
    )
    if not ok:
        raise RuntimeError(f"JPEG encoding failed for an image of shape {rgb.shape}")
    return buffer.tobytes()


def decode_jpeg(data: bytes) -> np.ndarray:
    """RGB image of JPEG bytes."""
    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError("not a JPEG image")
    return bgr[..., ::-1]


def video_frame(lanes: Sequence[tuple[bytes, bytes, str]]) -> np.ndarray:
    """One video frame: per lane (wrist JPEG, third-person JPEG, caption) a row wrist | third person,
    captioned, rows stacked top to bottom."""
    rows = []
    for wrist_jpeg, third_jpeg, caption in lanes:
        wrist, third = decode_jpeg(wrist_jpeg), decode_jpeg(third_jpeg)
        row = np.concatenate(
            [wrist, cv2.resize(third, (third.shape[1] * wrist.shape[0] // third.shape[0], wrist.shape[0]))],
            axis=1,
        )
        rows.append(label(np.ascontiguousarray(row), caption))
    return np.concatenate(rows, axis=0)
