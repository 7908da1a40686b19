"""The suite's bbox sources: oracle, a person's noisy box at a requested IoU, the tracker's box."""

import numpy as np
import pytest

from lerobot_bboxpick.data.tracking import bbox_iou
from lerobot_bboxpick.eval.bbox_source import BboxSource, check_bbox_source, noise_for_iou, perturb_box


def _random_box(rng):
    c = rng.uniform(0.2, 0.8, size=2)
    half = rng.uniform(0.02, 0.08, size=2)
    return np.concatenate([c - half, c + half]).astype(np.float32)


@pytest.mark.parametrize("iou", [0.5, 0.7, 0.9])
def test_noisy_box_hits_the_requested_iou_on_average(iou):
    rng = np.random.default_rng(0)
    got = []
    for _ in range(200):
        box = _random_box(rng)
        offset, log_scale = noise_for_iou(box, iou, rng)
        got.append(float(bbox_iou(perturb_box(box, offset, log_scale), box)))
    assert abs(np.mean(got) - iou) < 0.01 and np.std(got) < 0.02


def test_noisy_source_keeps_its_error_relative_to_the_moving_box_and_is_seeded():
    box = np.array([0.40, 0.40, 0.48, 0.46], np.float32)
    moved = box + np.float32(0.1)
    obs = {"bbox": box, "pixels": {"wrist": np.zeros((8, 8, 3), np.uint8)}}
    a, b = BboxSource("noisy", noisy_iou=0.6), BboxSource("noisy", noisy_iou=0.6)
    first = a.reset(obs, seed=10003)["bbox"]
    assert np.array_equal(first, b.reset(obs, seed=10003)["bbox"])  # same seed, same error
    assert not np.array_equal(first, BboxSource("noisy", noisy_iou=0.6).reset(obs, seed=10004)["bbox"])
    later = a({**obs, "bbox": moved})["bbox"]
    assert abs(bbox_iou(first, box) - 0.6) < 1e-3 and abs(bbox_iou(later, moved) - 0.6) < 1e-3
    assert np.allclose(later - first, 0.1, atol=1e-5)  # the same offset, carried with the box
    assert a.mean_iou == pytest.approx(0.6, abs=1e-3)
    # A target out of view gives the env's "none" box, never a made-up one.
    assert not a({**obs, "bbox": np.zeros(4, np.float32)})["bbox"].any()


def test_tracked_source_follows_the_target_through_an_expert_episode():
    """Closed loop in MuJoCo: the tracker starts from the first oracle box and stays on the target."""
    from lerobot_bboxpick.sim.env import LegoPickEnv
    from lerobot_bboxpick.sim.expert import ScriptedExpert

    env = LegoPickEnv(setting="grid_id", terminate_on_lift=False)
    obs, _ = env.reset(seed=10001)
    source = BboxSource("tracked")
    given = source.reset(obs, seed=10001)
    assert np.array_equal(given["bbox"], obs["bbox"])  # the first frame is the oracle box
    expert = ScriptedExpert(np.random.default_rng(10001))
    expert.reset(env)
    for _ in range(60):  # approach and descent: the brick grows in the image
        obs, *_ = env.step(expert.act())
        source(obs)
    env.close()
    assert source.mean_iou > 0.6, source.ious


def test_unknown_source_is_refused_with_the_valid_ones():
    with pytest.raises(ValueError, match="bbox_source='human'.*oracle, noisy, tracked"):
        check_bbox_source("human")
    with pytest.raises(ValueError, match="noisy_iou"):
        BboxSource("noisy", noisy_iou=1.5)
