"""The ``ur5`` robot (MuJoCo backend) through LeRobot's own CLIs in subprocesses: ``lerobot-record`` with
the expert teleoperator, ``lerobot-train`` on what it recorded, ``lerobot-rollout`` (base, with a spy on
what the policy received) and one DAgger correction typed on a terminal as a person would."""

from __future__ import annotations

import json
import os
import pty
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers_cli import TINY_BBOX_DIFFUSION, cli_env

pytestmark = pytest.mark.slow

BIN = Path(sys.executable).parent
TESTS = Path(__file__).parent
TASK = "--dataset.single_task=pick up the block in the box"
TINY = [*TINY_BBOX_DIFFUSION, "--policy.push_to_hub=false"]
_env = cli_env


def _run(cmd: list, timeout: float = 600) -> str:
    result = subprocess.run(
        [str(c) for c in cmd],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=_env(),
        stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 0, (result.stdout + result.stderr)[-4000:]
    return result.stdout + result.stderr


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two expert episodes recorded by lerobot-record (scenes of seeds 0 and 1) and its console log."""
    root = tmp_path_factory.mktemp("ur5_rec") / "data"
    log = _run(
        [
            BIN / "lerobot-record",
            "--robot.type=ur5",
            "--robot.seed=0",
            "--robot.scene_time_s=8.1",  # episode_time_s + a little: each episode starts a scene
            "--teleop.type=bboxpick_expert",
            "--dataset.repo_id=local/ur5_expert",
            f"--dataset.root={root}",
            "--dataset.fps=20",
            "--dataset.num_episodes=2",
            "--dataset.episode_time_s=8",
            "--dataset.reset_time_s=0",
            TASK,
            "--dataset.push_to_hub=false",
            "--play_sounds=false",
        ]
    )
    return root, log


@pytest.fixture(scope="module")
def checkpoint(recorded, tmp_path_factory):
    """One lerobot-train step of bbox_diffusion on the recorded dataset, unchanged."""
    out = tmp_path_factory.mktemp("ur5_train") / "train"
    _run(
        [
            BIN / "lerobot-train",
            *TINY,
            "--dataset.repo_id=local/ur5_expert",
            f"--dataset.root={recorded[0]}",
            f"--output_dir={out}",
            "--steps=1",
            "--batch_size=2",
            "--num_workers=0",
            "--save_freq=1",
            "--wandb.enable=false",
        ]
    )
    return out / "checkpoints" / "last" / "pretrained_model"


def test_the_clis_list_the_robot_and_the_teleoperator():
    for cli in ("lerobot-record", "lerobot-rollout"):
        text = _run([BIN / cli, "--help"], timeout=120)
        assert "ur5" in text and "bboxpick_expert" in text, cli
    for cli in ("bboxpick-record-ee", "bboxpick-rollout-ee"):  # a person's end-effector teleoperators
        text = _run([BIN / cli, "--help"], timeout=120)
        assert "ur5" in text and "keyboard_ee" in text and "gamepad" in text, cli


def test_lerobot_record_with_the_expert_records_two_picks(recorded):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_bboxpick.robots.ur5.ur5 import BBOX_KEYS, POSE_KEYS

    root, log = recorded
    ds = LeRobotDataset("local/ur5_expert", root=root)
    assert ds.num_episodes == 2 and ds.fps == 20
    assert ds.features["observation.state"]["names"] == list(POSE_KEYS + BBOX_KEYS)
    assert ds.features["action"]["names"] == list(POSE_KEYS)
    assert "scene 0 (seed 0) ended: pick" in log and "scene 1 (seed 1) ended: pick" in log
    states = np.stack([ds[i]["observation.state"].numpy() for i in range(ds.num_frames)])
    episodes = np.array([int(ds[i]["episode_index"]) for i in range(ds.num_frames)])
    for e in (0, 1):
        s = states[episodes == e]
        assert len(s) >= 120, f"episode {e}: {len(s)} frames"  # 8 s at 20 fps, some loss when loaded
        assert s[0, 2] == pytest.approx(0.22, abs=0.02)  # starts at the start pose: a fresh scene
        assert s[0, 12] > s[0, 10] > 0  # the target's box is in the first frame
        closed = np.flatnonzero(s[:, 9] < 0.04)
        assert len(closed), f"episode {e}: the gripper never closed"
        assert s[closed[0] :, 2].max() - s[closed[0], 2] > 0.05  # and lifted by more than 5 cm
    # Episode 1's first box is not episode 0's last: a new scene, not the tail of the old one.
    assert np.abs(states[episodes == 1][0, 10:] - states[episodes == 0][-1, 10:]).max() > 0.01


def test_lerobot_train_reads_the_packed_state_as_pose_and_bbox(checkpoint):
    config = json.loads((checkpoint / "config.json").read_text())
    assert config["input_features"]["observation.state"]["shape"] == [10]
    assert config["input_features"]["observation.bbox"]["shape"] == [4]
    steps = [
        s["registry_name"] for s in json.loads((checkpoint / "policy_preprocessor.json").read_text())["steps"]
    ]
    assert "bboxpick_unpack_bbox_from_state" in steps


def _base_rollout(checkpoint: Path, duration_s: int) -> list[str]:
    """lerobot-rollout options: the base strategy on scene 10000 for ``duration_s`` seconds."""
    return [
        "--robot.type=ur5",
        "--robot.seed=10000",
        # A one-step policy's actions are noise: a wide box keeps the robot from refusing them (the
        # simulator's IK still clamps to its reach).
        "--robot.safety.workspace_low=[-2,-2,-1]",
        "--robot.safety.workspace_high=[2,2,2]",
        f"--policy.path={checkpoint}",
        "--strategy.type=base",
        f"--duration={duration_s}",
        "--fps=20",
        "--task=pick up the block in the box",
        "--play_sounds=false",
        "--device=cpu",
    ]


def test_lerobot_rollout_base_feeds_the_policy_the_robot_bbox_and_pose(checkpoint, tmp_path):
    spy = tmp_path / "spy.jsonl"
    _run(
        [
            sys.executable,
            TESTS / "rollout_spy.py",
            spy,
            *_base_rollout(checkpoint, duration_s=10),
        ]
    )
    events = [json.loads(line) for line in spy.read_text().splitlines()]
    calls = [i for i, e in enumerate(events) if "policy_box" in e]
    assert len(calls) >= 3, f"the policy was called {len(calls)} times"
    for i in calls:  # each call saw the last observation the robot reported
        robot = next(e for e in reversed(events[:i]) if "robot_box" in e)
        np.testing.assert_allclose(events[i]["policy_box"], robot["robot_box"], atol=1e-6)
        np.testing.assert_allclose(events[i]["policy_state"], robot["robot_pose"], atol=1e-5)
    first = events[calls[0]]["policy_box"]  # at the start the target is in view: a real box, not zeros
    assert first[2] > first[0] > 0 and first[3] > first[1] > 0


def test_bboxpick_rollout_ee_runs_lerobots_rollout_with_the_delta_step(checkpoint):
    """The entry point a person uses for DAgger with a keyboard or gamepad: LeRobot's rollout, our teleop
    step. (The takeover itself needs a keyboard on an X11 session or a gamepad: not here.)"""
    out = _run(
        [
            BIN / "bboxpick-rollout-ee",
            *_base_rollout(checkpoint, duration_s=3),
        ]
    )
    assert "rollout strategy base, teleop actions through ['EEDeltaToPose10Step']" in out


def _wait_for(log: Path, text: str, process: subprocess.Popen, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in log.read_text():
            return
        assert process.poll() is None, log.read_text()[-3000:]
        time.sleep(0.2)
    raise AssertionError(f"{text!r} not seen in {timeout} s: {log.read_text()[-3000:]}")


def test_one_dagger_correction_by_the_expert_is_recorded(checkpoint, tmp_path):
    """A person at the terminal: space pauses the policy, tab hands over to the expert, tab again ends
    the correction, which LeRobot's DAgger strategy saves as one episode."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root, log = tmp_path / "dagger", tmp_path / "dagger.log"
    master, slave = pty.openpty()  # the strategy reads keys from its terminal
    cmd = [
        BIN / "lerobot-rollout",
        "--robot.type=ur5",
        "--robot.seed=10001",
        "--robot.scene_time_s=600",
        "--robot.safety.workspace_low=[-2,-2,-1]",
        "--robot.safety.workspace_high=[2,2,2]",
        "--teleop.type=bboxpick_expert",
        "--strategy.type=dagger",
        f"--policy.path={checkpoint}",
        "--dataset.repo_id=local/rollout_dagger",
        f"--dataset.root={root}",
        "--dataset.fps=20",
        TASK,
        "--dataset.num_episodes=1",
        "--dataset.push_to_hub=false",
        "--fps=20",
        "--play_sounds=false",
        "--device=cpu",
        "--return_to_initial_position=false",
    ]
    with open(log, "w") as out:
        process = subprocess.Popen([str(c) for c in cmd], stdin=slave, stdout=out, stderr=out, env=_env())
    try:
        _wait_for(log, "recording started", process, 180)
        time.sleep(6)  # the policy's warm-up and a few autonomous steps
        os.write(master, b" ")  # pause
        _wait_for(log, "autonomous -> paused", process, 30)
        os.write(master, b"\t")  # correct
        _wait_for(log, "paused -> correcting", process, 30)
        time.sleep(6)
        os.write(master, b"\t")  # end the correction: saved as an episode
        _wait_for(log, "Correction 1/1 saved", process, 60)
        assert process.wait(timeout=120) == 0
    finally:
        if process.poll() is None:
            process.kill()
        os.close(master)
        os.close(slave)
    ds = LeRobotDataset("local/rollout_dagger", root=root)
    assert ds.num_episodes == 1 and ds.num_frames >= 30  # 6 s at up to 20 fps (slower when loaded)
    assert all(bool(ds[i]["intervention"]) for i in range(ds.num_frames))
    # The expert re-plans from wherever the policy left the arm: down onto the target from above, or first
    # up to above it when the policy left the arm low (CI saw that once), so the sign of the motion depends
    # on the policy; its size does not: the correction moves the arm by centimetres.
    xyz = np.array([ds[i]["action"][:3].numpy() for i in range(ds.num_frames)])
    assert np.linalg.norm(xyz - xyz[0], axis=1).max() > 0.03
