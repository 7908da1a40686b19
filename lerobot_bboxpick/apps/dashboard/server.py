"""``bboxpick-dashboard``: the FastAPI app over a ``DashboardSession``, and its uvicorn entry point.

API (JSON; errors are ``{"error", "field"}`` with a 4xx status):

* ``GET /api/config``: settings, policies, box modes; ``GET /api/state``: the latest status
* ``POST /api/scene`` ``{setting, seed}``
* ``POST /api/target`` ``{box: [x0, y0, x1, y1]}`` or ``{point: [x, y]}`` (normalised)
* ``POST /api/run`` ``{policies: [a] or [a, b], bbox_mode, realtime, max_steps, start_paused}``
* ``POST /api/pause`` / ``resume`` / ``step`` / ``reset``
* ``GET /api/frame/{view}.jpg``; ``GET /api/episode.json``; ``GET /api/video.mp4``
* ``WS /api/ws``: the status as text on every change, live frames as binary (byte 0 = index of the
  view in ``LIVE_VIEWS``, then the JPEG)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import tempfile
from pathlib import Path

from fastapi import FastAPI, WebSocket
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field

from lerobot_bboxpick.apps.dashboard.http_common import install_common, jpeg_response
from lerobot_bboxpick.apps.dashboard.policies import PolicyCatalog
from lerobot_bboxpick.apps.dashboard.session import DEFAULT_MAX_STEPS, DashboardSession

LIVE_VIEWS: tuple[str, ...] = ("wrist_A", "third_A", "wrist_B", "third_B")
ALL_VIEWS: tuple[str, ...] = ("scene", *LIVE_VIEWS)
WS_POLL_S = 0.01  # how often a socket looks for a new snapshot: well under a 20 Hz frame period
WS_HEARTBEAT_S = 2.0  # the status is re-sent this often even when nothing changes


class SceneRequest(BaseModel):
    """``POST /api/scene``."""

    setting: str
    seed: int = 0


class TargetRequest(BaseModel):
    """``POST /api/target``: exactly one of ``box`` or ``point``."""

    box: list[float] | None = None
    point: list[float] | None = None


class RunRequest(BaseModel):
    """``POST /api/run``."""

    policies: list[str] = Field(default_factory=lambda: ["expert"])
    bbox_mode: str = "tracked"
    realtime: bool = True
    max_steps: int = DEFAULT_MAX_STEPS
    start_paused: bool = False


def create_app(session: DashboardSession) -> FastAPI:
    """The dashboard's FastAPI app over ``session`` (the caller owns the session and closes it)."""
    app = FastAPI(title="bboxpick dashboard", docs_url="/api/docs", openapi_url="/api/openapi.json")
    install_common(app)

    @app.get("/api/config")
    def config() -> dict:
        return session.config()

    @app.get("/api/state")
    def state() -> dict:
        return session.snapshot().status

    @app.post("/api/scene")
    def scene(request: SceneRequest) -> dict:
        return session.load_scene(request.setting, request.seed)

    @app.post("/api/target")
    def target(request: TargetRequest) -> dict:
        return session.set_target(box=request.box, point=request.point)

    @app.post("/api/run")
    def run(request: RunRequest) -> dict:
        return session.run(
            request.policies,
            bbox_mode=request.bbox_mode,
            realtime=request.realtime,
            max_steps=request.max_steps,
            start_paused=request.start_paused,
        )

    @app.post("/api/pause")
    def pause() -> dict:
        return session.pause()

    @app.post("/api/resume")
    def resume() -> dict:
        return session.resume()

    @app.post("/api/step")
    def step() -> dict:
        return session.step()

    @app.post("/api/reset")
    def reset() -> dict:
        return session.reset()

    @app.get("/api/frame/{view}.jpg")
    def frame(view: str) -> Response:
        return jpeg_response(session.snapshot().frames.get(view), view, ALL_VIEWS)

    @app.get("/api/episode.json")
    def episode() -> JSONResponse:
        data = session.episode()
        name = f"episode_{data['setting']}_seed{data['seed']}.json"
        return JSONResponse(data, headers={"Content-Disposition": f'attachment; filename="{name}"'})

    @app.get("/api/video.mp4")
    def video() -> Response:
        from lerobot_bboxpick.viz import save_mp4

        frames, fps = session.video_frames()
        scene = session.snapshot().status["scene"] or {}
        with tempfile.TemporaryDirectory() as tmp:
            path = save_mp4(Path(tmp) / "rollout.mp4", frames, fps)
            data = path.read_bytes()
        name = f"rollout_{scene.get('setting', 'scene')}_seed{scene.get('seed', 0)}.mp4"
        return Response(
            data, media_type="video/mp4", headers={"Content-Disposition": f'attachment; filename="{name}"'}
        )

    @app.websocket("/api/ws")
    async def live(websocket: WebSocket) -> None:
        await websocket.accept()
        closed = asyncio.Event()

        async def watch_close() -> None:
            # The page sends nothing; reading is how a closed tab is noticed while nothing changes.
            try:
                while (await websocket.receive())["type"] != "websocket.disconnect":
                    pass
            finally:
                closed.set()

        watcher = asyncio.create_task(watch_close())
        version, sent, last_send = -1, {}, 0.0
        loop = asyncio.get_running_loop()
        try:
            while not closed.is_set():
                snap = session.snapshot()
                if snap.version != version or loop.time() - last_send > WS_HEARTBEAT_S:
                    await websocket.send_text(json.dumps(snap.status))
                    for index, view in enumerate(LIVE_VIEWS):
                        data = snap.frames.get(view)
                        if data is not None and sent.get(view) is not data:
                            await websocket.send_bytes(bytes([index]) + data)
                            sent[view] = data
                    version, last_send = snap.version, loop.time()
                await asyncio.sleep(WS_POLL_S)
        except Exception:  # the browser went away mid-send: nothing to clean up but the watcher
            pass
        finally:
            watcher.cancel()

    return app


def main(argv: list[str] | None = None) -> None:
    """``bboxpick-dashboard``: start the dashboard on a local web server and print its URL."""
    parser = argparse.ArgumentParser(prog="bboxpick-dashboard", description=__doc__.split("\n")[0])
    parser.add_argument(
        "--host", default="127.0.0.1", help="interface to listen on (default: this machine only)"
    )
    parser.add_argument("--port", type=int, default=8765, help="port (0: any free port)")
    parser.add_argument(
        "--checkpoints_dir",
        type=Path,
        default=None,
        help="folder searched for checkpoints (folders with config.json + model.safetensors)",
    )
    args = parser.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    from lerobot_bboxpick.apps.dashboard.serving import serve_forever

    try:
        catalog = PolicyCatalog(args.checkpoints_dir)
    except ValueError as e:
        parser.error(str(e))
    session = DashboardSession(catalog)
    try:
        serve_forever(
            create_app(session),
            args.host,
            args.port,
            on_ready=lambda url: print(f"bboxpick dashboard: {url}  (Ctrl-C stops it)", flush=True),
        )
    finally:
        session.close()


if __name__ == "__main__":
    main()
