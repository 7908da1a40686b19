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
