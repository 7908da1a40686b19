"""The verification tool on critics with known answers: action-sensitive vs action-blind (test B) and a
value that orders outcomes right vs wrong (test A); and the report it writes."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from test_rl_critic_dataset import synthetic_table

from lerobot_bboxpick.geometry import absolute_pose10
from lerobot_bboxpick.rl.critic_dataset import CriticDataConfig, build_transitions
from lerobot_bboxpick.rl.diagnostics import evaluate, summarize
from lerobot_bboxpick.rl.verify import (
    VerifyConfig,
    action_sensitivity,
    shift_chunks,
    sweep_offsets,
    write_report,
)

STATE_STD = 0.35  # the paper's across-state std of Q


class SyntheticCritic:
    """Critics over a synthetic state feature ``[f(s), a*(s) positions (48)]``:
    ``sensitive``: Q = f(s) - ||positions(a) - positions(a*(s))||; otherwise Q = f(s); V = f(s)."""

    def __init__(self, sensitive: bool) -> None:
        self.sensitive = sensitive

    def v(self, state: torch.Tensor) -> torch.Tensor:
        return state[:, 0]

    def q(self, state: torch.Tensor, chunk: torch.Tensor) -> torch.Tensor:
        if not self.sensitive:
            return state[:, 0]
        return state[:, 0] - (chunk[..., :3].flatten(1) - state[:, 1:]).norm(dim=1)


def features(tr, n_frames: int, seed: int = 0) -> torch.Tensor:
    """Per-frame features: f(s) with std STATE_STD, and the dataset chunk's positions as a*(s)."""
    rng = np.random.default_rng(seed)
    emb = np.zeros((n_frames, 1 + 48))
    emb[:, 0] = rng.normal(0, STATE_STD, n_frames)
    emb[tr.obs_row, 1:] = tr.actions[..., :3].reshape(len(tr), -1)
    return torch.from_numpy(emb).float()


@pytest.fixture(scope="module")
def data():
    table = synthetic_table(["pick", "pick", "empty", "wrong"], length=60, success_at=50)
    tr = build_transitions(table, CriticDataConfig(val_fraction=0.0, near_terminal_steps=10), 16, 12, 0.99)
    return tr, features(tr, table.num_frames)


def test_world_frame_shift_moves_every_absolute_position_by_the_offset(data):
    tr, _ = data
    d = np.array([0.0, 0.08, 0.0])
    shifted = shift_chunks(tr.actions[:5], tr.base_pose[:5], d, "world")
    before = absolute_pose10(tr.actions[:5].astype(np.float64), tr.base_pose[:5, None])
    after = absolute_pose10(shifted, tr.base_pose[:5, None])
    np.testing.assert_allclose(after[..., :3] - before[..., :3], np.broadcast_to(d, (5, 16, 3)), atol=1e-6)
    np.testing.assert_allclose(after[..., 3:], before[..., 3:], atol=1e-6)  # rotation, width untouched
    # in the TCP frame the relative positions move by the offset instead (a different world direction)
    tcp = shift_chunks(tr.actions[:5], tr.base_pose[:5], d, "tcp")
    np.testing.assert_allclose(
        tcp[..., :3] - tr.actions[:5, :, :3], np.broadcast_to(d, (5, 16, 3)), atol=1e-6
    )
    assert np.abs(absolute_pose10(tcp, tr.base_pose[:5, None])[..., :3] - after[..., :3]).max() > 0.01


def test_action_sensitive_critic_has_a_high_ratio_and_wins_the_argmax(data):
    tr, emb = data
    b = action_sensitivity(SyntheticCritic(sensitive=True), emb, tr, sweep_offsets(0.08, 9))
    std = float(emb[tr.obs_row, 0].numpy().std())
    # Shifting 16 positions by 8 cm changes ||a - a*|| by 0.08 * sqrt(16) = 0.32 (a rotation keeps norms)
    for axis in ("x", "y", "z"):
        assert b["axes"][axis]["q_change"] == pytest.approx(0.32, abs=1e-4)
        assert b["axes"][axis]["ratio"] == pytest.approx(0.32 / std, rel=1e-3)
        assert b["axes"][axis]["ratio"] > 0.8
        assert b["axes"][axis]["slope"] == pytest.approx(0.0, abs=1e-4)  # symmetric bowl
    assert b["state_std"] == pytest.approx(std, rel=1e-5)
    assert b["n_pregrasp"] == 2 * 29 and b["argmax_match"] == 1.0


def test_action_blind_critic_has_ratio_zero_and_never_wins_the_argmax(data):
    tr, emb = data
    b = action_sensitivity(SyntheticCritic(sensitive=False), emb, tr, sweep_offsets(0.08, 9))
    for axis in ("x", "y", "z"):
        assert b["axes"][axis]["q_change"] == 0.0 and b["axes"][axis]["ratio"] == 0.0
    assert b["argmax_match"] == 0.0  # all candidates tie: the dataset chunk is not *the* argmax


def test_value_ordering_scores_one_for_outcome_aware_v_and_zero_reversed(data):
    tr, _ = data
    n = tr.obs_row.max() + 1
    # V = the group's reward-to-go shape: success rises to +1, miss 0, wrong falls to -1
    sign = np.array([1.0, 0.0, -1.0])[tr.group]
    good = np.zeros(n)
    good[tr.obs_row] = sign * (0.5 + 0.5 * tr.progress)
    for v, score in ((good, 1.0), (-good, 0.0)):
        emb = torch.from_numpy(v[:, None]).float()
        critic = type("C", (), {"v": lambda self, s: s[:, 0], "q": lambda self, s, a: s[:, 0]})()
        a = summarize(evaluate(critic, emb, tr), tr)
        assert len(a["checks"]) == 12 and a["ordering_score"] == score
    a = summarize(evaluate(critic, torch.from_numpy(good[:, None]).float(), tr), tr)
    assert a["margins"]["success-wrong"]["all"] > 1.0
    assert a["ramp_v"]["success"]["spearman"] == pytest.approx(1.0)
    assert a["ramp_v"]["wrong"]["spearman"] == pytest.approx(-1.0)


def test_report_puts_our_numbers_beside_the_papers(data, tmp_path):
    tr, emb = data
    critic = SyntheticCritic(sensitive=False)
    a = summarize(evaluate(critic, emb, tr), tr)
    b = action_sensitivity(critic, emb, tr, sweep_offsets(0.08, 5))
    cfg = VerifyConfig(critic_path=tmp_path, out_dir=tmp_path / "report")
    md = write_report(a, b, cfg, "synthetic").read_text()
    assert "| action/state sensitivity ratio | 0.000 | 0.000 | 0.000 | 0.026 / 0.050 / 0.078 |" in md
    assert "| verdict | too flat | too flat | too flat |" in md
    for png in ("value_by_outcome_phase.png", "ramp.png", "sweeps.png"):
        assert (tmp_path / "report" / png).stat().st_size > 5000
    with pytest.raises(ValueError, match="frame='body' is not one of world, tcp"):
        VerifyConfig(frame="body")
    with pytest.raises(ValueError, match="sweep_points"):
        VerifyConfig(sweep_points=4)
