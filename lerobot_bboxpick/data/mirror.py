"""Mirror augmentation (paper table 1, Exp. 5 and 8): every episode mirrored across the table's x-z plane.

    bboxpick-mirror --src-repo-id local/lego_pick_expert --src-root outputs/datasets/expert \
        --dst-repo-id local/lego_pick_expert_mirrored --dst-root outputs/datasets/expert_mirrored

The mirror is a reflection of the whole world across y = 0 (``geometry.mirror_pose10``): brick
positions ``y -> -y``, yaws ``-> -yaw``, and the TCP pose ``R' = M R D``, which flips only the
gripper-frame x coordinate of every scene point. The wrist camera sits in the gripper's y-z plane
with its image x axis along the gripper's finger axis, so in camera coordinates the mirror is
``(x, y, z) -> (-x, y, z)``: the fisheye projects the mirrored scene to ``u' = 2 cx - u`` (v
unchanged), a flip about the principal point's column. ``np.fliplr`` flips about the array centre
``(W - 1) / 2 = 111.5`` instead, ``u -> 223 - u``; our lens has ``cx = 112.27`` (the UMI GoPro
calibration resized and centre-cropped to 224), 0.77 px off the centre, so a flipped image (and
``geometry.mirror_image_bbox``, which uses the same convention) is the true mirrored view shifted
by ``2 (cx - 111.5) = 1.54 px`` to the left: the same for every pixel, under 0.7 % of the image
width, and identical for the pixels and the bbox, which therefore stay consistent with each other
(tests/test_mirror.py measures it). The real GoPro's principal point is off-centre too, so the
paper's flipped real images carried the same kind of shift. Lighting is not mirrored (the key light
sits at -y) and shading is what a flip makes of it.

Other columns: the state and the action go through ``mirror_pose10``; the task text has "left" and
"right" swapped (so it matches ``describe_target`` of the mirrored layout); ``episode.*`` and
``next.*`` are copied. Episode ``k`` of the mirrored part is the mirror of source episode ``k``; its
scene is ``mirror_layout`` of the source episode's layout (same ``episode.seed``).
"""

from __future__ import annotations

import argparse
import re
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from lerobot_bboxpick.data.features import ACTION, BBOX, STATE, WRIST_IMAGE, dataset_features
from lerobot_bboxpick.geometry import mirror_image_bbox, mirror_pose10
from lerobot_bboxpick.sim.layouts import Layout

if TYPE_CHECKING:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

_Y_FLIP = np.array([1.0, -1.0, 1.0])
_LEFT_RIGHT = re.compile(r"\b(left|right)", re.IGNORECASE)


def mirror_layout(layout: Layout) -> Layout:
    """The scene mirrored across y = 0: positions ``y -> -y``, yaws negated, same colours and target."""
    positions = np.asarray(layout.positions, dtype=np.float64) * _Y_FLIP
    return Layout(
        layout.setting, positions, -np.asarray(layout.yaws, dtype=np.float64), layout.colors, layout.target
    )


def swap_left_right(text: str) -> str:
    """Swap the words "left" and "right" (also as word starts, e.g. "leftmost"), keeping their case."""

    def swap(m: re.Match) -> str:
        word = "right" if m.group(1).lower() == "left" else "left"
        return (
            word.upper() if m.group(1).isupper() else word.capitalize() if m.group(1)[0].isupper() else word
        )

    return _LEFT_RIGHT.sub(swap, text)


def mirror_frame(frame: dict) -> dict:
    """Mirror a frame dict of numpy arrays (leading batch dims allowed; images ``(..., H, W, C)``).

    Image flipped left-right, bbox, state and action mirrored, task text left<->right; entries that
    are absent are skipped and every other entry is copied.
    """
    out = dict(frame)
    if WRIST_IMAGE in frame:
        out[WRIST_IMAGE] = np.ascontiguousarray(np.flip(frame[WRIST_IMAGE], axis=-2))
    if BBOX in frame:
        out[BBOX] = mirror_image_bbox(frame[BBOX]).astype(np.float32)
    for key in (STATE, ACTION):
        if key in frame:
            out[key] = mirror_pose10(frame[key]).astype(np.float32)
    if "task" in frame:
        out["task"] = swap_left_right(frame["task"])
    return out


def _features_of(src: LeRobotDataset) -> dict[str, dict]:
    """``dataset_features()`` matching the source (image size, video or image), checked against it."""
    image = src.meta.features[WRIST_IMAGE]
    features = dataset_features(image_size=int(image["shape"][0]), use_video=image["dtype"] == "video")
    for key, ft in features.items():
        have = src.meta.features.get(key)
        if have is None or have["dtype"] != ft["dtype"] or tuple(have["shape"]) != tuple(ft["shape"]):
            raise ValueError(f"source feature {key!r} is {have}, expected the lerobot_bboxpick schema {ft}")
    return features


def _frame_of(item: dict, features: dict[str, dict]) -> dict:
    """A ``LeRobotDataset`` item (torch; image CHW) -> an ``add_frame`` dict (numpy; image HWC uint8)."""
    frame = {"task": item["task"]}
    for key, ft in features.items():
        v = item[key].numpy()
        if ft["dtype"] in ("video", "image"):
            v = v if v.dtype == np.uint8 else (v * 255).round().astype(np.uint8)  # image datasets: float
            frame[key] = np.ascontiguousarray(v.transpose(1, 2, 0))
        else:
            frame[key] = v.astype(ft["dtype"]).reshape(ft["shape"])
    return frame


def mirror_dataset(
    src_repo_id: str,
    src_root: str | Path | None,
    dst_repo_id: str,
    dst_root: str | Path,
    include_original: bool = True,
) -> LeRobotDataset:
    """Write a LeRobotDataset at ``dst_root``: the source episodes (if ``include_original``, copied
    losslessly by LeRobot's aggregation) followed by their mirrored copies (re-encoded with the
    source's video encoder settings). Returns the new dataset, opened for reading.

    Refuses an existing ``dst_root``. Everything is built in a temporary folder beside ``dst_root``
    and renamed into place at the end, so a crash never leaves a half-written dataset there.
    """
    from lerobot.configs.video import encoder_config_from_video_info
    from lerobot.datasets.aggregate import aggregate_datasets
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dst_root = Path(dst_root)
    if dst_root.exists():
        raise FileExistsError(
            f"dst_root={dst_root} already exists; mirror_dataset never overwrites a dataset"
        )
    src = LeRobotDataset(src_repo_id, root=src_root, return_uint8=True)
    features = _features_of(src)
    video_info = src.meta.features[WRIST_IMAGE].get("info")
    dst_root.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{dst_root.name}.", suffix=".partial", dir=dst_root.parent))
    try:
        mirrored = LeRobotDataset.create(
            repo_id=dst_repo_id,
            fps=src.fps,
            features=features,
            root=work / "mirrored",
            robot_type=src.meta.robot_type,
            use_videos=features[WRIST_IMAGE]["dtype"] == "video",
            rgb_encoder=encoder_config_from_video_info(video_info) if video_info else None,
        )
        episodes = src.meta.episodes
        for ep in tqdm(range(src.num_episodes), desc="mirroring episodes", unit="ep"):
            for i in range(episodes[ep]["dataset_from_index"], episodes[ep]["dataset_to_index"]):
                mirrored.add_frame(mirror_frame(_frame_of(src[i], features)))
            mirrored.save_episode()
        mirrored.finalize()
        out = work / "mirrored"
        if include_original:
            out = work / "merged"
            aggregate_datasets(
                repo_ids=[src_repo_id, dst_repo_id], roots=[src.root, work / "mirrored"],
                aggr_repo_id=dst_repo_id, aggr_root=out,
            )  # fmt: skip
        out.rename(dst_root)  # raises rather than replace a non-empty dst_root made meanwhile
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return LeRobotDataset(dst_repo_id, root=dst_root)


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``bboxpick-mirror``."""
    parser = argparse.ArgumentParser(prog="bboxpick-mirror", description=__doc__.split("\n\n")[0])
    parser.add_argument("--src-repo-id", required=True)
    parser.add_argument("--src-root", default=None, help="source dataset folder (default: LeRobot's cache)")
    parser.add_argument("--dst-repo-id", required=True)
    parser.add_argument("--dst-root", required=True, help="output folder; must not exist")
    parser.add_argument("--no-original", action="store_true", help="write only the mirrored episodes")
    args = parser.parse_args(argv)
    ds = mirror_dataset(
        args.src_repo_id,
        args.src_root,
        args.dst_repo_id,
        args.dst_root,
        include_original=not args.no_original,
    )
    print(f"wrote {ds.num_episodes} episodes ({ds.num_frames} frames) to {args.dst_root}")
