"""The ``lerobot_bboxpick`` command: the main job writes what a person looks at; bad input is refused."""

import csv
import subprocess
import sys
from pathlib import Path

import cv2

from lerobot_bboxpick.cli import main

BIN = Path(sys.executable).parent


def test_demo_writes_video_sheet_and_table(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--out-dir", str(out), "--settings", "grid_id,identical_2"]) == 0
    rows = list(csv.DictReader((out / "outcomes.csv").read_text().splitlines()))
    outcomes = [(r["setting"], r["outcome"]) for r in rows]
    assert outcomes == [("grid_id", "pick"), ("identical_2", "pick")]
    assert "| grid_id | 1 | 0 | 0 | 0 |" in (out / "outcomes.md").read_text()
    video = cv2.VideoCapture(str(out / "grid_id_seed0.mp4"))
    n_frames = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
    assert n_frames == int(rows[0]["steps"]) + 1 and video.get(cv2.CAP_PROP_FRAME_WIDTH) == 224
    sheet = cv2.imread(str(out / "settings_contact_sheet.png"))
    assert sheet.shape == (448, 3 * 448, 3)


def test_unknown_setting_is_refused_with_the_valid_list():
    result = subprocess.run(
        [BIN / "lerobot_bboxpick", "demo", "--settings", "grid_id,piles"], capture_output=True, text=True
    )
    assert result.returncode == 2
    assert "setting='piles'" in result.stderr and "identical_4" in result.stderr


def test_non_positive_episode_count_is_refused():
    result = subprocess.run(
        [BIN / "lerobot_bboxpick", "demo", "--episodes", "0"], capture_output=True, text=True
    )
    assert result.returncode == 2 and "--episodes" in result.stderr and ">= 1" in result.stderr
