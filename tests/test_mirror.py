"""Mirror augmentation: mirrored expert episodes replay in the mirrored scene; image/bbox flip; datasets."""

from dataclasses import dataclass

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_bboxpick import geometry
from lerobot_bboxpick.data.collect import record_episode
from lerobot_bboxpick.data.features import (
    ACTION,
    BBOX,
    EPISODE_OUTCOME,
    STATE,
    WRIST_IMAGE,
    create_dataset,
    dataset_features,
)
from lerobot_bboxpick.data.mirror import main, mirror_dataset, mirror_frame, mirror_layout, swap_left_right
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.layouts import SETTINGS, Layout, describe_target, make_layout
from lerobot_bboxpick.sim.scene import brick_silhouette_points

SEEDS = (0, 1)
COLUMNS = [STATE, ACTION, BBOX, "next.reward", "next.done", "next.success", "episode.seed",
           "episode.setting", "episode.target", EPISODE_OUTCOME]  # fmt: skip


@dataclass
class Rollout:
    seed: int
    layout: Layout
    task: str
    actions: np.ndarray  # (N, 10)
    frames: list[dict]  # make_frame dicts, every step kept
    outcome: str


def mirror_start(agent_pos: np.ndarray) -> np.ndarray:
    """4x4 start pose of the mirrored episode: the mirror of the recorded first agent_pos."""
    return geometry.pose9_to_mat(geometry.mirror_pose10(agent_pos)[:9])


@pytest.fixture(scope="module")
def rollouts(grid_env) -> list[Rollout]:
    """Expert episodes on grid_id (terminate_on_lift=False), every frame recorded."""
    out = []
    for seed in SEEDS:
        frames, outcome = record_episode(grid_env, seed)
        actions = np.array([f["action"] for f in frames], dtype=np.float64)
        out.append(Rollout(seed, grid_env.layout, frames[0]["task"], actions, frames, outcome))
    return out


def test_swap_left_right_and_mirror_layout():
    assert (
        swap_left_right("pick up the red block on the far left") == "pick up the red block on the far right"
    )
    assert (
        swap_left_right("Right of the LEFT one, leftmost, bright")
        == "Left of the RIGHT one, rightmost, bright"
    )
    assert swap_left_right("in the middle") == "in the middle"
    for setting in SETTINGS:
        for seed in range(20):
            layout = make_layout(setting, np.random.default_rng(seed))
            m = mirror_layout(layout)
            np.testing.assert_allclose(m.positions[:, 1], -layout.positions[:, 1])
            assert m.colors == layout.colors and m.target == layout.target and m.setting == layout.setting
            np.testing.assert_array_equal(mirror_layout(m).positions, layout.positions)
            np.testing.assert_array_equal(mirror_layout(m).yaws, layout.yaws)
            # the language task of the mirrored scene is the swapped task
            assert describe_target(m) == swap_left_right(describe_target(layout))


@pytest.mark.slow
def test_mirrored_episode_replays_in_mirrored_scene(grid_env, rollouts):
    """THE KEY TEST: open-loop replay of the mirrored actions from the mirrored start picks the target."""
    for r in rollouts:
        assert r.outcome == "pick", f"seed {r.seed}: the expert itself failed ({r.outcome})"
        first_state = r.frames[0][STATE]
        obs, info = grid_env.reset(
            seed=r.seed, options={"layout": mirror_layout(r.layout), "start_pose": mirror_start(first_state)}
        )
        start_err = np.abs(obs["agent_pos"] - geometry.mirror_pose10(first_state)).max()
        assert start_err < 1e-3, start_err
        assert info["task"] == swap_left_right(r.task)
        target_y = grid_env.brick_pose(r.layout.target)[1, 3]
        np.testing.assert_allclose(target_y, -r.layout.positions[r.layout.target, 1], atol=2e-3)
        for action in geometry.mirror_pose10(r.actions.astype(np.float64)).astype(np.float32):
            obs, _, _, _, info = grid_env.step(action)
        print(f"\nseed {r.seed}: {len(r.actions)} mirrored actions replayed -> {info['outcome']}; "
              f"start error {start_err:.1e}; task {info['task']!r}")  # fmt: skip
        assert info["outcome"] == "pick", f"seed {r.seed}: mirrored replay ended {info['outcome']}"


def test_image_flip_matches_mirrored_render():
    """fliplr / mirror_image_bbox vs a render of the mirrored scene (no domain randomisation).

    The true mirrored view is u' = 2 cx - u; fliplr gives 223 - u: a uniform 2 (cx - 111.5) px shift.
    """
    env = LegoPickEnv(setting="grid_id", domain_randomization=False)
    silhouette = brick_silhouette_points()
    cx = env.camera.lens.cx
    expected_shift = 2 * cx - (env.camera.lens.width - 1)

    def view():
        T = env.brick_pose(env.target)
        u, _ = env.camera.project_world(env.data, silhouette @ T[:3, :3].T + T[:3, 3])
        return u

    try:
        for seed in SEEDS:
            obs, _ = env.reset(seed=seed)
            u0, img0, box0 = view(), obs["pixels"]["wrist"], obs["bbox"]
            obs, _ = env.reset(
                seed=seed,
                options={"layout": mirror_layout(env.layout), "start_pose": mirror_start(obs["agent_pos"])},
            )
            u1, img1, box1 = view(), obs["pixels"]["wrist"], obs["bbox"]
            # exact (unsnapped) outline extents: a horizontal shift of both edges, v extents unchanged
            w1 = env.camera.lens.width - 1
            shift = np.array([u1[:, 0].min() - (w1 - u0[:, 0].max()), u1[:, 0].max() - (w1 - u0[:, 0].min())])
            v_err = np.abs([u1[:, 1].min() - u0[:, 1].min(), u1[:, 1].max() - u0[:, 1].max()]).max()
            box_px = (box1 - geometry.mirror_image_bbox(box0)) * env.camera.lens.width
            # pixels: the integer shift that best aligns fliplr(original) with the mirrored render
            flipped, seen = np.fliplr(img0).astype(float), img1.astype(float)
            err = {d: np.abs(np.roll(flipped, d, axis=1) - seen)[:, 8:-8].mean() for d in range(-3, 4)}
            best = min(err, key=err.get)
            print(f"\nseed {seed}: cx={cx:.2f}: outline edge shifts {np.round(shift, 3)} px (expected "
                  f"{expected_shift:.3f}), v error {v_err:.4f} px; snapped bbox edge errors "
                  f"{np.round(box_px, 2)} px; image best shift {best} px (mean abs err {err[best]:.2f} "
                  f"vs {err[0]:.2f} unshifted)")  # fmt: skip
            np.testing.assert_allclose(shift, expected_shift, atol=0.05)
            assert v_err < 0.05
            # the snapped (pixel-edge) bbox: x edges off by the 1.54 px shift rounded, y edges exact
            assert np.abs(box_px[[0, 2]]).max() <= np.ceil(abs(expected_shift)) + 1e-3
            assert np.abs(box_px[[1, 3]]).max() <= 1.0 + 1e-3
            assert best in (np.floor(expected_shift), np.ceil(expected_shift))
    finally:
        env.close()


@pytest.fixture(scope="module")
def src_dataset(rollouts, tmp_path_factory) -> LeRobotDataset:
    root = tmp_path_factory.mktemp("mirror") / "src"
    ds = create_dataset("test/src", root)
    for r in rollouts:
        for frame in r.frames:
            ds.add_frame(dict(frame))
        ds.save_episode()
    ds.finalize()
    return LeRobotDataset("test/src", root=root, return_uint8=True)


def _columns(ds: LeRobotDataset, start: int, stop: int) -> dict[str, np.ndarray]:
    rows = ds.hf_dataset.select(range(start, stop))
    return {c: np.stack([np.asarray(v) for v in rows[c]]).reshape(stop - start, -1) for c in COLUMNS}


@pytest.mark.slow
def test_mirror_dataset(src_dataset):
    src, n_ep = src_dataset, src_dataset.num_episodes
    dst_root = src.root.parent / "dst"
    dst = mirror_dataset("test/src", src.root, "test/dst", dst_root)
    assert dst.num_episodes == 2 * n_ep and dst.num_frames == 2 * src.num_frames
    assert not [p for p in dst_root.parent.iterdir() if p.name.endswith(".partial")]
    dst = LeRobotDataset("test/dst", root=dst_root, return_uint8=True)  # loads from disk
    assert set(dataset_features()) <= set(dst.features)
    eps_src, eps_dst = src.meta.episodes, dst.meta.episodes
    worst = 0.0
    for k in range(n_ep):
        a, b = eps_src[k]["dataset_from_index"], eps_src[k]["dataset_to_index"]
        cols = _columns(src, a, b)
        for part, ep in (("original", k), ("mirrored", n_ep + k)):
            c, d = eps_dst[ep]["dataset_from_index"], eps_dst[ep]["dataset_to_index"]
            assert d - c == b - a
            got = _columns(dst, c, d)
            want = cols if part == "original" else mirror_frame(cols)
            for col in COLUMNS:
                np.testing.assert_allclose(got[col], want[col], atol=1e-5, err_msg=f"{part} {col}")
            for i in (0, (b - a) // 2, b - a - 1):
                s_item, d_item = src[a + i], dst[c + i]
                s_img = s_item[WRIST_IMAGE].numpy().transpose(1, 2, 0)
                d_img = d_item[WRIST_IMAGE].numpy().transpose(1, 2, 0).astype(float)
                if part == "original":  # copied, not re-encoded: bit-identical
                    np.testing.assert_array_equal(d_img, s_img)
                    assert d_item["task"] == s_item["task"]
                else:
                    diff = np.abs(d_img - np.fliplr(s_img)).mean()
                    unflipped = np.abs(d_img - s_img).mean()
                    worst = max(worst, diff)
                    assert diff < 2.0 and diff < unflipped / 4, (diff, unflipped)
                    assert d_item["task"] == swap_left_right(s_item["task"])
    print(f"\nmirrored images vs fliplr(source): worst mean abs error {worst:.2f}/255 (codec loss)")
    swapped = {swap_left_right(t) for t in src.meta.tasks.index}
    assert swapped != set(src.meta.tasks.index)  # seed 0's task names a side
    assert set(dst.meta.tasks.index) == set(src.meta.tasks.index) | swapped
    with pytest.raises(FileExistsError, match="already exists"):
        mirror_dataset("test/src", src.root, "test/dst", dst_root)
    # the entry point, mirrored episodes only
    only_root = src.root.parent / "only_mirrored"
    main(["--src-repo-id", "test/src", "--src-root", str(src.root), "--dst-repo-id", "test/m",
          "--dst-root", str(only_root), "--no-original"])  # fmt: skip
    only = LeRobotDataset("test/m", root=only_root)
    assert only.num_episodes == n_ep
    np.testing.assert_allclose(
        only[0][STATE].numpy(), geometry.mirror_pose10(src[0][STATE].numpy()), atol=1e-5
    )


def test_mirror_dataset_crash_leaves_nothing(src_dataset, monkeypatch):
    """A failure mid-way leaves neither dst_root nor the temporary folder behind."""
    import lerobot_bboxpick.data.mirror as mirror

    def boom(frame):
        raise RuntimeError("simulated crash")

    monkeypatch.setattr(mirror, "mirror_frame", boom)
    dst_root = src_dataset.root.parent / "crashed"
    with pytest.raises(RuntimeError, match="simulated crash"):
        mirror.mirror_dataset("test/src", src_dataset.root, "test/crashed", dst_root)
    assert not dst_root.exists()
    assert not [p for p in dst_root.parent.iterdir() if p.name.startswith(".crashed")]
