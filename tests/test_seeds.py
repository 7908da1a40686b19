"""One module owns the seed ranges; collection refuses evaluation seeds, the suite warns on training ones."""

import logging

import pytest

from lerobot_bboxpick import seeds
from lerobot_bboxpick.data.collect import CollectConfig


def test_the_ranges_are_disjoint_and_cover_every_seed():
    assert [seeds.split_of(s) for s in (0, 4999, 5000, 9999, 10000, 10**7)] == [
        "train",
        "train",
        "validation",
        "validation",
        "test",
        "test",
    ]
    with pytest.raises(ValueError, match="seed=-1"):
        seeds.split_of(-1)


def test_collection_refuses_a_test_seed_unless_it_makes_an_evaluation_dataset(tmp_path):
    with pytest.raises(ValueError, match="seed_start.*10000-10009 are not all train"):
        CollectConfig(root=tmp_path / "a", seed_start=10000, episodes=10)
    with pytest.raises(ValueError, match="5000-5009 are not all train"):
        CollectConfig(root=tmp_path / "a", seed_start=5000, episodes=10)
    # Demonstrations that would spill over into the validation range are refused up front too.
    with pytest.raises(ValueError, match="4995-5004"):
        CollectConfig(root=tmp_path / "a", seed_start=4995, episodes=10)
    assert CollectConfig(root=tmp_path / "a", split="test", episodes=10).seed_start == 10000
    assert (
        CollectConfig(root=tmp_path / "a", split="validation", seed_start=5100, episodes=10).seed_start
        == 5100
    )
    with pytest.raises(ValueError, match="split='holdout'.*train, validation, test"):
        CollectConfig(root=tmp_path / "a", split="holdout")


def test_the_suite_warns_when_it_reports_on_training_seeds(caplog):
    with caplog.at_level(logging.WARNING):
        assert seeds.warn_unless_held_out(0, 29) is True
    assert "overlap the train (0-4999) seeds" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        assert seeds.warn_unless_held_out(5000, 5029) is False
        assert seeds.warn_unless_held_out(10000, 10029) is False
    assert caplog.text == ""
