"""The target-sensitivity check (issue 4) measures what the bbox does to the predicted chunk, no more."""

import pytest


@pytest.mark.parametrize(("mask_centroid", "moves"), [(False, False), (True, True)])
def test_shift_is_zero_when_the_bbox_cannot_matter(tmp_path, mask_centroid: bool, moves: bool) -> None:
    """At initialisation the mask channel's weights are zero, so moving the bbox between two identical
    bricks cannot move the chunk: the check must report exactly 0. With ``mask_centroid`` the box's
    position reaches the UNet even at initialisation, and the check must see the chunk move."""
    from lerobot_bboxpick.bench import save_random_checkpoint
    from lerobot_bboxpick.canary import target_sensitivity

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
