"""``bboxpick-compare``: paired gains and losses, the sign test and the table, on suites written here."""

import json
import subprocess
import sys

import pytest
from helpers_cli import cli_env

from lerobot_bboxpick.eval.paired import (
    comparison_table,
    load_outcomes,
    paired_counts,
    parse_runs,
    sign_test_p,
)
from lerobot_bboxpick.eval.target_yaw import target_yaw_off_axis, yaw_bin


def _suite(folder, outcomes: dict) -> str:
    """A suite folder whose episodes.jsonl holds ``{(setting, seed): outcome}``."""
    folder.mkdir(parents=True)
    lines = [json.dumps({"setting": s, "seed": seed, "outcome": o}) for (s, seed), o in outcomes.items()]
    (folder / "episodes.jsonl").write_text("\n".join(lines) + "\n")
    return str(folder)


def test_sign_test_matches_the_binomial_tail():
    assert sign_test_p(0, 0) == 1.0
    assert sign_test_p(5, 5) == pytest.approx(1.0)
    assert sign_test_p(0, 6) == pytest.approx(2 / 64)  # two-sided: 2 * 0.5**6
    assert sign_test_p(11, 30) == pytest.approx(0.0043, abs=5e-5)


def test_counts_are_paired_by_scene_and_the_table_reads_them(tmp_path):
    base = {("grid_id", 1): "pick", ("grid_id", 2): "pick", ("grid_id", 3): "empty", ("pile_id", 1): "wrong"}
    other = {("grid_id", 1): "empty", ("grid_id", 2): "pick", ("grid_id", 3): "pick", ("pile_id", 1): "pick"}
    runs = parse_runs(f"IL={_suite(tmp_path / 'a', base)};X (T = 1)={_suite(tmp_path / 'b', other)}")
    assert list(runs) == ["IL", "X (T = 1)"]
    outcomes = {name: load_outcomes(folders) for name, folders in runs.items()}
    assert paired_counts(outcomes["X (T = 1)"], outcomes["IL"]) == (2, 1)
    assert paired_counts(outcomes["X (T = 1)"], outcomes["IL"], "grid_id") == (1, 1)
    table = comparison_table(outcomes).splitlines()
    assert table[0] == "| policy | grid_id | pile_id | all settings |"
    assert table[2].startswith("| IL | 67% [21-94] (0%) | 0% [0-79] (100%) | 50% [15-85] (25%) |")
    assert table[3].endswith(
        "| 67% [21-94] (0%) +1/-1 | 100% [21-100] (0%) +1/-0 | 75% [30-95] (0%) +2/-1, p = 1 |"
    )


def test_a_scene_twice_and_a_missing_folder_are_errors(tmp_path):
    a = _suite(tmp_path / "a", {("grid_id", 1): "pick"})
    with pytest.raises(ValueError, match=r"scene \('grid_id', 1\) appears twice"):
        load_outcomes([a, a])
    result = subprocess.run(
        [sys.executable, "-m", "lerobot_bboxpick.eval.paired", f"--runs=IL={tmp_path / 'none'}"],
        capture_output=True, text=True, env=cli_env(),
    )  # fmt: skip
    assert result.returncode != 0 and "has no episodes.jsonl" in result.stderr
    with pytest.raises(ValueError, match="is not NAME=dir"):
        parse_runs("IL")


def test_target_yaw_is_the_scene_s_own():
    """Grid targets are turned at most 10 degrees (the layout's jitter), random ones spread over 0-45,
    and the value is the turn the simulator's settled brick actually has."""
    import numpy as np

    from lerobot_bboxpick.sim.env import LegoPickEnv

    grid = [target_yaw_off_axis("grid_id", seed) for seed in range(20)]
    assert max(grid) <= 10.0
    turned = [target_yaw_off_axis("random_id", seed) for seed in range(60)]
    assert min(turned) >= 0.0 and max(turned) <= 45.0
    assert all(sum(yaw_bin(y) == b for y in turned) >= 10 for b in range(3))  # uniform over 0-45: ~20 each
    env = LegoPickEnv(setting="random_id", episode_length=10)
    try:
        for seed in (3, 4):
            env.reset(seed=seed)
            R = env.brick_pose(env.target)[:3, :3]
            settled = float(np.degrees(np.arctan2(R[1, 0], R[0, 0]))) % 90.0
            assert min(settled, 90 - settled) == pytest.approx(
                target_yaw_off_axis("random_id", seed), abs=1.0
            )
    finally:
        env.close()


def test_compare_by_target_yaw_splits_each_setting_by_the_target_s_turn(tmp_path):
    """A policy that picks only targets turned under 15 degrees: the CLI's table shows every pick in the
    first bin and every turned target as an empty miss; @label keeps one policy of a two-policy suite."""
    seeds = range(30)
    aligned = {s for s in seeds if target_yaw_off_axis("random_id", s) < 15.0}
    folder = tmp_path / "suite"
    folder.mkdir()
    lines = [
        json.dumps({"policy": p, "setting": "random_id", "seed": s, "outcome": o})
        for s in seeds
        for p, o in (("expert", "pick"), ("il", "pick" if s in aligned else "empty"))
    ]
    (folder / "episodes.jsonl").write_text("\n".join(lines) + "\n")
    out = tmp_path / "yaw.md"
    result = subprocess.run(
        [sys.executable, "-m", "lerobot_bboxpick.eval.paired", f"--runs=IL={folder}@il", "--by=target_yaw",
         f"--out={out}"],
        capture_output=True, text=True, env=cli_env(),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    row = out.read_text().splitlines()[2].split(" | ")
    n_turned = len(seeds) - len(aligned)
    assert row[:3] == ["| IL", "random_id", f"{len(aligned)}/{len(aligned)} " + row[2].split(" ", 1)[1]]
    assert [cell.split(" ")[0] for cell in row[3:5]] == [
        f"0/{sum(yaw_bin(target_yaw_off_axis('random_id', s)) == b for s in seeds)}" for b in (1, 2)
    ]
    assert row[5] == f"{n_turned} / 0 |"
    with pytest.raises(ValueError, match="policy 'dp'; policies: \\['expert', 'il'\\]"):
        load_outcomes([f"{folder}@dp"])
    with pytest.raises(ValueError, match="appears twice"):
        load_outcomes([folder])  # two policies on the same scenes need a label
    bad = subprocess.run(
        [sys.executable, "-m", "lerobot_bboxpick.eval.paired", f"--runs=IL={folder}@il", "--by=yaw"],
        capture_output=True, text=True, env=cli_env(),
    )  # fmt: skip
    assert bad.returncode != 0 and "by='yaw': allowed values are setting, target_yaw" in bad.stderr
