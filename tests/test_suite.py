"""bboxpick-suite: the expert scores as an upper bound, reports are consistent, scenes are matched."""

import csv
import subprocess
import sys
from pathlib import Path

import pytest

from lerobot_bboxpick import seeds
from lerobot_bboxpick.eval.suite import (
    SuiteConfig,
    markdown_table,
    read_episodes,
    run_suite,
    summarize,
    wilson_interval,
)
from lerobot_bboxpick.sim.layouts import SETTINGS
from lerobot_bboxpick.sim.outcome import OUTCOMES


def _random_checkpoint(path: Path) -> Path:
    """A tiny randomly initialised bbox_diffusion checkpoint, saved as lerobot-train saves one."""
    from lerobot_bboxpick.apps.bench import save_random_checkpoint

    return save_random_checkpoint(
        path,
        backbone="resnet10t",
        pooling="default",
        group_norm=False,
        image_size=64,
        down_dims=(32, 64),
        diffusion_step_embed_dim=32,
        num_inference_steps=4,
    )


def test_wilson_interval_matches_known_values() -> None:
    # Reference values of the Wilson score interval (z = 1.96).
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson_interval(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson_interval(30, 30) == pytest.approx((0.8865, 1.0), abs=1e-4)


@pytest.mark.slow
def test_expert_suite_picks_writes_consistent_reports_and_resumes(tmp_path: Path) -> None:
    out = tmp_path / "suite"
    cfg = SuiteConfig(policies="expert", episodes=2, workers=2, videos=1, out_dir=out)
    table = run_suite(cfg)
    records = read_episodes(out / "episodes.jsonl")
    assert len(records) == 2 * len(SETTINGS)
    picks = sum(r["outcome"] == "pick" for r in records)
    assert picks / len(records) >= 0.95, records
    assert {r["seed"] for r in records} == {10000, 10001}
    for r in records:
        fields = {"policy", "setting", "seed", "scene", "target", "outcome", "steps", "final_distance_m"}
        assert set(r) >= fields
        if r["outcome"] == "pick":  # lifted in the fingers: the TCP is at the brick
            assert r["final_distance_m"] < 0.05

    # CSV: one row per setting, counts summing to the episodes, rates equal to counts / n.
    with open(out / "table.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["setting"] for r in rows] == list(SETTINGS)
    for row in rows:
        counts = [int(row[o]) for o in OUTCOMES]
        assert sum(counts) == int(row["episodes"]) == 2
        assert float(row["pick_rate"]) == pytest.approx(int(row["pick"]) / 2)
        assert float(row["pick_ci_low"]) <= float(row["pick_rate"]) <= float(row["pick_ci_high"])
    text = table.read_text()
    assert text.count("| expert |") == len(SETTINGS) and "Wilson" in text
    assert (out / "outcomes.png").stat().st_size > 10_000
    assert len(list((out / "videos" / "expert").glob("*.mp4"))) == len(SETTINGS)
    # The outcome sheet: one 118 px framed thumbnail per episode (8 per row), green frames for picks.
    import cv2

    sheet = cv2.imread(str(out / "outcomes_expert.png"))[..., ::-1]
    assert sheet.shape == (2 * 118, 8 * 118, 3)
    for i, r in enumerate(sorted(records, key=lambda r: (r["setting"], r["seed"]))):
        row, col = divmod(i, 8)
        corner = sheet[row * 118 + 1, col * 118 + 1]
        assert (corner[1] > 150 and corner[0] < 100) == (r["outcome"] == "pick"), (i, r["outcome"], corner)

    # Re-running the same suite reproduces it: a third episode per setting is added, the first two kept.
    (out / "episodes.jsonl").write_text((out / "episodes.jsonl").read_text() + '{"torn": ')
    rerun = SuiteConfig(policies="expert", settings="grid_id", episodes=3, workers=1, videos=0, out_dir=out)
    run_suite(rerun)
    everything = read_episodes(out / "episodes.jsonl")
    assert len(everything) == len(records) + 1  # the other settings' episodes stay in the file
    again = [r for r in everything if r["setting"] == "grid_id"]
    assert sorted(r["seed"] for r in again) == [10000, 10001, 10002]
    kept = {(r["seed"], r["outcome"], r["steps"], r["scene"]) for r in again if r["seed"] < 10002}
    first = {(r["seed"], r["outcome"], r["steps"], r["scene"]) for r in records if r["setting"] == "grid_id"}
    assert kept == first


@pytest.mark.slow
def test_expert_is_deterministic_and_policies_meet_the_same_scenes(tmp_path: Path) -> None:
    ckpt = _random_checkpoint(tmp_path / "ckpt" / "pretrained_model")
    cfg = SuiteConfig(
        policies=f"expert,random={ckpt}",
        settings="identical_4,pile_id",
        episodes=2,
        workers=2,
        videos=0,
        max_steps=120,
        out_dir=tmp_path / "a",
    )
    run_suite(cfg)
    a = read_episodes(tmp_path / "a" / "episodes.jsonl")
    scenes = {}
    for r in a:
        scenes.setdefault((r["setting"], r["seed"]), set()).add((r["scene"], r["target"]))
    assert len(scenes) == 4 and all(len(v) == 1 for v in scenes.values())  # same scene for both policies
    assert len({next(iter(v))[0] for v in scenes.values()}) == 4  # and different scenes across seeds
    # The random policy does not pick; its rows exist with all episodes accounted for.
    rows = summarize(a, ["expert", "random"], ("identical_4", "pile_id"))
    assert [r["episodes"] for r in rows] == [2, 2, 2, 2]
    assert all(r["pick"] == 0 for r in rows if r["policy"] == "random")
    assert "| random | pile_id | 2 |" in markdown_table(rows)

    # Same suite in a fresh folder: same scenes, same expert outcomes and step counts.
    cfg_b = SuiteConfig(
        policies="expert",
        settings="identical_4,pile_id",
        episodes=2,
        workers=1,
        videos=0,
        max_steps=120,
        out_dir=tmp_path / "b",
    )
    run_suite(cfg_b)
    b = read_episodes(tmp_path / "b" / "episodes.jsonl")

    def key(records: list[dict]) -> set:
        return {
            (r["setting"], r["seed"], r["scene"], r["outcome"], r["steps"])
            for r in records
            if r["policy"] == "expert"
        }

    assert key(a) == key(b)


@pytest.mark.slow
def test_bad_options_name_the_field(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="settings"):
        SuiteConfig(settings="grid_idd", out_dir=tmp_path)
    with pytest.raises(ValueError, match="episodes"):
        SuiteConfig(episodes=0, out_dir=tmp_path)
    with pytest.raises(ValueError, match="num_inference_steps=0 must be an integer >= 1"):
        SuiteConfig(num_inference_steps=0, out_dir=tmp_path)
    with pytest.raises(ValueError, match="checkpoint folder"):
        SuiteConfig(policies=str(tmp_path / "missing"), out_dir=tmp_path)
    result = subprocess.run(
        [Path(sys.executable).parent / "bboxpick-suite", "--episodes=0", f"--out_dir={tmp_path}"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode != 0 and "episodes" in result.stderr
    assert not (tmp_path / "episodes.jsonl").exists()


def test_resume_is_refused_after_the_checkpoint_weights_change(tmp_path: Path) -> None:
    """Episodes are keyed on a digest of the weights and the behaviour options: a re-run after more
    training (or with another n_action_steps) never mixes into the old table."""
    import torch

    from lerobot_bboxpick.eval.suite import weights_digest

    torch.manual_seed(0)
    ckpt = _random_checkpoint(tmp_path / "ckpt")
    out = tmp_path / "suite"

    def cfg(**kw) -> SuiteConfig:
        options = dict(policies=f"p={ckpt}", settings="grid_id", episodes=1, workers=1, videos=0, max_steps=3)
        return SuiteConfig(out_dir=out, **{**options, **kw})

    run_suite(cfg())
    first = read_episodes(out / "episodes.jsonl")
    old_digest = weights_digest(str(ckpt))
    assert first[0]["run_key"]["weights"] == old_digest and first[0]["run_key"]["n_action_steps"] == 12
    run_suite(cfg())  # same weights, same options: resumes, nothing re-run
    assert read_episodes(out / "episodes.jsonl") == first

    torch.manual_seed(1)
    _random_checkpoint(ckpt)  # "more training": other weights under the same path and label
    new_digest = weights_digest(str(ckpt))
    assert new_digest != old_digest
    with pytest.raises(ValueError, match=f"run as .*{old_digest}.*this run is .*{new_digest}"):
        run_suite(cfg())
    assert read_episodes(out / "episodes.jsonl") == first  # the refused run changed nothing
    with pytest.raises(ValueError, match="n_action_steps"):
        run_suite(cfg(n_action_steps=8))
    with pytest.raises(ValueError, match="num_inference_steps"):
        run_suite(cfg(num_inference_steps=4))
    with pytest.raises(ValueError, match="policy_seed_offset"):
        run_suite(cfg(policy_seed_offset=7))

    run_suite(cfg(fresh=True))  # asked for: the old episodes move aside, the new run starts over
    now = read_episodes(out / "episodes.jsonl")
    assert len(now) == 1 and now[0]["run_key"]["weights"] == new_digest
    aside = list(out.glob("episodes.*.jsonl"))
    assert len(aside) == 1 and read_episodes(aside[0]) == first


def test_the_noisy_bbox_source_reaches_the_policy_at_its_iou(tmp_path: Path) -> None:
    cfg = SuiteConfig(
        policies="expert",
        settings="grid_id",
        episodes=2,
        workers=1,
        videos=0,
        max_steps=40,
        bbox_source="noisy",
        noisy_iou=0.6,
        out_dir=tmp_path,
    )
    table = run_suite(cfg)
    records = read_episodes(tmp_path / "episodes.jsonl")
    assert [r["bbox_source"] for r in records] == ["noisy", "noisy"]
    assert all(abs(r["bbox_mean_iou"] - 0.6) < 0.02 for r in records), records
    assert "bbox source: noisy (IoU 0.6" in table.read_text()


def test_policy_seed_offset_redraws_the_noise_and_onnx_inference_reaches_the_policy(tmp_path: Path) -> None:
    """``--policy_seed_offset``: the same scene and target, the policy's noise drawn from seed + offset;
    ``--onnx_inference``: kept in the run key and set on the loaded policy (its chunks equal the eager
    UNet's: tests/test_modeling_bbox_diffusion.py)."""
    from lerobot_bboxpick.eval.suite import load_runner

    ckpt = _random_checkpoint(tmp_path / "ckpt")
    records = {}
    for offset, onnx in ((0, False), (7, False), (0, True)):
        out = tmp_path / f"offset{offset}_onnx{onnx}"
        run_suite(
            SuiteConfig(
                policies=f"p={ckpt}", settings="grid_id", episodes=1, workers=1, videos=0, max_steps=5,
                policy_seed_offset=offset, onnx_inference=onnx, out_dir=out,
            )
        )  # fmt: skip
        (records[offset, onnx],) = read_episodes(out / "episodes.jsonl")
    seed = seeds.TEST_START
    assert [records[k]["policy_seed"] for k in ((0, False), (7, False), (0, True))] == [seed, seed + 7, seed]
    assert len({(r["scene"], r["target"]) for r in records.values()}) == 1
    assert [r["run_key"].get("policy_seed_offset") for r in records.values()] == [None, 7, None]
    assert [r["run_key"].get("onnx_inference") for r in records.values()] == [None, None, True]
    assert load_runner(str(ckpt), None, None, onnx_inference=True).policy.config.onnx_inference
    assert not load_runner(str(ckpt), None, None).policy.config.onnx_inference
    with pytest.raises(ValueError, match="policy_seed_offset=-1"):
        SuiteConfig(policy_seed_offset=-1, out_dir=tmp_path)
