"""The dashboard in a real headless Chromium (Debian's ``chromium``, driven by Playwright).

A person's path through the page: load a scene, drag a box on the wrist canvas, run the expert and
see "pick"; click a brick and run two policies side by side; see the error of a bad box; draw and
send a box for the robot. Screenshots go to ``tmp_path``, or to ``$BBOXPICK_DASHBOARD_SCREENSHOTS``
(how ``examples/dashboard*.png`` are made).
"""

from __future__ import annotations

import os
import queue
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from helpers_dashboard import SEED, SETTING
from tiny_policy import save_tiny_policy

from lerobot_bboxpick.apps.dashboard.box_picker import pick_box_in_browser
from lerobot_bboxpick.apps.dashboard.policies import PolicyCatalog
from lerobot_bboxpick.apps.dashboard.server import create_app
from lerobot_bboxpick.apps.dashboard.serving import BackgroundServer, serve_in_thread
from lerobot_bboxpick.apps.dashboard.session import DashboardSession
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.scene import N_BRICKS

pytestmark = pytest.mark.slow

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
CANVAS = 448  # CSS px of the wrist canvas (index.html)
VIEWPORT = {"width": 1400, "height": 1000}


@pytest.fixture(scope="module")
def browser() -> Iterator:
    """Debian's Chromium under Playwright (the set-up installs it: its absence is a failure)."""
    from playwright.sync_api import sync_playwright

    if not CHROMIUM.exists():
        pytest.fail(f"{CHROMIUM} is missing: the set-up must `apt-get install -y chromium`")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield browser
        browser.close()


@pytest.fixture(scope="module")
def dashboard(
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[tuple[DashboardSession, BackgroundServer]]:
    """The dashboard on a real uvicorn server, with a tiny real checkpoint under runs/tiny."""
    checkpoints = tmp_path_factory.mktemp("checkpoints")
    save_tiny_policy(checkpoints / "runs" / "tiny", seed=0)
    session = DashboardSession(
        PolicyCatalog(checkpoints, examples_dir=tmp_path_factory.mktemp("no_examples"))
    )
    server = serve_in_thread(create_app(session))
    yield session, server
    server.stop()
    session.close()


@pytest.fixture
def page(browser, dashboard) -> Iterator:
    """A fresh tab on the dashboard; fails the test on any JavaScript error."""
    _, server = dashboard
    tab = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    tab.on("pageerror", lambda e: errors.append(str(e)))
    tab.goto(server.url)
    tab.wait_for_selector("body[data-ready=true]")
    yield tab
    tab.close()
    assert errors == [], errors


def _screenshot_dir(tmp_path: Path) -> Path:
    folder = Path(os.environ.get("BBOXPICK_DASHBOARD_SCREENSHOTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _load_scene(page, session: DashboardSession) -> None:
    scene = session.snapshot().status["scene"]
    version = 1 + (scene["version"] if scene else 0)
    page.select_option("#setting", SETTING)
    page.fill("#seed", str(SEED))
    page.click("#load")
    page.wait_for_selector(f"#target-info[data-scene-version='{version}']")
    assert page.text_content("#message").startswith(f"scene {SETTING} seed {SEED}:")


def _drag(page, box: list[float]) -> list[float]:
    """Drag on the canvas from the box's top-left to its bottom-right corner (whole CSS pixels);
    returns the normalised box the drag spans."""
    rect = page.locator("#box-canvas").bounding_box()
    assert (rect["width"], rect["height"]) == (CANVAS, CANVAS)
    x0, y0, x1, y1 = (round(v * CANVAS) for v in box)
    page.mouse.move(rect["x"] + x0, rect["y"] + y0)
    page.mouse.down()
    page.mouse.move(rect["x"] + (x0 + x1) / 2, rect["y"] + (y0 + y1) / 2, steps=3)
    page.mouse.move(rect["x"] + x1, rect["y"] + y1, steps=3)
    page.mouse.up()
    return [x0 / CANVAS, y0 / CANVAS, x1 / CANVAS, y1 / CANVAS]


def _other_visible_brick(env: LegoPickEnv) -> int:
    return next(i for i in range(N_BRICKS) if i != env.target and env.brick_box(i).visibility == "full")


def _wait_done(page, slot: str, timeout_ms: int = 90_000) -> str:
    page.wait_for_selector(f"#outcome-{slot}[data-done=true]", timeout=timeout_ms)
    return page.text_content(f"#outcome-{slot}")


def test_drag_a_box_run_the_expert_see_pick(page, dashboard, reference: LegoPickEnv, tmp_path: Path) -> None:
    session, server = dashboard
    _load_scene(page, session)
    k = _other_visible_brick(reference)
    brick = reference.brick_box(k).bbox
    dragged = _drag(page, [brick[0] - 0.01, brick[1] - 0.01, brick[2] + 0.01, brick[3] + 0.01])
    page.wait_for_function(
        f"document.querySelector('#target-info').textContent.startsWith('target brick {k} ')"
    )
    np.testing.assert_allclose(session.snapshot().status["scene"]["box"], dragged, atol=1e-6)
    assert page.get_attribute("#message", "data-kind") == "info"

    page.check("#realtime")
    page.click("#run")
    assert _wait_done(page, "A") == "pick"
    episode = page.request.get(server.url + "api/episode.json").json()
    assert episode["target"] == k
    np.testing.assert_allclose(episode["lanes"][0]["steps_log"][0]["policy_bbox"], dragged, atol=1e-6)
    assert page.is_hidden("#lane-B")
    print(f"live view after a real-time expert run: {page.text_content('#fps')}")
    page.screenshot(path=_screenshot_dir(tmp_path) / "dashboard.png", full_page=True)


def test_click_a_brick_and_run_two_policies_side_by_side(
    page, dashboard, reference: LegoPickEnv, tmp_path: Path
) -> None:
    session, server = dashboard
    _load_scene(page, session)
    k = _other_visible_brick(reference)
    ys, xs = np.nonzero(reference.render_brick_masks() == k)
    rect = page.locator("#box-canvas").bounding_box()
    i = len(xs) // 2
    page.mouse.click(rect["x"] + (xs[i] + 0.5) * CANVAS / 224, rect["y"] + (ys[i] + 0.5) * CANVAS / 224)
    page.wait_for_function(
        f"document.querySelector('#target-info').textContent.startsWith('target brick {k} ')"
    )
    assert "by click" in page.text_content("#target-info")

    page.select_option("#policy-A", "expert")
    page.select_option("#policy-B", "runs/tiny")
    page.fill("#max-steps", "150")
    page.uncheck("#realtime")
    page.click("#run")
    page.wait_for_selector("#lane-B", state="visible")
    outcome_a, outcome_b = _wait_done(page, "A"), _wait_done(page, "B")
    episode = page.request.get(server.url + "api/episode.json").json()
    a, b = episode["lanes"]
    assert (outcome_a, outcome_b) == (a["outcome"], b["outcome"])
    assert outcome_a == "pick" and a["policy"] == "expert" and b["policy"] == "runs/tiny"
    # Same scene and box for both: the same first box, and the same first wrist frame.
    assert a["steps_log"][0]["policy_bbox"] == b["steps_log"][0]["policy_bbox"]
    np.testing.assert_allclose(a["steps_log"][0]["policy_bbox"], reference.brick_box(k).bbox, atol=1e-7)
    assert page.text_content("#steps-B") == f"step {b['steps']}"
    page.screenshot(path=_screenshot_dir(tmp_path) / "dashboard_side_by_side.png", full_page=True)


def test_bad_box_and_missing_checkpoint_show_their_errors(page, dashboard) -> None:
    session, _ = dashboard
    _load_scene(page, session)
    before = session.snapshot().status["scene"]
    _drag(page, [0.40, 0.80, 0.48, 0.86])  # bare table below the grid
    page.wait_for_selector("#message.error")
    assert "does not outline a brick" in page.text_content("#message")
    assert session.snapshot().status["scene"]["target"] == before["target"]
    # The canvas goes back to showing the box the server holds, not the refused one.
    np.testing.assert_allclose(page.evaluate("window.page.canvas.box"), before["box"], atol=1e-6)

    page.fill("#path-A", "no/such/checkpoint")
    page.click("#run")
    page.wait_for_function("document.querySelector('#message').textContent.includes('no checkpoint there')")
    assert page.get_attribute("#message", "data-kind") == "error"
    assert session.snapshot().status["phase"] == "ready"


def test_robot_box_picker_returns_the_dragged_box(browser, reference: LegoPickEnv, tmp_path: Path) -> None:
    frame = reference.camera.render(reference.data)
    urls: queue.Queue = queue.Queue()
    result: dict = {}

    def pick() -> None:
        try:
            result["box"] = pick_box_in_browser(frame, timeout_s=60, announce=urls.put)
        except Exception as e:  # handed to the test thread
            result["error"] = e

    thread = threading.Thread(target=pick)
    thread.start()
    tab = browser.new_page(viewport=VIEWPORT)
    try:
        tab.goto(urls.get(timeout=30))
        tab.wait_for_selector("body.mode-picker[data-ready=true]")
        assert tab.is_hidden("#controls") and tab.is_disabled("#send-box")
        brick = reference.brick_box(reference.target).bbox
        dragged = _drag(tab, [brick[0] - 0.02, brick[1] - 0.02, brick[2] + 0.02, brick[3] + 0.02])
        tab.click("#send-box")
        tab.wait_for_function("document.querySelector('#message').textContent.startsWith('box sent')")
        thread.join(timeout=30)
    finally:
        tab.close()
    assert "error" not in result, result
    box = result["box"]
    assert box.shape == (4,) and box.dtype == np.float32
    np.testing.assert_allclose(box, dragged, atol=1 / 224)


def test_the_ur5_robot_takes_its_target_from_the_picker(browser) -> None:
    """--robot.bbox_picker=web: a person drags a box around a brick on the robot's first frame; that
    brick becomes the simulated robot's target and the first observation reports the dragged box."""
    import socket

    from lerobot.robots.utils import make_robot_from_config

    from lerobot_bboxpick.robots.ur5 import UR5Config
    from lerobot_bboxpick.robots.ur5.ur5 import BBOX_KEYS

    with socket.socket() as s:  # a free port for the picker's page
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    probe = LegoPickEnv(setting="grid_id")
    probe.reset(seed=0)
    brick = _other_visible_brick(probe)
    box = probe.brick_box(brick).bbox
    probe.close()
    seen: dict = {}

    def robot_session() -> None:  # the robot lives in one thread: its EGL context is bound there
        robot = make_robot_from_config(UR5Config(seed=0, bbox_picker="web", bbox_picker_port=port))
        robot.connect()
        try:
            seen["target"] = robot.backend.env.target
            obs = robot.get_observation()
            seen["first_box"] = [obs[k] for k in BBOX_KEYS]
        finally:
            robot.disconnect()

    errors: list = []
    thread = threading.Thread(target=lambda: _run_collecting(robot_session, errors))
    thread.start()
    tab = browser.new_page(viewport=VIEWPORT)
    try:
        deadline = time.monotonic() + 60
        while True:  # the robot builds its simulator before it serves the page
            try:
                tab.goto(f"http://127.0.0.1:{port}/")
                break
            except Exception:
                assert time.monotonic() < deadline and thread.is_alive(), errors
                time.sleep(0.5)
        tab.wait_for_selector("body.mode-picker[data-ready=true]")
        # A loose box, as a person draws it: 0.02 larger than the brick on every side.
        dragged = _drag(tab, [box[0] - 0.02, box[1] - 0.02, box[2] + 0.02, box[3] + 0.02])
        tab.click("#send-box")
        thread.join(timeout=60)
    finally:
        tab.close()
    assert not errors, errors
    assert seen["target"] == brick, seen
    np.testing.assert_allclose(seen["first_box"], dragged, atol=1 / 224)


def _run_collecting(fn, errors: list) -> None:
    try:
        fn()
    except Exception as e:  # handed to the test thread
        errors.append(e)
