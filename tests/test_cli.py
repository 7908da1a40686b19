"""The ``lerobot_bboxpick`` command: the main job writes what a person looks at; bad input is refused."""

import csv
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import pytest

from lerobot_bboxpick.apps.cli import main

BIN = Path(sys.executable).parent


@pytest.mark.slow
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


def test_inputs_sheet_shows_the_target_magnified_in_the_target_view(tmp_path):
    """``sheet --inputs``: per setting, the frame, the 64 px policy image and the 48 px target view. The
    view's centre quarter is mostly brick (saturated pixels) in every setting; the same region of the
    frame and of the policy image is mostly table."""
    out = tmp_path / "inputs.png"
    assert main(["sheet", "--inputs", "--out", str(out)]) == 0
    sheet = cv2.imread(str(out))
    assert sheet.shape == (6 * 224, 3 * 224, 3)
    saturated = cv2.cvtColor(sheet, cv2.COLOR_BGR2HSV)[..., 1] > 0.6 * 255
    for row in range(6):
        centres = [
            saturated[row * 224 + 84 : row * 224 + 140, col * 224 + 84 : col * 224 + 140] for col in range(3)
        ]
        frame, policy_image, view = (c.mean() for c in centres)
        assert view > 0.5 and frame < 0.2 and policy_image < 0.2, (row, frame, policy_image, view)


@pytest.mark.slow
def test_unknown_setting_is_refused_with_the_valid_list():
    result = subprocess.run(
        [BIN / "lerobot_bboxpick", "demo", "--settings", "grid_id,piles"], capture_output=True, text=True
    )
    assert result.returncode == 2
    assert "setting='piles'" in result.stderr and "identical_4" in result.stderr


@pytest.mark.slow
def test_non_positive_episode_count_is_refused():
    result = subprocess.run(
        [BIN / "lerobot_bboxpick", "demo", "--episodes", "0"], capture_output=True, text=True
    )
    assert result.returncode == 2 and "--episodes" in result.stderr and ">= 1" in result.stderr


def test_run_trains_the_recipe_and_the_ablation_without_a_centroid(tmp_path):
    """The main job's lerobot-train call carries the recipe's options; the no-prompt ablation differs
    only by its bbox mode (no centroid: it has no mask to measure); a finished checkpoint resumes."""
    from dataclasses import replace

    from lerobot_bboxpick.apps.main_job import PROFILES, train_command

    full = PROFILES["full"]
    args = train_command(full, tmp_path / "data", "local/x", tmp_path / "train", 5000, True)
    recipe = {"--policy.bbox_mode=mask", "--policy.mask_centroid=true", "--policy.n_action_steps=12"}
    assert recipe <= set(args)
    assert {"--steps=5000", "--batch_size=32", "--seed=1000"} <= set(args)
    reseeded = train_command(
        replace(full, train_seed=1), tmp_path / "data", "local/x", tmp_path / "train", 5000, True
    )
    assert set(reseeded) - set(args) == {"--seed=1"}
    ablation = train_command(
        replace(full, bbox_mode="none"), tmp_path / "data", "local/x", tmp_path / "t", 5000, True
    )
    assert {"--policy.bbox_mode=none", "--policy.mask_centroid=false"} <= set(ablation)
    assert set(args) - set(ablation) == {
        "--policy.bbox_mode=mask",
        "--policy.mask_centroid=true",
        f"--output_dir={tmp_path / 'train'}",
    }
    assert "--policy.use_amp=true" in args
    fp32 = train_command(full, tmp_path / "data", "local/x", tmp_path / "train", 5000, False)
    assert set(fp32) - set(args) == {"--policy.use_amp=false"}
    last = tmp_path / "train" / "checkpoints" / "last" / "pretrained_model"
    last.mkdir(parents=True)
    (last / "train_config.json").write_text("{}")
    resumed = train_command(full, tmp_path / "data", "local/x", tmp_path / "train", 5000, True)
    assert resumed[1:] == [
        f"--config_path={last / 'train_config.json'}",
        "--resume=true",
        "--steps=5000",
        "--save_freq=1000",
    ]


def test_quick_and_practical_profiles_train_the_fast_encoder_and_full_the_preset(tmp_path):
    """The first run and the practical recipe use the 64 px single-frame encoder; the paper protocol
    keeps the preset; only the practical recipe records recoveries from every layout."""
    from lerobot_bboxpick.apps.main_job import PROFILES, train_command
    from lerobot_bboxpick.sim.layouts import SETTINGS

    fast = {"--policy.image_size=64", "--policy.n_obs_steps=1"}
    for name, wanted in (("quick", True), ("practical", True), ("full", False)):
        args = set(train_command(PROFILES[name], tmp_path, "local/x", tmp_path / name, 100, False))
        assert (fast <= args) == wanted, name
    practical = PROFILES["practical"]
    # The shipped checkpoint's height input and step count, validated on their own (docs/results.md).
    shipped = {"--policy.height_input=true", "--policy.num_inference_steps=4"}
    assert shipped <= set(train_command(practical, tmp_path, "local/x", tmp_path / "p", 100, False))
    quick = set(train_command(PROFILES["quick"], tmp_path, "local/x", tmp_path / "q", 100, False))
    assert not shipped & quick
    assert (practical.batch_size, practical.steps, practical.use_amp) == (8, 12000, False)
    # No recovery demos in any profile: with the height input they bought nothing (docs/results.md).
    assert practical.train_settings.split(",") == list(SETTINGS)
    assert PROFILES["full"].recovery == PROFILES["quick"].recovery == practical.recovery == 0.0
    # The first run loads data in the trainer's process (a worker slows a 2-core step); the recipes keep one.
    for name, workers in (("quick", 0), ("practical", 1), ("full", 1)):
        args = train_command(PROFILES[name], tmp_path, "local/x", tmp_path / name, 100, False)
        assert f"--num_workers={workers}" in args, name


def test_calibration_rate_is_wall_clock_after_the_first_log_line():
    """The budget is sized from wall-clock seconds per step after the warm-up interval, which includes
    what the logged update/data times leave out; fewer than two log lines give no rate."""
    from lerobot_bboxpick.apps.main_job import wall_seconds_per_step

    # Warm-up: 10 steps in 9 s; then 30 steps in 15 s (0.5 s/step), whatever lerobot-train logged.
    marks = [(109.0, 10), (114.0, 20), (119.0, 30), (124.0, 40)]
    assert wall_seconds_per_step(marks) == pytest.approx(0.5)
    assert wall_seconds_per_step(marks[:1]) is None and wall_seconds_per_step([]) is None
    assert wall_seconds_per_step([(1.0, 10), (2.0, 10)]) is None


def test_quick_training_is_sized_by_its_time_budget_and_full_by_its_samples():
    """Steps follow the measured rate: a 3x slower machine trains 3x fewer steps in the same minutes,
    down to the quick profile's floor, which a slow machine trains to however long it takes; the recipe
    keeps its fixed sample budget on any machine."""
    from lerobot_bboxpick.apps.main_job import (
        _STEP_LINE,
        CALIBRATION_STEPS,
        PROFILES,
        _parse_count,
        budget_steps,
    )

    quick = PROFILES["quick"]
    assert quick.min_steps == 2900
    fast, slower = budget_steps(quick, 0.15), budget_steps(quick, 0.18)
    assert fast == int(quick.train_minutes * 60 / 0.15) == 3600 < quick.steps
    assert slower == 3000  # 1.2x slower, 1.2x fewer steps
    assert budget_steps(quick, 0.01) == quick.steps  # capped
    assert budget_steps(quick, 0.33) == budget_steps(quick, 1000.0) == 2900  # the floor: ~16 min at 0.33 s
    unfloored = replace(quick, min_steps=0)
    assert budget_steps(unfloored, 0.3) == 1800
    assert budget_steps(unfloored, 1000.0) == CALIBRATION_STEPS  # never below the calibration itself
    assert (
        budget_steps(PROFILES["full"], 0.2) == budget_steps(PROFILES["full"], 2.0) == PROFILES["full"].steps
    )
    line = (
        "INFO 2026-12-01 lerobot_train.py:400 step:1K smpl:32K ep:190 epch:1.07 loss:0.120 grdn:0.5 "
        "lr:3.0e-04 updt_s:0.412 data_s:0.013"
    )
    m = _STEP_LINE.search(line)
    assert _parse_count(m.group(1)) == 1000 and float(m.group(2)) + float(m.group(3)) == 0.425
    assert _parse_count("1.2K") == 1200 and _parse_count("40") == 40


@pytest.mark.slow
@pytest.mark.parametrize(
    ("script", "option"),
    [
        ("bboxpick-collect", "--keep_failed"),
        ("bboxpick-rollouts", "--merge_with"),
        ("bboxpick-suite", "--bbox_source"),
        ("bboxpick-train-critic", "--policy_path"),
        ("bboxpick-verify-critic", "--max_states"),
        ("bboxpick-dashboard", "--checkpoints_dir"),
    ],
)
def test_every_command_prints_its_help(script, option):
    """--help lists the options (argparse formats help strings with %, so a stray % breaks it)."""
    result = subprocess.run([BIN / script, "--help"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert option in result.stdout
