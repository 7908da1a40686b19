"""The target-sensitivity check (issue 4) measures what the bbox does to the predicted chunk, no more."""

import pytest


@pytest.mark.parametrize(("mask_centroid", "moves"), [(False, False), (True, True)])
def test_shift_is_zero_when_the_bbox_cannot_matter(tmp_path, mask_centroid: bool, moves: bool) -> None:
    """At initialisation the mask channel's weights are zero, so moving the bbox between two identical
    bricks cannot move the chunk: the check must report exactly 0. With ``mask_centroid`` the box's
    position reaches the UNet even at initialisation, and the check must see the chunk move."""
    from lerobot_bboxpick.apps.bench import save_random_checkpoint
    from lerobot_bboxpick.apps.canary import target_sensitivity

    path = save_random_checkpoint(tmp_path / "ckpt", mask_centroid=mask_centroid, num_inference_steps=4)
    result = target_sensitivity(path, seed=10000, samples=2)
    first, second = result["bricks"]
    assert first != second
    on_first, on_second = result[f"bbox_on_{first}"], result[f"bbox_on_{second}"]
    moved = abs(result["shift_toward_new_box_m"])
    if moves:
        assert on_first["end_point"] != on_second["end_point"] and moved > 1e-5
    else:
        assert on_first["end_point"] == on_second["end_point"] and moved == 0.0
    # the distances are measured to the two bricks 7.5 cm apart in the grid row
    gap = abs(on_first[f"distance_to_{first}_m"] - on_first[f"distance_to_{second}_m"])
    assert gap <= 0.075 + 1e-6


@pytest.mark.slow
def test_canary_designates_two_neighbouring_bricks_of_one_scene(tmp_path) -> None:
    """The two-target canary's demos alternate between the seed's target and its grid neighbour, so the
    same first image needs two different chunks and only the bbox can tell the policy which one."""
    import numpy as np
    import pandas as pd

    from lerobot_bboxpick.apps.canary import canary_targets, record
    from lerobot_bboxpick.data.features import EPISODE_TARGET
    from lerobot_bboxpick.sim.layouts import make_layout, scene_rng

    first, second = canary_targets(0, 2)
    layout = make_layout("grid_id", scene_rng("grid_id", 0))
    assert first == layout.target and second != first
    gap = np.linalg.norm(layout.positions[first] - layout.positions[second])
    assert abs(gap - 0.075) < 0.01, f"neighbours {first}, {second} are {gap * 1000:.0f} mm apart"
    assert canary_targets(0, 1) == [first]
    with pytest.raises(ValueError, match="targets=3"):
        canary_targets(0, 3)

    root = record(tmp_path / "canary", seed=0, episodes=3, targets=2)
    frames = pd.concat(pd.read_parquet(p) for p in sorted((root / "data").rglob("*.parquet")))
    per_episode = frames.groupby("episode_index")[EPISODE_TARGET].first().tolist()
    assert per_episode == [first, second, first]
