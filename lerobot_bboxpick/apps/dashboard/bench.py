"""How fast the live view is: frames per second a browser receives over the WebSocket during a run.

``python -m lerobot_bboxpick.apps.dashboard.bench`` runs the expert alone and beside itself on a
real uvicorn server and prints the rates (a speed figure for the docs, never a test assertion: it
depends on the machine and its load).
"""

from __future__ import annotations

import argparse
import json
import os
import time

from lerobot_bboxpick.apps.dashboard.policies import PolicyCatalog
from lerobot_bboxpick.apps.dashboard.server import create_app
from lerobot_bboxpick.apps.dashboard.serving import serve_in_thread
from lerobot_bboxpick.apps.dashboard.session import DashboardSession


def measure_live_fps(
    policies: tuple[str, ...] = ("expert",),
    realtime: bool = False,
    max_steps: int = 120,
    setting: str = "grid_id",
    seed: int = 3,
) -> dict:
    """Run ``policies`` on one scene and count lane A's wrist frames a WebSocket client receives.

    Returns frames received, seconds from the first frame to the last, frames per second, and the
    simulation's own control steps per second (every lane steps once per frame).
    """
    import httpx2
    from websockets.sync.client import connect

    session = DashboardSession(PolicyCatalog(None))
    server = serve_in_thread(create_app(session))
    try:
        httpx2.post(
            server.url + "api/scene", json={"setting": setting, "seed": seed}, timeout=120
        ).raise_for_status()
        times: list[float] = []
        with connect(server.url.replace("http", "ws") + "api/ws", max_size=None) as ws:
            body = {"policies": list(policies), "realtime": realtime, "max_steps": max_steps}
            httpx2.post(server.url + "api/run", json=body, timeout=300).raise_for_status()
            while True:
                message = ws.recv(timeout=60)
                if isinstance(message, bytes):
                    if message[0] == 0:  # wrist_A
                        times.append(time.perf_counter())
                elif json.loads(message)["phase"] in ("done", "error"):
                    break
        seconds = times[-1] - times[0] if len(times) > 1 else float("nan")
        status = session.snapshot().status
        steps = max(lane["steps"] for lane in status["run"]["lanes"])
        run_seconds = sum(lane["seconds"] for lane in session.episode()["lanes"])
        return {
            "policies": list(policies),
            "realtime": realtime,
            "frames": len(times),
            "seconds": round(seconds, 2),
            "fps": round((len(times) - 1) / seconds, 1),
            "lane_step_ms": round(1000 * run_seconds / (steps * len(policies)), 1),
        }
    finally:
        server.stop()
        session.close()


def main(argv: list[str] | None = None) -> None:
    """Print the live view's frame rate for one lane and for two side by side."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--realtime", action="store_true", help="pace at the env's 20 Hz (the page's default)"
    )
    args = parser.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    for policies in (("expert",), ("expert", "expert")):
        print(json.dumps(measure_live_fps(policies, realtime=args.realtime)), flush=True)


if __name__ == "__main__":
    main()
