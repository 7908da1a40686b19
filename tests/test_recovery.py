"""Recovery demonstrations: an unrecorded off-course lead-in, then the expert's recorded recovery."""

import numpy as np
import pytest

from lerobot_bboxpick.data.collect import CollectConfig, ExpertRecorder, collect
from lerobot_bboxpick.data.recovery import LEAD_INS, RecoveryRecorder, lead_in_actions
from lerobot_bboxpick.data.replay import episode_arrays, load_dataset
from lerobot_bboxpick.keys import STATE


@pytest.fixture(scope="module")
def env():
    env = ExpertRecorder().make_env("grid_id")
    yield env
    env.close()


def _start_state(env, seed: int) -> np.ndarray:
    env.reset(seed=seed)
    return env.agent_pos()


@pytest.mark.parametrize("kind", LEAD_INS)
def test_a_lead_in_leaves_the_expert_path_and_the_expert_recovers(env, kind):
    """A recovery episode starts where the lead-in left the arm (centimetres from the brick, not at the
    start pose) and the expert's re-plan from there still picks the target."""
    seed = 3
    env.reset(seed=seed)
    rng = np.random.default_rng(0)
    for action in lead_in_actions(env, kind, rng):
        env.step(action)
    brick = env.brick_pose(env.target)[:3, 3]
    tcp = env.tcp_pose()[:3, 3]
    lateral = np.linalg.norm(tcp[:2] - brick[:2])
    assert 0.005 < lateral < 0.06, lateral  # off the brick's axis, but near it
    assert tcp[2] - brick[2] < 0.1  # down at the bricks, far below the 0.22 m start height


def test_fraction_one_records_recoveries_and_zero_plain_demos(env):
    frames_plain, outcome_plain = RecoveryRecorder(fraction=0.0)(env, 5)
    start = _start_state(env, 5)
    assert outcome_plain == "pick"
    np.testing.assert_allclose(frames_plain[0][STATE], start, atol=1e-6)  # a plain demo starts at reset

    frames, outcome = RecoveryRecorder(fraction=1.0)(env, 5)
    assert outcome == "pick"
    moved = np.linalg.norm(frames[0][STATE][:3] - start[:3])
    assert moved > 0.08, moved  # recorded from where the lead-in left the arm
    again, _ = RecoveryRecorder(fraction=1.0)(env, 5)  # the seed decides everything
    np.testing.assert_array_equal(
        np.stack([f["action"] for f in frames]), np.stack([f["action"] for f in again])
    )


def test_collect_config_recovery_reaches_the_recorder(env, tmp_path):
    """``CollectConfig(recovery=...)`` alone (what bboxpick-collect --recovery passes) records
    recovery demos: the episode starts where the lead-in left the arm, not at the reset pose."""
    root = tmp_path / "ds"
    collect(CollectConfig(repo_id="test/recovery", root=root, episodes=1, recovery=1.0))
    states = episode_arrays(load_dataset("test/recovery", root), 0)["states"]
    assert np.linalg.norm(states[0, :3] - _start_state(env, 0)[:3]) > 0.08


def test_bad_fraction_and_kind_are_refused(env):
    with pytest.raises(ValueError, match=r"recovery=1.5 must be a fraction in \[0, 1\]"):
        RecoveryRecorder(fraction=1.5)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="valid kinds: offset, failed_grasp"):
        lead_in_actions(env, "spin", np.random.default_rng(0))


def test_resuming_with_another_recovery_fraction_is_refused(tmp_path):
    import json

    from lerobot_bboxpick.data.collect import CollectConfig, ExpertRecorder, check_resumable
    from lerobot_bboxpick.data.recovery import RecoveryRecorder

    cfg = CollectConfig(root=tmp_path / "ds", resume=True)
    shard = cfg.work_dir / "shard_00000000"
    shard.mkdir(parents=True)
    recorded = RecoveryRecorder(fraction=0.3).run_key
    (shard / "seeds.json").write_text(json.dumps([{"seed": 0, "kept": True, "run_key": recorded}]))
    check_resumable(cfg, RecoveryRecorder(fraction=0.3).run_key)  # the same run resumes
    for other in (RecoveryRecorder(fraction=0.5), ExpertRecorder()):
        with pytest.raises(ValueError, match=r"recorded as \{'recovery': 0.3\}.*choose another --root"):
            check_resumable(cfg, other.run_key)
