"""The per-axis sign-flip diagnostic (rl.sign_flip): agreement of a critic's preferred sign with the true
returns, and where the TCP's own axes point against the world's."""

from __future__ import annotations

import numpy as np
import pytest

from lerobot_bboxpick import geometry
from lerobot_bboxpick.rl.sign_flip import sign_agreement, sign_flip_table, tcp_flips

KINDS = ["policy", "x+0.030", "x-0.030", "yaw+0.350", "yaw-0.350"]


def pose10(rotation: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotation
    return np.concatenate([geometry.mat_to_pose9(T), [0.05]])


TOP_DOWN = np.diag([1.0, -1.0, -1.0])  # tool z down, tool x along world x
TOP_DOWN_TURNED = np.diag([-1.0, 1.0, -1.0])  # the same, turned 180 deg about the tool axis


def test_tcp_flips_read_the_tools_axes_in_the_world():
    poses = np.stack([pose10(np.eye(3)), pose10(TOP_DOWN), pose10(TOP_DOWN_TURNED)])
    assert tcp_flips(poses, "x").tolist() == [False, False, True]
    assert tcp_flips(poses, "y").tolist() == [False, True, False]
    assert tcp_flips(poses, "yaw").tolist() == [False, True, True]  # yaw about a downward tool axis
    with pytest.raises(ValueError, match="axis='roll'"):
        tcp_flips(poses, "roll")


def test_agreement_is_one_for_a_perfect_critic_zero_for_an_inverted_one_half_for_a_blind_one():
    rng = np.random.default_rng(0)
    returns = rng.choice([0.0, 0.9], size=(40, len(KINDS)))
    base = np.stack([pose10(TOP_DOWN if i % 4 else TOP_DOWN_TURNED) for i in range(40)])  # x flips on 1/4
    differ = int((returns[:, 1] != returns[:, 2]).sum())
    assert 5 < differ < 35  # the draw has informative points and uninformative ones
    perfect = sign_agreement(returns, returns, KINDS, base)
    assert perfect["x"]["points"] == differ
    assert perfect["x"]["agree"] == 1.0
    assert perfect["x"]["tcp_flip"] == 0.25
    rows = returns[:, 1] != returns[:, 2]
    assert perfect["x"]["agree_if_tcp_frame"] == pytest.approx(1 - (np.arange(40)[rows] % 4 == 0).mean())
    assert perfect["yaw"]["tcp_flip"] == 1.0 and perfect["yaw"]["agree_if_tcp_frame"] == 0.0
    assert sign_agreement(-returns, returns, KINDS, base)["x"]["agree"] == 0.0
    blind = sign_agreement(np.ones_like(returns), returns, KINDS, base)
    assert blind["x"]["agree"] == 0.5 and blind["x"]["agree_if_tcp_frame"] == 0.5
    table = sign_flip_table([("MC", perfect), ("blind", blind)])
    assert f"| x | {differ} |" in table and "100%" in table and "50%" in table


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="must both be"):
        sign_agreement(np.zeros((3, 5)), np.zeros((3, 4)), KINDS, np.zeros((3, 10)))
