"""Transitions from outcome-labelled episodes: rewards, discounts, chunks, phases, split (synthetic table)."""

from __future__ import annotations

import numpy as np
import pytest

from lerobot_bboxpick.geometry import absolute_pose10, pos_axis_angle_to_pose9
from lerobot_bboxpick.rl.critic_dataset import (
    OUTCOME_GROUPS,
    PHASES,
    CriticDataConfig,
    FrameTable,
    build_transitions,
    obs_window_rows,
    split_episodes,
)
from lerobot_bboxpick.sim.outcome import OUTCOMES

GAMMA = 0.99


def synthetic_table(outcomes: list[str], length: int = 60, success_at: int = 50, seed: int = 0) -> FrameTable:
    """Episodes of ``length`` frames with random TCP poses (random rotations) and actions = next poses;
    success episodes set next.success from ``success_at`` on; the gripper closes at frame 30."""
    rng = np.random.default_rng(seed)
    states, actions, success, outcome, bounds = [], [], [], [], []
    for e, name in enumerate(outcomes):
        pos = rng.uniform([0.3, -0.2, 0.05], [0.6, 0.2, 0.3], size=(length + 1, 3))
        rot = rng.normal(size=(length + 1, 3))
        poses = pos_axis_angle_to_pose9(pos, rot)
        width = np.where(np.arange(length + 1) < 30, 0.075, 0.0)[:, None]
        p10 = np.concatenate([poses, width], axis=1)
        states.append(p10[:-1])
        actions.append(p10[1:])
        s = np.zeros(length, dtype=bool)
        if name == "pick":
            s[success_at:] = True
        success.append(s)
        outcome.append(np.full(length, OUTCOMES.index(name)))
        bounds.append((e * length, (e + 1) * length))
    n = len(outcomes) * length
    return FrameTable(
        state=np.concatenate(states),
        bbox=np.zeros((n, 4), np.float32),
        action=np.concatenate(actions),
        success=np.concatenate(success),
        outcome=np.concatenate(outcome),
        episode_bounds=np.array(bounds),
        episode_ids=np.arange(len(outcomes)),
    )


def test_sparse_terminal_rewards_discounts_and_phases():
    table = synthetic_table(["pick", "empty", "wrong", "contact"])
    cfg = CriticDataConfig(val_fraction=0.0, start_steps=5, near_terminal_steps=10, pregrasp_steps=8)
    tr = build_transitions(table, cfg, horizon=16, stride=12, gamma=GAMMA)
    # A success ends at its first next.success frame (50): frames 0..50 -> 51 transitions; failures 60.
    assert len(tr) == 51 + 3 * 60
    succ = tr.subset(tr.group == OUTCOME_GROUPS.index("success"))
    assert succ.obs_row.tolist() == list(range(51))
    # done when the terminal frame lies within the chunk's 12 executed steps: t = 39..50
    assert np.flatnonzero(succ.done).tolist() == list(range(39, 51))
    # reward = +1 discounted per step to the terminal; zero before
    np.testing.assert_allclose(succ.reward[39:], GAMMA ** np.arange(11, -1, -1), rtol=1e-6)
    assert np.all(succ.reward[:39] == 0)
    np.testing.assert_allclose(succ.discount, GAMMA**12, rtol=1e-6)
    assert succ.next_row[0] == 12 and succ.next_row[38] == 50
    # miss (empty and contact) 0, wrong -1 at the last frame
    for name, value in (("miss", 0.0), ("wrong", -1.0)):
        g = tr.subset(tr.group == OUTCOME_GROUPS.index(name))
        np.testing.assert_allclose(g.reward[g.done], value * GAMMA ** g.steps_to_end[g.done], rtol=1e-6)
    assert tr.subset(tr.group == OUTCOME_GROUPS.index("miss")).done.sum() == 24  # two episodes x 12
    # phases of the success: start 0-4, mid 5-28, near terminal = the 10 frames before the final chunk
    expected = ["start"] * 5 + ["mid"] * 24 + ["near_terminal"] * 10 + ["terminal"] * 12
    assert [PHASES[p] for p in succ.phase] == expected
    # pre-grasp: the 8 frames before the commanded close (action width 0 from action row 29)
    assert np.flatnonzero(succ.pregrasp).tolist() == list(range(21, 29))
    assert not tr.subset(tr.group != OUTCOME_GROUPS.index("success")).pregrasp.any()


def test_chunks_are_the_dataset_actions_relative_to_the_observed_pose():
    table = synthetic_table(["pick", "wrong"], length=40, success_at=35)
    tr = build_transitions(table, CriticDataConfig(val_fraction=0.0), horizon=16, stride=8, gamma=GAMMA)
    # composing back with the base pose gives the absolute actions, clamped at the episode's last frame
    rows = np.minimum(tr.obs_row[:, None] + np.arange(16), np.where(tr.group[:, None] == 0, 39, 79))
    back = absolute_pose10(tr.actions.astype(np.float64), tr.base_pose[:, None, :])
    np.testing.assert_allclose(back, table.action[rows], atol=1e-5)
    # a chunk relative to its own base starting at the base pose is the identity pose
    np.testing.assert_allclose(tr.base_pose, table.state[tr.obs_row])


def test_observation_history_is_clamped_to_the_episode_start():
    table = synthetic_table(["pick", "wrong"], length=40, success_at=35)
    assert obs_window_rows(np.array([0, 1, 40, 41]), table, 2).tolist() == [
        [0, 0],
        [0, 1],
        [40, 40],
        [40, 41],
    ]
    assert obs_window_rows(np.array([42]), table, 3).tolist() == [[40, 41, 42]]


def test_validation_split_is_by_episode_and_stratified():
    groups = ["success"] * 20 + ["miss"] * 10 + ["wrong"] * 10
    val = split_episodes(groups, 0.1, seed=0)
    assert val[:20].sum() == 2 and val[20:30].sum() == 1 and val[30:].sum() == 1
    assert (val == split_episodes(groups, 0.1, seed=0)).all()
    assert split_episodes(["success", "wrong"], 0.1, seed=0).sum() == 1  # at least one held out
    table = synthetic_table(["pick", "pick", "empty", "wrong"], length=30, success_at=25)
    tr = build_transitions(table, CriticDataConfig(val_fraction=0.3), horizon=16, stride=8, gamma=GAMMA)
    for e in range(4):  # every transition of an episode is on the same side
        assert len(np.unique(tr.is_val[tr.episode == e])) == 1


def test_bad_labels_and_options_are_refused_by_name():
    table = synthetic_table(["pick", "wrong"], length=30, success_at=25)
    table.outcome[30:] = -1
    with pytest.raises(ValueError, match=r"episode 1 has episode.outcome \[-1\].*pick"):
        build_transitions(table, CriticDataConfig(), horizon=16, stride=8, gamma=GAMMA)
    with pytest.raises(ValueError, match="val_fraction"):
        CriticDataConfig(val_fraction=1.0)
    with pytest.raises(ValueError, match="chunk_stride"):
        CriticDataConfig(chunk_stride=0)
    with pytest.raises(ValueError, match="success, miss, wrong"):
        CriticDataConfig().reward_of("pick")
