"""The seed ranges of the project, owned here and nowhere else.

An episode seed draws a whole scene (layout, target, start pose, appearance), so disjoint seed
ranges are disjoint scene sets:

* ``train``: 0-4999, expert demonstrations and anything a policy learns from;
* ``validation``: 5000-9999, every choice of recipe or hyper-parameter;
* ``test``: 10000 and up, the numbers a table reports (the paper's held-out seeds >= 10000).
"""

from __future__ import annotations

import logging

SPLITS: dict[str, tuple[int, int | None]] = {
    "train": (0, 5000),
    "validation": (5000, 10000),
    "test": (10000, None),  # open-ended
}
TRAIN_START, VALIDATION_START, TEST_START = (SPLITS[s][0] for s in ("train", "validation", "test"))
log = logging.getLogger(__name__)


def check_split(split: str) -> str:
    """Return ``split`` or raise a ValueError naming the valid ones."""
    if split not in SPLITS:
        raise ValueError(f"split={split!r} is not a seed split; valid splits: {', '.join(SPLITS)}")
    return split


def split_of(seed: int) -> str:
    """The split a seed belongs to."""
    if seed < 0:
        raise ValueError(f"seed={seed} must be >= 0")
    for name, (low, high) in SPLITS.items():
        if seed >= low and (high is None or seed < high):
            return name
    raise AssertionError("unreachable: the splits cover every seed >= 0")


def describe(split: str) -> str:
    """``'validation (5000-9999)'`` and the like, for messages."""
    low, high = SPLITS[check_split(split)]
    return f"{split} ({low}-{high - 1})" if high is not None else f"{split} ({low} and up)"


def check_seeds_in_split(first: int, last: int, split: str, field: str = "seed_start") -> None:
    """Raise a ValueError (naming ``field``) unless seeds ``first..last`` all lie in ``split``."""
    low, high = SPLITS[check_split(split)]
    if first < low or (high is not None and last >= high):
        raise ValueError(
            f"{field}: seeds {first}-{last} are not all {describe(split)} seeds; the ranges are "
            + ", ".join(describe(s) for s in SPLITS)
        )


def warn_unless_held_out(first: int, last: int, what: str = "the suite") -> bool:
    """Log a warning when seeds ``first..last`` reach into the training range; True if they do."""
    if first < VALIDATION_START:  # the training range ends where validation begins
        log.warning(
            "%s uses seeds %d-%d, which overlap the %s seeds policies are trained on: "
            "report on test seeds (>= %d); choose recipes on validation seeds (%d-%d)",
            what,
            first,
            last,
            describe("train"),
            TEST_START,
            VALIDATION_START,
            TEST_START - 1,
        )
        return True
    return False
