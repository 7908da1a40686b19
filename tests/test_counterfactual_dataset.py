"""Counterfactual datasets: perturbations move a chunk by exactly what they say, branch labels are true
returns, and the same options give the same dataset (the shipped checkpoint proposes and finishes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lerobot_bboxpick import geometry
from lerobot_bboxpick.rl.branch_demos import success_branches
from lerobot_bboxpick.rl.chunk_perturbations import Perturbation, cosine_ramp, parse_perturbations
from lerobot_bboxpick.rl.counterfactual_dataset import (
    CounterfactualConfig,
    load_points,
    mc_return,
    run_counterfactual,
)
from lerobot_bboxpick.rl.critic_dataset import CriticDataConfig
from lerobot_bboxpick.sim.outcome import OUTCOMES

SHIPPED = Path(__file__).resolve().parents[1] / "examples" / "bbox_diffusion_lego_pick"


def _chunk(h: int = 16) -> np.ndarray:
    R = geometry.rot6d_to_mat(np.array([1.0, 0, 0, 0, -1, 0]))  # tool pointing down
    T = np.tile(np.eye(4), (h, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = np.linspace([0.4, 0.0, 0.2], [0.45, 0.02, 0.1], h)
    return np.concatenate([geometry.mat_to_pose9(T), np.full((h, 1), 0.07)], axis=1)


def test_ramp_starts_near_zero_and_ends_at_the_amount():
    r = cosine_ramp(16)
    assert r[0] < 0.01 and r[-1] == pytest.approx(1.0) and np.all(np.diff(r) > 0)


@pytest.mark.parametrize("axis,index", [("x", 0), ("y", 1), ("z", 2)])
def test_position_perturbation_moves_the_chunk_end_by_the_amount(axis, index):
    chunk = _chunk()
    out = Perturbation(axis, -0.03).apply(chunk)
    delta = out[:, :3] - chunk[:, :3]
    assert delta[-1, index] == pytest.approx(-0.03)
    assert abs(delta[0, index]) < 0.0003  # no jump at the chunk's start
    assert np.abs(np.delete(delta, index, axis=1)).max() == 0.0
    assert np.array_equal(out[:, 3:], chunk[:, 3:])


def test_yaw_perturbation_turns_about_world_z_and_keeps_positions():
    chunk = _chunk()
    out = Perturbation("yaw", 0.35).apply(chunk)
    assert np.array_equal(out[:, :3], chunk[:, :3])
    R0, R1 = geometry.rot6d_to_mat(chunk[-1, 3:9]), geometry.rot6d_to_mat(out[-1, 3:9])
    rel = R1 @ R0.T
    assert np.arctan2(rel[1, 0], rel[0, 0]) == pytest.approx(0.35, abs=1e-9)
    assert rel[2, 2] == pytest.approx(1.0)


def test_gripper_perturbation_never_goes_below_zero():
    out = Perturbation("gripper", -0.2).apply(_chunk())
    assert out[:, 9].min() == 0.0


@pytest.mark.parametrize("spec", ["x", "q:0.1", "x:-0.02", "y:abc"])
def test_bad_perturbation_specs_name_the_field_and_the_axes(spec):
    with pytest.raises(ValueError, match=r"perturbations: .*x, y, z, yaw, gripper"):
        parse_perturbations(spec)


def test_parse_gives_plus_and_minus():
    names = [p.name for p in parse_perturbations("x:0.03,yaw:0.35")]
    assert names == ["x+0.030", "x-0.030", "yaw+0.350", "yaw-0.350"]


def test_returns_are_discounted_terminal_rewards():
    rewards = CriticDataConfig()
    assert mc_return("pick", 1, 0.99, rewards) == 1.0
    assert mc_return("pick", 11, 0.99, rewards) == pytest.approx(0.99**10)
    assert mc_return("wrong", 3, 0.99, rewards) == pytest.approx(-(0.99**2))
    assert mc_return("empty", 300, 0.99, rewards) == 0.0


def test_seeds_outside_training_are_refused(tmp_path):
    with pytest.raises(ValueError, match="seed_start: seeds 5000-5001 are not all train"):
        CounterfactualConfig(policy_path=SHIPPED, seed_start=5000, episodes=2, out_dir=tmp_path)


def small_config(out_dir: Path, **overrides) -> CounterfactualConfig:
    """A counterfactual run small enough for a test: one grid_id episode of the shipped checkpoint."""
    options = {
        "policy_path": SHIPPED,
        "settings": "grid_id",
        "episodes": 1,
        "seed_start": 7,
        "branch_every": 2,
        "max_points": 2,
        "samples": 1,
        "perturbations": "z:0.05",
        "max_steps": 180,
        "workers": 1,
        "out_dir": out_dir,
    }
    return CounterfactualConfig(**{**options, **overrides})


def _run(out_dir: Path, **overrides) -> CounterfactualConfig:
    cfg = small_config(out_dir, **overrides)
    run_counterfactual(cfg)
    return cfg


@pytest.mark.slow
def test_same_options_same_dataset_and_true_labels(tmp_path):
    cfg = _run(tmp_path / "a")
    # b also records its picking branches as episodes: that must not change a single branch.
    a, b = load_points(tmp_path / "a"), load_points(_run(tmp_path / "b", success_demos=True).out_dir)
    assert a.kinds == ["policy", "sample1", "z+0.050", "z-0.050", "expert"] == cfg.candidate_kinds
    assert len(a) == 2 and a.step.tolist() == [0, 24]  # chunk boundaries 0 and 2 (12 steps each)
    for name in ("image", "state", "bbox", "candidates", "outcome", "steps", "ret"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    # Labels are the returns of the outcomes they record.
    for p in range(len(a)):
        for c in range(len(a.kinds)):
            expected = mc_return(OUTCOMES[a.outcome[p, c]], int(a.steps[p, c]), cfg.gamma, cfg.rewards)
            assert a.ret[p, c] == pytest.approx(expected)
    # The perturbed candidates are the policy's chunk, moved.
    end = a.candidates[:, :, -1, 2]
    assert np.allclose(end[:, 2] - end[:, 0], 0.05, atol=1e-6) and np.allclose(
        end[:, 3] - end[:, 0], -0.05, atol=1e-6
    )
    # The shipped checkpoint picks grid scenes: from the episode's start some candidate succeeds.
    assert (a.outcome[0] == OUTCOMES.index("pick")).any()
    assert "| expert |" in (tmp_path / "a" / "summary.md").read_text()
    _check_success_demos(b, tmp_path / "b" / "success_demos", n_exec=12)
    _check_branch_advantages(b, tmp_path / "b", tmp_path / "advantages.json")


@pytest.mark.slow
def test_first_branch_chunk_moves_the_branch_points_past_the_approach(tmp_path):
    """Branching from chunk 3 every chunk: the points sit at env steps 36 and 48 (12-step chunks), and
    the state and chunk at step 36 are those of a run that branched at 0 and 36 (the same seeds)."""
    options = {"max_points": 2, "samples": 0, "expert": False, "max_steps": 120}
    early = load_points(_run(tmp_path / "early", branch_every=3, **options).out_dir)
    late = load_points(_run(tmp_path / "late", branch_every=1, first_branch_chunk=3, **options).out_dir)
    assert early.step.tolist() == [0, 36] and late.step.tolist() == [36, 48]
    # chunk 3's state and policy chunk do not depend on whether chunk 0 was branched
    assert np.allclose(late.state[0], early.state[1], atol=1e-9)
    assert np.allclose(late.candidates[0, 0], early.candidates[1, 0], atol=1e-9)
    with pytest.raises(ValueError, match="first_branch_chunk=-1 must be an integer >= 0"):
        small_config(tmp_path / "bad", first_branch_chunk=-1)


def _check_branch_advantages(points, out_dir: Path, path: Path) -> None:
    """bboxpick-branch-advantages on the real success demos: each episode's advantage is its branch's
    return minus the mean return of the policy's own draws (policy, sample1) at its point."""
    from lerobot_bboxpick.rl.branch_advantages import (
        BranchAdvantagesConfig,
        load_advantages,
        write_advantages,
    )

    write_advantages(
        BranchAdvantagesConfig(data_dir=out_dir, dataset_root=out_dir / "success_demos", out=path)
    )
    got = load_advantages(path)
    picks = success_branches(points)
    expected = [points.ret[p, c] - points.ret[p, :2].mean() for p, c in picks]
    assert got == pytest.approx(expected, abs=1e-5)


def _check_success_demos(points, root: Path, n_exec: int) -> None:
    """Every picking branch, and only those, is an episode that starts at its branch point's observation,
    executes its candidate's chunk first and ends with the pick."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    picks = [(p, c) for p in range(len(points)) for c in range(len(points.kinds))]
    picks = [(p, c) for p, c in picks if points.outcome[p, c] == OUTCOMES.index("pick")]
    assert success_branches(points) == picks
    assert picks, "no branch picked: nothing to check"
    demos = LeRobotDataset("local/counterfactual_successes", root=root)
    assert demos.meta.total_episodes == len(picks)
    ends = np.cumsum(points.steps[tuple(zip(*picks, strict=True))])
    assert demos.meta.total_frames == ends[-1]  # each episode is its branch's steps long
    for e, (p, c) in enumerate(picks):
        start = int(ends[e - 1]) if e else 0
        first = demos.hf_dataset[start]
        assert np.allclose(first["observation.state"].numpy(), points.state[p, -1], atol=1e-6)
        actions = np.stack([demos.hf_dataset[start + t]["action"].numpy() for t in range(n_exec)])
        assert np.allclose(actions, points.candidates[p, c, :n_exec], atol=1e-6)
        last = demos.hf_dataset[int(ends[e]) - 1]
        assert bool(last["next.success"]) and bool(last["next.done"])
        assert int(last["episode_index"]) == e
