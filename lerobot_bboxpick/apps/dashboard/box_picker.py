"""``pick_box_in_browser``: a person draws the target box on a robot's wrist frame, in the dashboard page.

For the UR5 robot backend (``--robot.bbox_picker=web``): the frame is served on the dashboard's own page
in its "picker" mode (same canvas code, ``static/box_canvas.js``); the person drags a box and presses
"Send box to the robot", and the function returns that box, normalised x0, y0, x1, y1 as the env's
``observation.bbox``, clipped to the image.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout

import numpy as np
from fastapi import FastAPI
from fastapi.responses import Response
from pydantic import BaseModel

from lerobot_bboxpick.apps.dashboard.boxes import check_box
from lerobot_bboxpick.apps.dashboard.errors import RequestError
from lerobot_bboxpick.apps.dashboard.http_common import install_common, jpeg_response
from lerobot_bboxpick.apps.dashboard.views import encode_jpeg

DEFAULT_TIMEOUT_S = 600.0


class PickRequest(BaseModel):
    """``POST /api/pick``."""

    box: list[float] | None = None


def _check_frame(frame: np.ndarray) -> np.ndarray:
    frame = np.asarray(frame)
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8 or min(frame.shape[:2]) < 1:
        raise ValueError(f"frame must be an (H, W, 3) uint8 RGB image, got shape {frame.shape} {frame.dtype}")
    return frame


def create_picker_app(frame: np.ndarray, result: Future) -> FastAPI:
    """The page in picker mode over ``frame``; the first valid box sent completes ``result``."""
    frame = _check_frame(frame)
    jpeg = encode_jpeg(frame, quality=95)
    app = FastAPI(title="bboxpick box picker", docs_url=None, redoc_url=None, openapi_url=None)
    install_common(app)

    @app.get("/api/config")
    def config() -> dict:
        return {
            "mode": "picker",
            "image_size": [int(frame.shape[1]), int(frame.shape[0])],
            "frame_version": 1,
        }

    @app.get("/api/state")
    def state() -> dict:
        box = result.result() if result.done() else None
        return {
            "phase": "picked" if box is not None else "picking",
            "box": None if box is None else box.tolist(),
        }

    @app.get("/api/frame/{view}.jpg")
    def frame_jpeg(view: str) -> Response:
        return jpeg_response(jpeg, view, ("scene",))

    @app.post("/api/pick")
    def pick(request: PickRequest) -> dict:
        if request.box is None:
            raise RequestError("box is missing: drag a box on the image first", field="box")
        box = check_box(request.box)
        if result.done():
            raise RequestError("a box was already sent to the robot", status=409, field="box")
        result.set_result(box)
        return {"box": [float(v) for v in box]}

    return app


def pick_box_in_browser(
    frame: np.ndarray,
    host: str = "127.0.0.1",
    port: int = 0,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    announce: Callable[[str], None] | None = None,
) -> np.ndarray:
    """Serve ``frame`` on the dashboard page and return the box a person drags and sends.

    Returns float32 (4,) normalised x0, y0, x1, y1, clipped to the image. ``port=0`` picks a free
    port; the page's URL goes to ``announce`` (default: printed to stderr). Raises ``TimeoutError``
    when no box arrives within ``timeout_s`` seconds; the server is stopped either way.
    """
    from lerobot_bboxpick.apps.dashboard.serving import serve_in_thread

    if not timeout_s > 0:
        raise ValueError(f"timeout_s={timeout_s!r} must be > 0")
    result: Future = Future()
    server = serve_in_thread(create_picker_app(frame, result), host, port)
    try:
        message = f"draw the target box in the browser: {server.url}"
        if announce is None:
            print(message, file=sys.stderr, flush=True)
        else:
            announce(server.url)
        try:
            return result.result(timeout=timeout_s)
        except FutureTimeout:
            raise TimeoutError(f"no box was sent from {server.url} within {timeout_s} s") from None
    finally:
        server.stop()
