"""``bboxpick-dataset-viz``: LeRobot's ``lerobot-dataset-viz`` for our datasets, with the target bbox.

LeRobot's viewer logs the camera images, ``action`` and ``observation.state`` of an episode to Rerun;
it does not know ``observation.bbox``. This runs LeRobot's own ``visualize_dataset`` and then logs the
episode's boxes into the same recording, as a 2-D box on the wrist image entity at each frame:

    bboxpick-dataset-viz --repo-id local/lego_pick_quick --root outputs/main/quick/data --episode-index 0
    bboxpick-dataset-viz ... --save 1 --output-dir outputs/viz       # an .rrd file to open later
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from lerobot_bboxpick.keys import BBOX, WRIST_IMAGE


def episode_boxes(dataset, episode_index: int) -> np.ndarray:
    """(T, 4) normalised boxes of one episode, read from the parquet columns (no video decoding)."""
    column = dataset.hf_dataset.with_format(None)
    episodes = np.asarray(column["episode_index"])
    if episode_index not in set(episodes.tolist()):
        raise ValueError(f"episode_index={episode_index} is not in the dataset (0-{episodes.max()})")
    rows = np.flatnonzero(episodes == episode_index)
    return np.asarray([column[int(i)][BBOX] for i in rows], dtype=np.float32)


def log_boxes(boxes: np.ndarray, width: int, height: int) -> None:
    """Log each frame's box (zeros: target not visible, nothing drawn) on the wrist image entity."""
    import rerun as rr

    scale = np.array([width, height, width, height], dtype=np.float32)
    for k, box in enumerate(boxes):
        rr.set_time("frame_index", sequence=k)
        if box[2] > box[0] and box[3] > box[1]:
            rr.log(
                f"{WRIST_IMAGE}/bbox",
                rr.Boxes2D(array=box * scale, array_format=rr.Box2DFormat.XYXY, labels="target"),
            )
        else:
            rr.log(f"{WRIST_IMAGE}/bbox", rr.Clear(recursive=False))


def visualize(
    repo_id: str, root: Path | None, episode_index: int, save: bool, output_dir: Path | None, mode: str
) -> Path | None:
    """LeRobot's visualisation of one episode plus its bbox; returns the .rrd path when saving."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.scripts.lerobot_dataset_viz import visualize_dataset

    dataset = LeRobotDataset(repo_id, root=root, episodes=[episode_index])
    rrd = visualize_dataset(dataset, episode_index, mode=mode, save=save, output_dir=output_dir)
    height, width = dataset.meta.features[WRIST_IMAGE]["shape"][:2]
    log_boxes(episode_boxes(dataset, episode_index), width, height)
    import rerun as rr

    rr.disconnect()  # flushes the boxes to the .rrd file (or viewer) LeRobot's call opened
    return rrd


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``bboxpick-dataset-viz``."""
    parser = argparse.ArgumentParser(prog="bboxpick-dataset-viz", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo-id", required=True)
    parser.add_argument("--root", type=Path, default=None)
    parser.add_argument("--episode-index", type=int, default=0)
    parser.add_argument("--mode", choices=("local", "distant"), default="local")
    parser.add_argument("--save", type=int, choices=(0, 1), default=0)
    parser.add_argument("--output-dir", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.save and args.output_dir is None:
        parser.error("--save 1 needs --output-dir")
    logging.basicConfig(level=logging.INFO)
    rrd = visualize(args.repo_id, args.root, args.episode_index, bool(args.save), args.output_dir, args.mode)
    if rrd is not None:
        print(f"saved {rrd}")
