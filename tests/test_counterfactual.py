"""Counterfactual simulation: a restored snapshot replays the episode bit for bit (poses, pixels, outcome),
in the same env later, after another episode's reset and in another env of the same options; a perturbed
chunk branches off, the same way every time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from lerobot_bboxpick.rl.counterfactual import EPISODE_STATE, SimSnapshot, restore, run_branch, snapshot
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.expert import ScriptedExpert

SEED = 3
CHUNK = 12  # bbox_diffusion's n_action_steps
SNAP_STEP = 3 * CHUNK  # a chunk boundary, during the approach


@dataclass
class Continuation:
    """The original episode from the snapshot on."""

    snap: SimSnapshot
    pose_at_snap: np.ndarray
    frame_at_snap: np.ndarray
    actions: np.ndarray
    poses: np.ndarray
    images: list[np.ndarray]
    outcome: str
    reward: float


@pytest.fixture(scope="module")
def env():
    env = LegoPickEnv(setting="grid_id")
    yield env
    env.close()


@pytest.fixture(scope="module")
def original(env) -> Continuation:
    env.reset(seed=SEED)
    expert = ScriptedExpert(np.random.default_rng(SEED))
    expert.reset(env)
    for _ in range(SNAP_STEP):
        env.step(expert.act())
    snap = snapshot(env)
    pose_at_snap, frame_at_snap = env.tcp_pose(), env.render()
    actions, poses, images = [], [], []
    terminated = truncated = False
    while not (terminated or truncated):
        actions.append(expert.act())
        obs, reward, terminated, truncated, info = env.step(actions[-1])
        poses.append(env.tcp_pose())
        images.append(obs["pixels"]["wrist"])
    assert info["outcome"] == "pick" and terminated  # the expert picks this scene: a full episode to replay
    return Continuation(
        snap, pose_at_snap, frame_at_snap, np.stack(actions), np.stack(poses), images, info["outcome"], reward
    )


def replay(actions: np.ndarray):
    """A policy_fn that replays ``actions`` whatever it observes."""
    it = iter(actions)
    return lambda obs: next(it)


def branch(env, snap, chunk, rest, max_steps):
    """run_branch with the wrist images of every step kept."""
    images = []
    keep = lambda action, obs, reward, info: images.append(obs["pixels"]["wrist"])  # noqa: E731
    return run_branch(env, snap, chunk, replay(rest), max_steps, on_step=keep), images


def assert_replays(result, images, orig: Continuation, n: int | None = None) -> None:
    n = n or len(orig.actions)
    assert result.steps == n
    assert np.abs(result.tcp_poses - orig.poses[:n]).max() == 0.0
    assert all(np.array_equal(a, b) for a, b in zip(images, orig.images[:n], strict=True))


def test_restore_replays_the_original_continuation_exactly(env, original):
    # env is now at the end of the original episode (a pick): restore goes back 90-odd steps.
    restore(env, original.snap)
    assert np.array_equal(env.tcp_pose(), original.pose_at_snap)  # derived arrays restored too
    assert np.array_equal(env.render(), original.frame_at_snap)
    acts = original.actions
    result, images = branch(env, original.snap, acts[:CHUNK], acts[CHUNK:], max_steps=len(acts) + 10)
    assert_replays(result, images, original)
    assert (result.outcome, result.reward, result.success) == (original.outcome, original.reward, True)
    assert result.terminated and np.array_equal(result.actions, acts.astype(np.float64))


def test_restore_into_another_episode_replays_exactly(env, original):
    env.reset(seed=SEED + 1)  # another scene: other brick poses, colours, target and start pose
    for _ in range(5):
        env.step(env.agent_pos())
    assert not np.array_equal(env.model.geom_rgba, original.snap.appearance["geom_rgba"])
    acts = original.actions
    result, images = branch(env, original.snap, acts[:CHUNK], acts[CHUNK:], max_steps=len(acts))
    assert_replays(result, images, original)
    assert result.outcome == original.outcome
    assert (env.episode_seed, env.target) == (SEED, original.snap.layout.target)


def test_perturbed_chunk_branches_off_deterministically(env, original):
    chunk = original.actions[:CHUNK].copy()
    chunk[:, 0] += 0.05  # 5 cm further from the robot
    rest, n = original.actions[CHUNK:], 2 * CHUNK
    a, images_a = branch(env, original.snap, chunk, rest, max_steps=n)
    b, images_b = branch(env, original.snap, chunk, rest, max_steps=n)
    assert a.steps == b.steps == n and a.truncated
    assert np.abs(a.tcp_poses[:, :3, 3] - original.poses[:n, :3, 3]).max() > 0.01
    assert np.array_equal(a.tcp_poses, b.tcp_poses)
    assert all(np.array_equal(x, y) for x, y in zip(images_a, images_b, strict=True))
    assert (a.outcome, a.reward) == (b.outcome, b.reward)


def test_restore_into_another_env_needs_the_same_options(original):
    same, other = LegoPickEnv(setting="grid_id"), LegoPickEnv(setting="grid_id", episode_length=123)
    try:
        with pytest.raises(RuntimeError, match="reset"):
            snapshot(same)
        acts = original.actions
        result, images = branch(same, original.snap, acts[:CHUNK], acts[CHUNK:], max_steps=CHUNK)
        assert_replays(result, images, original, n=CHUNK)
        with pytest.raises(ValueError, match="same options"):
            restore(other, original.snap)
        with pytest.raises(ValueError, match="shape"):
            run_branch(same, original.snap, acts[:CHUNK, :9], replay(acts), max_steps=50)
    finally:
        same.close()
        other.close()


def test_snapshot_covers_every_attribute_an_episode_changes(env):
    env.reset(seed=0)
    env.step(env.agent_pos())
    # Built once in __init__ and never reassigned: a new attribute must be added to one of the two lists.
    static = {
        "render_mode", "metadata", "options", "model", "data", "ids", "camera", "controller", "randomizer",
        "n_substeps", "_ramp", "_silhouette", "_max_episode_steps", "observation_space", "action_space",
    }  # fmt: skip
    assert set(vars(env)) - static == set(EPISODE_STATE)
