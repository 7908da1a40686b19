"""Measured advantages of counterfactual successes (rl.branch_advantages): G - V with V the mean return of
the policy's own draws at the point, one per training episode in success_demos's order, leading episodes
at 0, and a dataset that does not end with the branches is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lerobot_bboxpick.rl.branch_advantages import (
    branch_advantages,
    dataset_advantages,
    load_advantages,
    point_values,
)
from lerobot_bboxpick.rl.counterfactual_dataset import CounterfactualPoints
from lerobot_bboxpick.sim.outcome import OUTCOMES

PICK, EMPTY = OUTCOMES.index("pick"), OUTCOMES.index("empty")
KINDS = ["policy", "sample1", "x+0.030", "expert"]


def points() -> CounterfactualPoints:
    """Two points: at the first the policy's draws both pick (V = 0.5) and the +x move too; at the second
    neither draw picks (V = 0) and only the expert does."""
    outcome = np.array([[PICK, PICK, PICK, EMPTY], [EMPTY, EMPTY, EMPTY, PICK]], dtype=np.int8)
    ret = np.array([[0.6, 0.4, 0.7, 0.0], [0.0, 0.0, 0.0, 0.3]], dtype=np.float32)
    steps = np.array([[51, 91, 36, 300], [300, 300, 300, 120]], dtype=np.int16)
    n = len(outcome)
    return CounterfactualPoints(
        image=np.zeros((n, 2, 3, 4, 4), np.uint8),
        state=np.zeros((n, 2, 10)),
        bbox=np.zeros((n, 2, 4), np.float32),
        candidates=np.zeros((n, 4, 16, 10), np.float32),
        outcome=outcome,
        steps=steps,
        ret=ret,
        step=np.array([0, 24]),
        setting=np.array(["random_id", "random_id"]),
        seed=np.array([1000, 1000]),
        kinds=KINDS,
    )


def test_values_are_the_mean_return_of_the_policys_draws():
    assert point_values(points()) == pytest.approx([0.5, 0.0])
    assert point_values(points(), "expert") == pytest.approx([0.0, 0.3])
    with pytest.raises(ValueError, match="baseline='teacher' matches none of the candidate kinds"):
        point_values(points(), "teacher")


def test_advantages_follow_the_success_episodes_order():
    # picking branches in order: (0, policy), (0, sample1), (0, x+), (1, expert)
    assert branch_advantages(points()) == pytest.approx([0.1, -0.1, 0.2, 0.3])


def test_leading_episodes_get_zero_and_the_tail_must_be_the_branches():
    lengths = np.array([150, 140, 51, 91, 36, 120])  # two demos, then the four branches
    assert dataset_advantages(points(), lengths, "policy,sample") == pytest.approx(
        [0, 0, 0.1, -0.1, 0.2, 0.3]
    )
    with pytest.raises(ValueError, match=r"branch 0: 36 frames, the branch ran 51 steps"):
        dataset_advantages(points(), np.array([150, 36, 51, 91, 120]), "policy,sample")  # shuffled
    with pytest.raises(ValueError, match="fewer than the 4 picking branches"):
        dataset_advantages(points(), np.array([51, 91, 36]), "policy,sample")


def test_bad_files_name_the_field(tmp_path):
    with pytest.raises(FileNotFoundError, match="awr_advantages_path='nowhere.json' is not a"):
        load_advantages("nowhere.json")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"weights": [1.0]}))
    with pytest.raises(ValueError, match="holds no 'advantages' list"):
        load_advantages(bad)
