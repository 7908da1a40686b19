"""LeRobot's lerobot-dataset-viz works on our datasets, and bboxpick-dataset-viz adds the target box."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # subprocesses, video decoding
BIN = Path(sys.executable).parent


def _boxes_in(rrd: Path) -> tuple[dict[int, np.ndarray], set[str]]:
    import rerun.recording as recording

    rec = recording.load_recording(rrd)
    boxes, entities = {}, set()
    for chunk in rec.chunks():
        entities.add(str(chunk.entity_path))
        if str(chunk.entity_path) != "/observation.images.wrist/bbox":
            continue
        batch = chunk.to_record_batch()
        if "Boxes2D:centers" not in batch.schema.names:
            continue
        frames = batch.column("frame_index").to_pylist()
        centres = batch.column("Boxes2D:centers").to_pylist()
        halves = batch.column("Boxes2D:half_sizes").to_pylist()
        for k, c, h in zip(frames, centres, halves, strict=True):
            c, h = np.array(c[0]), np.array(h[0])
            boxes[k] = np.concatenate([c - h, c + h])
    return boxes, entities


def test_viewers_record_the_episode_with_its_bbox(tmp_path):
    from helpers_data import make_expert_dataset

    from lerobot_bboxpick.data.dataset_viz import episode_boxes
    from lerobot_bboxpick.data.replay import load_dataset

    root = tmp_path / "data"
    make_expert_dataset(root, seeds=[0], repo_id="test/viz")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}
    common = ["--repo-id", "test/viz", "--root", str(root), "--episode-index", "0", "--save", "1"]
    for tool, out in (
        ("lerobot-dataset-viz", tmp_path / "lerobot"),
        ("bboxpick-dataset-viz", tmp_path / "ours"),
    ):
        result = subprocess.run(
            [BIN / tool, *common, "--output-dir", str(out)],
            capture_output=True,
            text=True,
            env=env,
            timeout=300,
        )
        assert result.returncode == 0, result.stderr[-3000:]
    (lerobot_rrd,) = (tmp_path / "lerobot").glob("*.rrd")
    _, entities = _boxes_in(lerobot_rrd)
    assert {"/observation.images.wrist", "/state", "/action"} <= entities  # LeRobot's own view works

    (ours,) = (tmp_path / "ours").glob("*.rrd")
    boxes, _ = _boxes_in(ours)
    expected = episode_boxes(load_dataset("test/viz", root), 0) * 224
    visible = [k for k, b in enumerate(expected) if b[2] > b[0]]
    assert sorted(boxes) == visible and len(visible) > 50
    assert max(np.abs(boxes[k] - expected[k]).max() for k in visible) < 1e-3  # pixels, as recorded
