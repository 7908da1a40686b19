"""UMI ``dataset.zarr.zip`` ReplayBuffer <-> lerobot_bboxpick LeRobotDataset.

The UMI file (``diffusion_policy/common/replay_buffer.py`` layout, zarr v2 in a ``zarr.ZipStore``):
``data/`` holds float32 ``robot0_eef_pos`` (N, 3), ``robot0_eef_rot_axis_angle`` (N, 3),
``robot0_gripper_width`` (N, 1), ``robot0_demo_start_pose`` / ``robot0_demo_end_pose`` (N, 6) (the
episode's first / last pose as position + axis-angle, repeated on every frame) and uint8
``camera0_rgb`` (N, H, W, 3) in one-frame chunks compressed with JPEG-XL level 99; low-dim arrays are
uncompressed; ``meta/episode_ends`` (int64) holds cumulative episode ends. We add ``data/camera0_bbox``
(N, 4) float32, the target box (normalised x0, y0, x1, y1), which UMI readers ignore.

Pose conversions go through :mod:`lerobot_bboxpick.geometry`.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import imagecodecs.numcodecs
import numpy as np
import zarr
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from tqdm.auto import tqdm

from lerobot_bboxpick import geometry
from lerobot_bboxpick.data.features import (
    BBOX,
    STATE,
    WRIST_IMAGE,
    create_dataset,
    make_frame,
)
from lerobot_bboxpick.data.tracking import track_bbox

EEF_POS = "robot0_eef_pos"
EEF_ROT = "robot0_eef_rot_axis_angle"
GRIPPER = "robot0_gripper_width"
DEMO_START = "robot0_demo_start_pose"
DEMO_END = "robot0_demo_end_pose"
RGB = "camera0_rgb"
CAMERA_BBOX = "camera0_bbox"
EPISODE_ENDS = "episode_ends"
JPEGXL_LEVEL = 99  # UMI's 07_generate_replay_buffer.py default
BBOX_SOURCES = ("auto", "zarr", "tracker")
DEFAULT_TASK = "pick up the block in the box"


# The arguments of UMI's vendored codec (diffusion_policy/codecs/imagecodecs_numcodecs.py ``JpegXl``):
# numcodecs builds a reader's codec from the stored config, so a key it lacks (this imagecodecs also
# stores bitspersample, primaries, transfer, perceptualheuristics, squeeze) is a TypeError in UMI.
UMI_JPEGXL_KEYS = frozenset(
    ["id", "level", "effort", "distance", "lossless", "decodingspeed", "photometric", "planar"]
    + ["usecontainer", "index", "keeporientation", "numthreads"]
)


class _UmiJpegxl(imagecodecs.numcodecs.Jpegxl):
    """imagecodecs' JPEG-XL codec whose stored config names only arguments UMI's ``JpegXl`` accepts."""

    def get_config(self) -> dict:
        return {k: v for k, v in super().get_config().items() if k in UMI_JPEGXL_KEYS}


def _register_codecs() -> None:
    imagecodecs.numcodecs.register_codecs(verbose=False)


def _pos_rotvec(pose10: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pos, rotvec = geometry.pose9_to_pos_axis_angle(pose10[..., :9])
    return pos.astype(np.float32), rotvec.astype(np.float32)


def export_umi_zarr(
    dataset: LeRobotDataset | tuple[str, str | Path],
    out_path: str | Path,
    *,
    jpegxl_effort: int | None = None,
) -> Path:
    """Write ``dataset`` (a LeRobotDataset or ``(repo_id, root)``) as a UMI ``dataset.zarr.zip``.

    Poses come from ``observation.state``, images from the decoded wrist video, boxes from
    ``observation.bbox`` (as ``data/camera0_bbox``). Written to a temporary file beside ``out_path``
    and renamed, so ``out_path`` never holds a partial file. Returns ``out_path``.

    ``jpegxl_effort`` (1-9) trades encoder speed for size only (readers need not know it); None is
    libjxl's default, as in UMI: about 40 ms per 224x224 frame here, effort 1 under 1 ms (+35% size).
    """
    if isinstance(dataset, tuple):
        if len(dataset) != 2:
            raise ValueError(f"dataset must be a LeRobotDataset or (repo_id, root), got {dataset!r}")
        repo_id, root, episodes = dataset[0], dataset[1], None
    elif isinstance(dataset, LeRobotDataset):
        repo_id, root, episodes = dataset.repo_id, dataset.root, dataset.episodes
    else:
        raise ValueError(f"dataset must be a LeRobotDataset or (repo_id, root), got {type(dataset).__name__}")
    # A fresh read-only view: no image transforms or delta timestamps of the caller's instance.
    ds = LeRobotDataset(repo_id, root=root, episodes=episodes)
    missing = [k for k in (STATE, BBOX, WRIST_IMAGE) if k not in ds.features]
    if missing:
        raise ValueError(
            f"dataset {repo_id!r} lacks feature(s) {missing}; export needs {STATE}, {BBOX}, {WRIST_IMAGE}"
        )
    n = len(ds)
    if n == 0:
        raise ValueError(f"dataset {repo_id!r} has no frames to export")
    cols = ds.hf_dataset.with_format("numpy")
    state = np.asarray(cols[STATE], dtype=np.float64)
    bbox = np.asarray(cols[BBOX], dtype=np.float32)
    episode_index = np.asarray(cols["episode_index"])
    change = np.flatnonzero(np.diff(episode_index) != 0) + 1
    if np.any(np.diff(episode_index) < 0):
        raise ValueError(f"dataset {repo_id!r} frames are not grouped by episode (episode_index decreases)")
    ends = np.append(change, n).astype(np.int64)
    starts = np.concatenate([[0], ends[:-1]])

    pos, rotvec = _pos_rotvec(state)
    pose6 = np.concatenate([pos, rotvec], axis=1)
    lengths = ends - starts
    demo_start = np.repeat(pose6[starts], lengths, axis=0)
    demo_end = np.repeat(pose6[ends - 1], lengths, axis=0)
    h, w = ds.features[WRIST_IMAGE]["shape"][:2]

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(f".{out_path.name}.{os.getpid()}.tmp")
    _register_codecs()
    store = zarr.ZipStore(str(tmp), mode="w")
    try:
        group = zarr.group(store=store)
        data, meta = group.create_group("data"), group.create_group("meta")
        lowdim = {
            EEF_POS: pos,
            EEF_ROT: rotvec,
            GRIPPER: state[:, 9:10].astype(np.float32),
            DEMO_START: demo_start,
            DEMO_END: demo_end,
            CAMERA_BBOX: bbox,
        }
        for name, arr in lowdim.items():
            data.array(name, arr, chunks=arr.shape, compressor=None, dtype=np.float32)
        meta.array(EPISODE_ENDS, ends, chunks=ends.shape, compressor=None, dtype=np.int64)
        rgb = data.create(
            RGB,
            shape=(n, h, w, 3),
            chunks=(1, h, w, 3),
            dtype=np.uint8,
            compressor=_UmiJpegxl(level=JPEGXL_LEVEL, effort=jpegxl_effort, numthreads=1),
        )
        with tqdm(total=n, desc=f"export {out_path.name}", unit="frame") as bar:
            for s, e in zip(starts, ends, strict=True):
                frames = np.stack([_frame_uint8(ds[i][WRIST_IMAGE]) for i in range(s, e)])
                rgb[s:e] = frames  # one-frame chunks: each is written once
                bar.update(int(e - s))
        store.close()
        os.replace(tmp, out_path)
    except BaseException:
        store.close()
        tmp.unlink(missing_ok=True)
        raise
    return out_path


def _frame_uint8(image) -> np.ndarray:
    """A decoded LeRobot image (C, H, W) float in [0, 1] -> (H, W, C) uint8."""
    a = np.asarray(image, dtype=np.float32)
    return np.clip(np.round(a.transpose(1, 2, 0) * 255.0), 0, 255).astype(np.uint8)


def _check_first_boxes(first_frame_boxes: dict, n_episodes: int) -> dict[int, np.ndarray]:
    boxes = {}
    for k, v in first_frame_boxes.items():
        b = np.asarray(v, dtype=np.float64).reshape(-1)
        if not (isinstance(k, int | np.integer) and 0 <= k < n_episodes):
            raise ValueError(f"first_frame_boxes key {k!r} is not an episode index in [0, {n_episodes - 1}]")
        if b.shape != (4,) or not (0 <= b[0] < b[2] <= 1 and 0 <= b[1] < b[3] <= 1):
            raise ValueError(
                f"first_frame_boxes[{k}] must be a normalised box x0, y0, x1, y1 in [0, 1] with x0 < x1, "
                f"y0 < y1, got {v!r}"
            )
        boxes[int(k)] = b
    missing = sorted(set(range(n_episodes)) - set(boxes))
    if missing:
        raise ValueError(f"first_frame_boxes has no box for episode(s) {missing} (of {n_episodes})")
    return boxes


def import_umi_zarr(
    zarr_path: str | Path,
    repo_id: str,
    root: str | Path,
    task: str = DEFAULT_TASK,
    bbox_source: str = "auto",
    first_frame_boxes: dict[int, np.ndarray] | None = None,
) -> LeRobotDataset:
    """Read a UMI ``dataset.zarr.zip`` into a new LeRobotDataset at ``root`` with ``dataset_features()``.

    * ``observation.state``: eef position + rot6d (from the axis-angle) + gripper width.
    * ``action`` at frame t = the state at t+1 (the last frame repeats its own state). UMI files hold
      measured poses, not commands; UMI's own training builds its action targets the same way, from
      the future poses of the recording.
    * ``observation.bbox``: ``bbox_source="zarr"`` reads ``data/camera0_bbox``; ``"tracker"``
      propagates ``first_frame_boxes[episode]`` (normalised x0, y0, x1, y1 on the episode's first
      frame) with :func:`~lerobot_bboxpick.data.tracking.track_bbox`; ``"auto"`` uses the array when
      the file has it, else the tracker.
    * ``episode.seed`` = the episode's index in the zarr file; setting, target and outcome = -1
      (unknown); reward 0, success False, done on each episode's last frame.

    Returns the finalized dataset, opened for reading.
    """
    if bbox_source not in BBOX_SOURCES:
        raise ValueError(f"bbox_source must be one of {BBOX_SOURCES}, got {bbox_source!r}")
    if not isinstance(task, str) or not task:
        raise ValueError(f"task must be a non-empty string, got {task!r}")
    zarr_path, root = Path(zarr_path), Path(root)
    if not zarr_path.is_file():
        raise FileNotFoundError(f"zarr_path {zarr_path} does not exist (expected a UMI dataset.zarr.zip)")
    if root.exists():
        raise ValueError(f"root {root} already exists; import_umi_zarr creates a new dataset there")
    _register_codecs()
    store = zarr.ZipStore(str(zarr_path), mode="r")
    try:
        group = zarr.open_group(store=store, mode="r")
        for path in (
            f"data/{EEF_POS}",
            f"data/{EEF_ROT}",
            f"data/{GRIPPER}",
            f"data/{RGB}",
            f"meta/{EPISODE_ENDS}",
        ):
            if path not in group:
                raise ValueError(f"{zarr_path} is not a UMI replay buffer: array {path!r} is missing")
        data = group["data"]
        ends = np.asarray(group["meta"][EPISODE_ENDS][:], dtype=np.int64)
        pos = np.asarray(data[EEF_POS][:], dtype=np.float64)
        rotvec = np.asarray(data[EEF_ROT][:], dtype=np.float64)
        width = np.asarray(data[GRIPPER][:], dtype=np.float64).reshape(len(pos), -1)
        rgb = data[RGB]
        n = len(pos)
        _check_shapes(zarr_path, n, rotvec, width, rgb, ends)
        has_bbox = CAMERA_BBOX in data
        use_zarr = bbox_source == "zarr" or (bbox_source == "auto" and has_bbox)
        if use_zarr and not has_bbox:
            raise ValueError(f"bbox_source='zarr' but {zarr_path} has no data/{CAMERA_BBOX} array")
        if not use_zarr and first_frame_boxes is None:
            raise ValueError(
                f"bbox_source={bbox_source!r} needs first_frame_boxes (no data/{CAMERA_BBOX} in {zarr_path} "
                "or tracker requested): give a normalised first-frame box per episode"
            )
        zarr_bbox = np.asarray(data[CAMERA_BBOX][:], dtype=np.float32) if use_zarr else None
        if zarr_bbox is not None and zarr_bbox.shape != (n, 4):
            raise ValueError(f"data/{CAMERA_BBOX} must have shape ({n}, 4), got {zarr_bbox.shape}")
        boxes0 = None if use_zarr else _check_first_boxes(first_frame_boxes, len(ends))

        state = np.concatenate([geometry.pos_axis_angle_to_pose9(pos, rotvec), width[:, :1]], axis=1)
        state = state.astype(np.float32)
        starts = np.concatenate([[0], ends[:-1]])
        ds = create_dataset(repo_id, root, image_size=rgb.shape[1])
        try:
            for ep, (s, e) in enumerate(
                tqdm(list(zip(starts, ends, strict=True)), desc="import", unit="episode")
            ):
                frames = np.asarray(rgb[s:e])
                bbox = zarr_bbox[s:e] if zarr_bbox is not None else track_bbox(frames, boxes0[ep]).boxes
                st = state[s:e]
                action = np.concatenate([st[1:], st[-1:]])
                for t in range(e - s):
                    ds.add_frame(
                        make_frame(frames[t], st[t], bbox[t], action[t], task, done=t == e - s - 1, seed=ep)
                    )
                ds.save_episode()
            ds.finalize()
        except BaseException:
            try:
                ds.finalize()
            finally:
                shutil.rmtree(root, ignore_errors=True)  # no half-written dataset left behind
            raise
    finally:
        store.close()
    return LeRobotDataset(repo_id, root=root)


def _check_shapes(path: Path, n: int, rotvec: np.ndarray, width: np.ndarray, rgb, ends: np.ndarray) -> None:
    if n == 0:
        raise ValueError(f"{path} holds no frames")
    for name, arr, shape in ((EEF_ROT, rotvec, (n, 3)), (GRIPPER, width, (n, 1))):
        if arr.shape != shape:
            raise ValueError(
                f"data/{name} must have shape {shape} (data/{EEF_POS} has {n} rows), got {arr.shape}"
            )
    if len(rgb.shape) != 4 or rgb.shape[0] != n or rgb.shape[3] != 3 or rgb.shape[1] != rgb.shape[2]:
        raise ValueError(f"data/{RGB} must have shape ({n}, S, S, 3) (square images), got {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise ValueError(f"data/{RGB} must be uint8, got {rgb.dtype}")
    if len(ends) == 0 or ends[-1] != n or np.any(np.diff(np.concatenate([[0], ends])) <= 0):
        raise ValueError(
            f"meta/{EPISODE_ENDS} must rise strictly to {n} (the frame count), got {ends.tolist()}"
        )
