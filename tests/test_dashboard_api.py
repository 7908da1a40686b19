"""The dashboard's HTTP API with FastAPI's test client: every endpoint and every bad request.

Real MuJoCo behind it (one worker thread), the real scripted expert, and a tiny real checkpoint; the
numbers checked are the env's own (targets, boxes, outcomes), not shapes.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Future
from pathlib import Path

import av
import httpx2
import numpy as np
import pytest
from fastapi.testclient import TestClient
from helpers_dashboard import SEED, SETTING
from tiny_policy import save_tiny_policy

from lerobot_bboxpick.apps.dashboard.box_picker import create_picker_app
from lerobot_bboxpick.apps.dashboard.boxes import MIN_TARGET_IOU, check_box
from lerobot_bboxpick.apps.dashboard.policies import PolicyCatalog
from lerobot_bboxpick.apps.dashboard.server import LIVE_VIEWS, create_app, main
from lerobot_bboxpick.apps.dashboard.session import DashboardSession
from lerobot_bboxpick.apps.dashboard.views import decode_jpeg
from lerobot_bboxpick.apps.dashboard.worker import SimWorker
from lerobot_bboxpick.data.tracking import bbox_iou
from lerobot_bboxpick.shipped_checkpoints import SHIPPED_CHECKPOINT
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.layouts import SETTINGS
from lerobot_bboxpick.sim.scene import N_BRICKS

PAD = 1.0 / 224  # one pixel: a drawn box a little looser than the brick's own box


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with one real (tiny, untrained) checkpoint under runs/tiny."""
    root = tmp_path_factory.mktemp("checkpoints")
    save_tiny_policy(root / "runs" / "tiny", seed=0)
    return root


@pytest.fixture(scope="module")
def session(checkpoints: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[DashboardSession]:
    """One session for the module (its envs are built once); tests start from a loaded scene."""
    s = DashboardSession(PolicyCatalog(checkpoints, examples_dir=tmp_path_factory.mktemp("no_examples")))
    yield s
    s.close()


@pytest.fixture
def client(session: DashboardSession) -> TestClient:
    """A client on the module's session, with no run going and the test scene loaded."""
    c = TestClient(create_app(session))
    if c.get("/api/state").json()["phase"] in ("running", "paused"):
        assert c.post("/api/reset").status_code == 200
    assert c.post("/api/scene", json={"setting": SETTING, "seed": SEED}).status_code == 200
    return c


@pytest.fixture
def fresh_client(tmp_path: Path) -> Iterator[TestClient]:
    """A client on a new session with nothing loaded."""
    s = DashboardSession(PolicyCatalog(None, examples_dir=tmp_path))
    yield TestClient(create_app(s))
    s.close()


def _other_visible_brick(reference: LegoPickEnv) -> int:
    """A brick in full view that is not the seed's target (so choosing it changes something)."""
    for i in range(N_BRICKS):
        if i != reference.target and reference.brick_box(i).visibility == "full":
            return i
    raise AssertionError("no other brick in full view")


def _padded(box: np.ndarray, pad: float = PAD) -> list[float]:
    return [float(box[0] - pad), float(box[1] - pad), float(box[2] + pad), float(box[3] + pad)]


def _wait_phase(c: TestClient, phases: tuple[str, ...], timeout: float = 90.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = c.get("/api/state").json()
        if state["phase"] in phases:
            return state
        time.sleep(0.05)
    raise AssertionError(f"phase did not reach {phases} in {timeout} s: {state['phase']} {state['message']}")


def _error(response, status: int, field: str, *words: str) -> None:
    assert response.status_code == status, response.text
    body = response.json()
    assert body["field"] == field, body
    for word in words:
        assert word in body["error"], body


# ---------------------------------------------------------------- page, config, state


def test_page_and_static_files_are_served(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200 and 'id="box-canvas"' in page.text and "dashboard.js" in page.text
    for name in ("dashboard.js", "box_canvas.js", "style.css"):
        response = client.get(f"/static/{name}")
        assert response.status_code == 200 and len(response.content) > 100, name
    assert "javascript" in client.get("/static/box_canvas.js").headers["content-type"]
    assert client.get("/static/missing.js").status_code == 404


def test_config_lists_settings_expert_and_found_checkpoints(client: TestClient) -> None:
    config = client.get("/api/config").json()
    assert config["mode"] == "sim"
    assert config["settings"] == list(SETTINGS)
    ids = [p["id"] for p in config["policies"]]
    assert ids == ["expert", "runs/tiny"]  # no "shipped": the examples folder of this session has none
    assert config["bbox_modes"] == ["tracked", "oracle"]


def test_shipped_checkpoint_listed_only_when_present(tmp_path: Path) -> None:
    examples = tmp_path / "examples"
    examples.mkdir()
    catalog = PolicyCatalog(None, examples_dir=examples)
    assert [c.id for c in catalog.choices()] == ["expert"]
    folder = examples / "checkpoint" / "pretrained_model"
    folder.mkdir(parents=True)
    for name in ("config.json", "model.safetensors"):
        (folder / name).write_text("{}")
    assert [c.id for c in catalog.choices()] == ["expert", "shipped"]
    assert catalog.resolve("shipped").path == folder.resolve()
    # With the first shipped checkpoint beside the current one, "shipped" is the main job's current one.
    current = examples / SHIPPED_CHECKPOINT.name
    current.mkdir()
    for name in ("config.json", "model.safetensors"):
        (current / name).write_text("{}")
    assert catalog.resolve("shipped").path == current.resolve()


def test_state_and_frames_before_a_scene(fresh_client: TestClient) -> None:
    state = fresh_client.get("/api/state").json()
    assert state["phase"] == "empty" and state["scene"] is None and state["run"] is None
    _error(fresh_client.get("/api/frame/scene.jpg"), 404, "view", "no frame yet")
    _error(fresh_client.get("/api/frame/top.jpg"), 404, "view", "valid views: scene, wrist_A")
    _error(fresh_client.get("/api/episode.json"), 404, "run", "no run")
    _error(fresh_client.get("/api/video.mp4"), 404, "run", "no run")
    _error(fresh_client.post("/api/reset"), 409, "scene", "load a scene")
    _error(fresh_client.post("/api/target", json={"box": [0.1, 0.1, 0.2, 0.2]}), 409, "scene", "load a scene")
    _error(fresh_client.post("/api/run", json={"policies": ["expert"]}), 409, "scene", "load a scene")


# ---------------------------------------------------------------- scene and target


def test_load_scene_gives_the_envs_target_box_and_image(client: TestClient, reference: LegoPickEnv) -> None:
    state = client.post("/api/scene", json={"setting": SETTING, "seed": SEED}).json()
    scene = state["scene"]
    assert state["phase"] == "ready"
    assert (scene["setting"], scene["seed"], scene["target"]) == (SETTING, SEED, reference.target)
    expected = reference.brick_box(reference.target).bbox
    np.testing.assert_allclose(scene["box"], expected, atol=1e-7)
    np.testing.assert_allclose(scene["target_box"], expected, atol=1e-7)
    image = decode_jpeg(client.get("/api/frame/scene.jpg").content)
    assert image.shape == (224, 224, 3)
    # The same first frame as the env's (up to JPEG loss).
    assert np.abs(image.astype(int) - reference.camera.render(reference.data).astype(int)).mean() < 3.0
    third = decode_jpeg(client.get("/api/frame/third_A.jpg").content)
    assert third.shape == (224, 300, 3) and third.std() > 10  # a rendered view, not a blank


def test_bad_scene_requests(client: TestClient) -> None:
    _error(
        client.post("/api/scene", json={"setting": "kitchen", "seed": 0}), 400, "setting", "grid_id, grid_ood"
    )
    _error(client.post("/api/scene", json={"setting": SETTING, "seed": -1}), 400, "seed", "[0, 2147483647]")
    _error(client.post("/api/scene", json={"setting": SETTING, "seed": "x"}), 422, "seed", "valid integer")
    _error(client.post("/api/scene", json={"seed": 1}), 422, "setting", "Field required")
    assert client.get("/api/state").json()["scene"]["seed"] == SEED  # nothing changed


def test_drawn_box_designates_the_best_overlapping_brick(client: TestClient, reference: LegoPickEnv) -> None:
    k = _other_visible_brick(reference)
    drawn = _padded(reference.brick_box(k).bbox)
    scene = client.post("/api/target", json={"box": drawn}).json()["scene"]
    assert scene["target"] == k and scene["target_source"] == "box"
    np.testing.assert_allclose(scene["box"], drawn, atol=1e-6)  # the drawn box, not the brick's
    assert scene["target_iou"] == pytest.approx(float(bbox_iou(np.array(drawn), reference.brick_box(k).bbox)))


def test_box_partly_outside_the_image_is_clipped_as_the_envs() -> None:
    # The env clips a brick's box to [0, 1] at the image edge; a drawn box is clipped the same way.
    np.testing.assert_allclose(check_box([-0.05, 0.2, 0.3, 1.4]), [0.0, 0.2, 0.3, 1.0], atol=1e-7)
    assert check_box([0.1, 0.2, 0.3, 0.4]).dtype == np.float32  # the dtype of observation.bbox


@pytest.mark.parametrize(
    ("body", "status", "field", "words"),
    [
        ({"box": [1.1, 1.1, 1.3, 1.3]}, 400, "box", ("outside the image",)),
        ({"box": [-0.5, 0.2, -0.1, 0.3]}, 400, "box", ("outside the image",)),
        ({"box": [0.6, 0.5, 0.4, 0.7]}, 400, "box", ("x1 > x0",)),
        ({"box": [0.1, 0.2, 0.3]}, 400, "box", ("4 finite numbers",)),
        ('{"box": [0.1, 0.2, 0.3, NaN]}', 400, "box", ("4 finite numbers",)),
        ({"box": ["a", 0.2, 0.3, 0.4]}, 422, "box.0", ("valid number",)),
        ({"box": [0.1, 0.1, 0.2, 0.2], "point": [0.5, 0.5]}, 400, "box", ("exactly one",)),
        ({}, 400, "box", ("exactly one",)),
        ({"point": [1.0, 0.5]}, 400, "point", ("outside the image",)),
        ({"point": [0.5]}, 400, "point", ("2 finite numbers",)),
    ],
)
def test_bad_target_requests(
    client: TestClient, body: dict | str, status: int, field: str, words: tuple
) -> None:
    before = client.get("/api/state").json()["scene"]
    if isinstance(body, str):  # JSON that json.dumps refuses to write (NaN)
        response = client.post("/api/target", content=body, headers={"Content-Type": "application/json"})
    else:
        response = client.post("/api/target", json=body)
    _error(response, status, field, *words)
    assert client.get("/api/state").json()["scene"] == before


def test_box_on_the_bare_table_is_refused(client: TestClient, reference: LegoPickEnv) -> None:
    table = [0.40, 0.80, 0.48, 0.86]  # below the grid, between the fingers
    boxes = np.stack([reference.brick_box(i).bbox for i in range(N_BRICKS)])
    assert bbox_iou(np.array(table)[None], boxes).max() < MIN_TARGET_IOU  # the premise
    _error(client.post("/api/target", json={"box": table}), 400, "box", "does not outline a brick")


def test_click_designates_the_brick_under_it(client: TestClient, reference: LegoPickEnv) -> None:
    k = _other_visible_brick(reference)
    masks = reference.render_brick_masks()
    ys, xs = np.nonzero(masks == k)
    i = len(xs) // 2
    point = [(xs[i] + 0.5) / 224, (ys[i] + 0.5) / 224]
    scene = client.post("/api/target", json={"point": point}).json()["scene"]
    assert scene["target"] == k and scene["target_source"] == "click"
    np.testing.assert_allclose(scene["box"], reference.brick_box(k).bbox, atol=1e-7)
    ys, xs = np.nonzero(masks < 0)
    off = [(xs[0] + 0.5) / 224, (ys[0] + 0.5) / 224]
    _error(client.post("/api/target", json={"point": off}), 400, "point", "not on a brick")


# ---------------------------------------------------------------- runs


def test_expert_picks_the_drawn_target_and_the_policy_gets_the_drawn_box(
    client: TestClient, reference: LegoPickEnv
) -> None:
    k = _other_visible_brick(reference)
    drawn = _padded(reference.brick_box(k).bbox)
    assert client.post("/api/target", json={"box": drawn}).status_code == 200
    state = client.post("/api/run", json={"policies": ["expert"], "realtime": False}).json()
    assert state["phase"] == "running" and state["run"]["lanes"][0]["policy"] == "expert"
    state = _wait_phase(client, ("done", "error"))
    lane = state["run"]["lanes"][0]
    assert (state["phase"], lane["outcome"], lane["done"]) == ("done", "pick", True)
    episode = client.get("/api/episode.json")
    assert episode.status_code == 200 and "attachment" in episode.headers["content-disposition"]
    data = episode.json()
    assert (data["target"], data["setting"], data["seed"]) == (k, SETTING, SEED)
    log = data["lanes"][0]["steps_log"]
    assert len(log) == lane["steps"] == data["lanes"][0]["steps"]
    np.testing.assert_allclose(log[0]["policy_bbox"], drawn, atol=1e-6)
    assert log[-1]["outcome"] == "pick"
    # Later boxes come from the tracker, which follows the target: close to the env's box of it.
    ious = [float(bbox_iou(np.array(r["policy_bbox"]), np.array(r["env_bbox"]))) for r in log[1:20]]
    assert np.mean(ious) > 0.5


def test_checkpoint_gets_the_drawn_box_and_oracle_mode_the_envs(
    client: TestClient, reference: LegoPickEnv, checkpoints: Path
) -> None:
    drawn = _padded(reference.brick_box(reference.target).bbox)
    client.post("/api/target", json={"box": drawn})
    body = {"policies": [str(checkpoints / "runs" / "tiny")], "realtime": False, "max_steps": 6}
    assert client.post("/api/run", json=body).status_code == 200
    lane = _wait_phase(client, ("done", "error"))["run"]["lanes"][0]
    assert lane["steps"] == 6 and lane["done"]
    log = client.get("/api/episode.json").json()["lanes"][0]["steps_log"]
    np.testing.assert_allclose(log[0]["policy_bbox"], drawn, atol=1e-6)
    assert len({tuple(r["action"]) for r in log}) > 1  # a real policy acting, not a constant

    body = {"policies": ["runs/tiny"], "realtime": False, "max_steps": 4, "bbox_mode": "oracle"}
    assert client.post("/api/run", json=body).status_code == 200
    _wait_phase(client, ("done", "error"))
    for record in client.get("/api/episode.json").json()["lanes"][0]["steps_log"]:
        np.testing.assert_allclose(record["policy_bbox"], record["env_bbox"], atol=0)


def test_side_by_side_runs_both_lanes_on_the_same_scene_and_box(
    client: TestClient, reference: LegoPickEnv
) -> None:
    drawn = _padded(reference.brick_box(reference.target).bbox)
    client.post("/api/target", json={"box": drawn})
    body = {"policies": ["expert", "expert"], "realtime": False, "max_steps": 40}
    assert client.post("/api/run", json=body).status_code == 200
    state = _wait_phase(client, ("done", "error"))
    a, b = state["run"]["lanes"]
    assert (a["slot"], b["slot"]) == ("A", "B") and a["steps"] == b["steps"] == 40
    lanes = client.get("/api/episode.json").json()["lanes"]
    # Same scene, same box, same (seeded) expert: the two lanes are step-for-step identical.
    assert lanes[0]["steps_log"] == lanes[1]["steps_log"]
    np.testing.assert_allclose(lanes[1]["steps_log"][0]["policy_bbox"], drawn, atol=1e-6)
    assert client.get("/api/frame/wrist_B.jpg").status_code == 200

    video = client.get("/api/video.mp4")
    assert video.status_code == 200 and video.headers["content-type"] == "video/mp4"
    with av.open(io.BytesIO(video.content)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == 41  # the first frame and one per step
    assert frames[0].shape == (448, 524, 3)  # two lanes stacked, each wrist | third person


def test_pause_step_resume_reset_and_conflicts(client: TestClient, reference: LegoPickEnv) -> None:
    _error(client.post("/api/pause"), 409, "phase", "nothing to pause")
    _error(client.post("/api/resume"), 409, "phase", "nothing to resume")
    _error(client.post("/api/step"), 409, "phase", "paused run")
    state = client.post("/api/run", json={"policies": ["expert"], "start_paused": True}).json()
    assert state["phase"] == "paused" and state["run"]["lanes"][0]["steps"] == 0
    for n in (1, 2, 3):
        assert client.post("/api/step").json()["run"]["lanes"][0]["steps"] == n
    # While a run is going: a second run, a new scene, a new target are refused; nothing changes.
    _error(client.post("/api/run", json={"policies": ["expert"]}), 409, "phase", "while a run is paused")
    _error(client.post("/api/scene", json={"setting": SETTING, "seed": 1}), 409, "phase", "while a run")
    _error(client.post("/api/target", json={"point": [0.5, 0.5]}), 409, "phase", "while a run")
    assert client.get("/api/state").json()["run"]["lanes"][0]["steps"] == 3
    assert client.post("/api/resume").json()["phase"] == "running"
    _error(client.post("/api/run", json={"policies": ["expert"]}), 409, "phase", "while a run is running")
    assert client.post("/api/pause").json()["phase"] == "paused"
    state = client.post("/api/reset").json()
    assert state["phase"] == "ready" and state["run"] is None and state["scene"]["seed"] == SEED
    _error(client.get("/api/episode.json"), 404, "run", "no run")
    _error(client.get("/api/frame/wrist_A.jpg"), 404, "view", "no frame yet")


def test_bad_run_requests(client: TestClient, tmp_path: Path) -> None:
    _error(
        client.post("/api/run", json={"policies": ["no/such/folder"]}), 404, "policies[0]", "no checkpoint"
    )
    _error(client.post("/api/run", json={"policies": ["expert", "nope"]}), 404, "policies[1]", "config.json")
    _error(client.post("/api/run", json={"policies": ["shipped"]}), 404, "policies[0]", "no checkpoint ships")
    _error(client.post("/api/run", json={"policies": []}), 400, "policies", "1 or 2")
    _error(client.post("/api/run", json={"policies": ["expert"] * 3}), 400, "policies", "1 or 2")
    _error(client.post("/api/run", json={"bbox_mode": "psychic"}), 400, "bbox_mode", "tracked, oracle")
    _error(client.post("/api/run", json={"max_steps": 0}), 400, "max_steps", "[1, 1000]")
    _error(client.post("/api/run", json={"realtime": "sometimes"}), 422, "realtime", "valid boolean")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "config.json").write_text("{not json")
    (broken / "model.safetensors").write_bytes(b"\0")
    _error(client.post("/api/run", json={"policies": [str(broken)]}), 400, "policies[0]", "could not load")
    assert client.get("/api/state").json()["phase"] == "ready"


# ---------------------------------------------------------------- live view and concurrency


def test_websocket_streams_status_and_live_frames(client: TestClient) -> None:
    with client.websocket_connect("/api/ws") as ws:
        first = json.loads(ws.receive_text())
        assert first["phase"] == "ready"
        client.post("/api/run", json={"policies": ["expert"], "realtime": False, "max_steps": 15})
        versions, frames, last = [first["version"]], {view: 0 for view in LIVE_VIEWS}, None
        while True:
            message = ws.receive()
            if message.get("text") is not None:
                status = json.loads(message["text"])
                versions.append(status["version"])
                if status["phase"] == "done":
                    break
            else:
                data = message["bytes"]
                frames[LIVE_VIEWS[data[0]]] += 1
                if data[0] == 0:
                    last = decode_jpeg(data[1:])
    assert versions == sorted(versions) and status["run"]["lanes"][0]["steps"] == 15
    assert frames["wrist_A"] >= 2 and frames["third_A"] >= 2 and frames["wrist_B"] == 0
    assert last is not None and last.shape == (224, 224, 3)


def test_concurrent_requests_queue_and_the_worker_survives(
    client: TestClient, session: DashboardSession
) -> None:
    codes: list[int] = []
    lock = threading.Lock()

    def hammer(i: int) -> None:
        c = TestClient(create_app(session))
        for request in (
            lambda: c.post("/api/scene", json={"setting": SETTING, "seed": SEED}),
            lambda: c.post("/api/run", json={"policies": ["expert"], "realtime": False, "max_steps": 3}),
            lambda: c.get("/api/state"),
            lambda: c.post("/api/target", json={"box": [1.5, 1.5, 2.0, 2.0]}),
        ):
            response = request()
            with lock:
                codes.append(response.status_code)

    threads = [threading.Thread(target=hammer, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert len(codes) == 24 and set(codes) <= {200, 400, 409}
    assert codes.count(400) == 6  # every bad box refused, whatever else was going on
    _wait_phase(client, ("done", "ready"))
    assert client.post("/api/scene", json={"setting": SETTING, "seed": SEED}).status_code == 200


def test_worker_reports_job_errors_and_survives_a_failing_tick() -> None:
    failures: list[BaseException] = []
    ticks = iter([0.0])  # one tick that raises, then idle

    def tick() -> float | None:
        if next(ticks, None) is not None:
            raise RuntimeError("policy blew up")
        return None

    worker = SimWorker(tick, failures.append)
    try:
        with pytest.raises(ValueError, match="bad job"):
            worker.call(lambda: (_ for _ in ()).throw(ValueError("bad job")))
        assert worker.call(lambda: 41 + 1) == 42
        assert [str(e) for e in failures] == ["policy blew up"]
    finally:
        worker.close()


# ---------------------------------------------------------------- the robot's box picker


def test_box_picker_api() -> None:
    frame = np.zeros((224, 224, 3), np.uint8)
    frame[80:120, 100:140] = (200, 30, 30)
    result: Future = Future()
    c = TestClient(create_picker_app(frame, result))
    assert c.get("/api/config").json() == {"mode": "picker", "image_size": [224, 224], "frame_version": 1}
    assert decode_jpeg(c.get("/api/frame/scene.jpg").content)[100, 120, 0] > 150
    _error(c.get("/api/frame/wrist_A.jpg"), 404, "view", "valid views: scene")
    _error(c.post("/api/pick", json={}), 400, "box", "missing")
    _error(c.post("/api/pick", json={"box": [1.2, 0.1, 1.4, 0.2]}), 400, "box", "outside the image")
    assert not result.done()
    assert c.get("/api/state").json() == {"phase": "picking", "box": None}
    picked = c.post("/api/pick", json={"box": [0.4, 0.3, 0.65, 1.2]}).json()["box"]
    np.testing.assert_allclose(picked, [0.4, 0.3, 0.65, 1.0], atol=1e-6)
    np.testing.assert_allclose(result.result(timeout=1), [0.4, 0.3, 0.65, 1.0], atol=1e-6)
    _error(c.post("/api/pick", json={"box": [0.1, 0.1, 0.2, 0.2]}), 409, "box", "already sent")
    with pytest.raises(ValueError, match=r"\(H, W, 3\) uint8"):
        create_picker_app(np.zeros((10, 10), np.uint8), Future())


# ---------------------------------------------------------------- the command


def test_command_refuses_a_missing_checkpoints_dir(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["--port", "0", "--checkpoints_dir", str(tmp_path / "none")])
    assert exit_info.value.code == 2 and "is not a folder" in capsys.readouterr().err


@pytest.mark.slow  # a subprocess that imports torch and LeRobot: ~10-15 s
def test_command_prints_its_url_and_serves() -> None:
    env = {**os.environ, "MUJOCO_GL": "egl"}
    command = [sys.executable, "-m", "lerobot_bboxpick.apps.dashboard.server", "--port", "0"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = process.stdout.readline()
        assert line.startswith("bboxpick dashboard: http://127.0.0.1:"), line or process.stderr.read()
        url = line.split()[2]
        assert httpx2.get(url + "api/config", timeout=30).json()["settings"] == list(SETTINGS)
        assert httpx2.get(url + "api/state", timeout=30).json()["phase"] == "empty"
    finally:
        process.terminate()
        process.wait(timeout=30)
