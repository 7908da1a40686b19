"""bboxpick-collect: a real LeRobotDataset on disk, open-loop replay, resume after a kill, bad input."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lerobot_bboxpick.data.collect import CollectConfig, collect, finished_shards
from lerobot_bboxpick.data.features import dataset_features
from lerobot_bboxpick.data.replay import episode_arrays, load_dataset, replay_dataset
from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.layouts import SETTINGS

pytestmark = pytest.mark.slow  # end-to-end: real datasets, subprocesses, rollouts

BIN = Path(sys.executable).parent
REPO = "test/expert"


@pytest.fixture(scope="module")
def collected(tmp_path_factory):
    root = tmp_path_factory.mktemp("collect") / "ds"
    summary = collect(
        CollectConfig(repo_id=REPO, root=root, settings="grid_id,identical_2", episodes=3, shard_size=2)
    )
    return root, summary


def test_dataset_has_the_schema_and_episode_facts(collected):
    root, summary = collected
    assert summary["episodes"] == 3 and summary["outcomes"]["pick"] == 3
    ds = load_dataset(REPO, root)
    assert ds.num_episodes == 3 and ds.fps == 20
    for key, ft in dataset_features().items():
        assert (
            tuple(ds.features[key]["shape"]) == tuple(ft["shape"])
            and ds.features[key]["dtype"] == ft["dtype"]
        )
    env = LegoPickEnv(setting="grid_id")
    for e in range(3):
        arrays = episode_arrays(ds, e)
        assert arrays["seed"] == e and SETTINGS[arrays["setting"]] == ("grid_id", "identical_2")[e % 2]
        env.reset(seed=e) if e % 2 == 0 else None
        if e % 2 == 0:
            assert arrays["target"] == env.target
        # state is the pose the arm had: the first one is the start pose, within 3 cm of nominal
        assert np.linalg.norm(arrays["states"][0, :3] - [0.42, 0.0, 0.22]) < 0.03
        # the recorded action leads the recorded state by about one step (tracking within 2 cm)
        lag = np.linalg.norm(arrays["actions"][:-1, :3] - arrays["states"][1:, :3], axis=1)
        assert np.percentile(lag, 95) < 0.02
    env.close()
    done = np.asarray(ds.hf_dataset["next.done"]).ravel()
    ends = [episode_arrays(ds, e)["to"] - 1 for e in range(3)]
    assert np.flatnonzero(done).tolist() == ends
    frame = ds[0]
    assert frame["observation.images.wrist"].shape == (3, 224, 224) and frame["task"].startswith(
        "pick up the "
    )


def test_open_loop_replay_picks_again(collected):
    root, _ = collected
    records = replay_dataset(REPO, root)
    assert [r["outcome"] for r in records] == ["pick"] * 3


def test_lerobot_edit_dataset_works_on_it(collected, tmp_path):
    root, _ = collected
    out = tmp_path / "edited"
    result = subprocess.run(
        [
            BIN / "lerobot-edit-dataset",
            f"--repo_id={REPO}",
            f"--root={root}",
            "--new_repo_id=test/edited",
            f"--new_root={out}",
            "--operation.type=delete_episodes",
            "--operation.episode_indices=[1]",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    edited = load_dataset("test/edited", out)
    assert edited.num_episodes == 2
    assert [episode_arrays(edited, e)["seed"] for e in range(2)] == [0, 2]


def _collect_cmd(root: Path, episodes: int, *extra: str) -> list:
    return [
        BIN / "bboxpick-collect",
        f"--repo_id={REPO}",
        f"--root={root}",
        f"--episodes={episodes}",
        "--shard_size=1",
        *extra,
    ]


def test_killed_collection_resumes_without_duplicates(tmp_path):
    root = tmp_path / "ds"
    work = root.with_name("ds.collect")
    proc = subprocess.Popen(_collect_cmd(root, 3), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 240
    while not finished_shards(work) and time.time() < deadline:
        time.sleep(0.5)
    proc.send_signal(signal.SIGKILL)  # no clean-up: as if the machine died mid-episode
    proc.wait()
    assert finished_shards(work), "no shard was finished before the deadline"
    assert not root.exists()  # the dataset is only ever swapped in whole
    refused = subprocess.run(_collect_cmd(root, 3), capture_output=True, text=True)
    assert refused.returncode != 0 and "--resume=true" in refused.stderr
    resumed = subprocess.run(
        _collect_cmd(root, 3, "--resume=true"), capture_output=True, text=True, timeout=600
    )
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    ds = load_dataset(REPO, root)
    seeds = [episode_arrays(ds, e)["seed"] for e in range(ds.num_episodes)]
    assert seeds == [0, 1, 2]
    attempts = [json.loads((s / "seeds.json").read_text()) for s in finished_shards(work)]
    assert sorted(r["seed"] for a in attempts for r in a) == [0, 1, 2]
    assert not list(work.glob("*.partial"))


def test_growing_a_dataset_keeps_it_loadable_until_the_swap(collected, tmp_path):
    import shutil

    src_root, _ = collected
    root = tmp_path / "ds"
    shutil.copytree(src_root, root)
    shutil.copytree(src_root.with_name("ds.collect"), tmp_path / "ds.collect")
    proc = subprocess.Popen(
        _collect_cmd(root, 5, "--resume=true"), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    deadline = time.time() + 240
    while not list((tmp_path / "ds.collect").glob("*.partial")) and time.time() < deadline:
        time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)  # killed while recording a new shard
    proc.wait()
    assert load_dataset(REPO, root).num_episodes == 3  # the old dataset is intact and loads


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"settings": "grid_id,piles"}, "valid settings: grid_id, grid_ood"),
        ({"episodes": -2}, "episodes=-2 must be an integer >= 1"),
        ({"workers": 0}, "workers=0 must be an integer >= 1"),
        ({"settings": ""}, "is empty"),
    ],
)
def test_bad_arguments_are_refused_with_clear_messages(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        CollectConfig(root=tmp_path / "x", **kwargs)


def test_existing_root_without_resume_is_refused(collected):
    root, _ = collected
    with pytest.raises(FileExistsError, match="--resume=true"):
        collect(CollectConfig(repo_id=REPO, root=root, episodes=1))


def test_cli_reports_bad_arguments():
    result = subprocess.run([BIN / "bboxpick-collect", "--episodes=0"], capture_output=True, text=True)
    assert result.returncode != 0 and "episodes=0 must be an integer >= 1" in result.stderr
