"""``worker_pool`` on a local Ray instance: the same results as the local spawned pool, worker failures
raised, the workers' environment forwarded, and a real collection identical to the local pool's."""

import importlib.util
import math
import os

import numpy as np
import pytest

from lerobot_bboxpick.data.collect import CollectConfig, collect
from lerobot_bboxpick.data.replay import episode_arrays, load_dataset
from lerobot_bboxpick.parallel import RAY_INSTALL_HINT, check_ray, worker_pool

REPO = "test/ray"


def test_missing_ray_is_reported_with_the_extra(monkeypatch):
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "ray" else real_find_spec(name, *a)
    )
    check_ray(None)  # no address: no Ray needed
    with pytest.raises(ImportError, match=r"lerobot_policy_bboxpick\[ray\]") as info:
        check_ray("auto")
    assert RAY_INSTALL_HINT in str(info.value)
    with pytest.raises(ImportError, match="ray_address='local' needs Ray"):
        CollectConfig(ray_address="local")


def test_ray_pool_maps_like_the_local_pool_and_raises_worker_errors():
    ray = pytest.importorskip("ray")
    numbers = list(range(12))
    with worker_pool(2) as pool:
        expected = pool.map(math.factorial, numbers)
    with worker_pool(2, "local", maxtasksperchild=None) as pool:  # starts a 2-CPU Ray instance
        assert ray.is_initialized()
        assert pool.map(math.factorial, numbers) == expected
        assert sorted(pool.imap_unordered(math.factorial, numbers)) == sorted(expected)
        assert list(pool.imap(math.factorial, numbers)) == expected
        # Ray's own iterators would yield the failure as a value; ours raise it, as multiprocessing does.
        with pytest.raises(ValueError, match="math domain error"):
            list(pool.imap_unordered(math.sqrt, [4.0, -1.0]))
        assert pool.map(os.getenv, ["MUJOCO_GL"]) == ["egl"]
    assert not ray.is_initialized()  # the instance worker_pool started is shut down


def test_ray_workers_get_the_forwarded_environment(monkeypatch):
    ray = pytest.importorskip("ray")
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    # A new instance (never a cluster found on the machine), whose nodes' environment lacks the variable.
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        monkeypatch.setenv("HF_HUB_OFFLINE", "1")
        with worker_pool(2, "local") as pool:
            assert pool.map(os.getenv, ["HF_HUB_OFFLINE", "MUJOCO_GL"]) == ["1", "egl"]
        assert ray.is_initialized()  # a Ray initialized by the caller is left running
    finally:
        ray.shutdown()


@pytest.mark.slow
def test_collection_on_ray_equals_the_local_one(tmp_path):
    pytest.importorskip("ray")
    roots = {}
    for name, address in (("local", None), ("ray", "local")):
        roots[name] = tmp_path / name / "ds"
        cfg = CollectConfig(
            repo_id=REPO,
            root=roots[name],
            settings="grid_id,identical_2",
            episodes=2,
            shard_size=1,
            workers=2,
            ray_address=address,
        )
        summary = collect(cfg)
        assert summary["episodes"] == 2 and summary["attempted"] == 2
    local, on_ray = (load_dataset(REPO, roots[name]) for name in ("local", "ray"))
    assert on_ray.num_episodes == local.num_episodes == 2
    assert on_ray.num_frames == local.num_frames
    for e in range(2):
        a, b = episode_arrays(local, e), episode_arrays(on_ray, e)
        assert a["seed"] == b["seed"] == e and a["setting"] == b["setting"]
        for key in ("actions", "states", "bboxes"):
            np.testing.assert_allclose(b[key], a[key], rtol=0, atol=1e-6, err_msg=f"episode {e} {key}")


@pytest.mark.slow
def test_counterfactual_branches_on_ray_equal_the_local_ones(tmp_path):
    pytest.importorskip("ray")
    from test_counterfactual_dataset import small_config

    from lerobot_bboxpick.rl.counterfactual_dataset import load_points, run_counterfactual

    points = {}
    for name, address in (("local", None), ("ray", "local")):
        cfg = small_config(
            tmp_path / name,
            episodes=2,
            max_points=1,
            perturbations="",
            expert=False,
            max_steps=40,
            workers=2,  # the same threads per worker on both pools
            ray_address=address,
        )
        run_counterfactual(cfg)
        points[name] = load_points(cfg.out_dir)
    local, on_ray = points["local"], points["ray"]
    assert len(local) == len(on_ray) == 2 and local.kinds == ["policy", "sample1"]
    assert on_ray.seed.tolist() == local.seed.tolist() == [7, 8]
    for key in ("image", "state", "outcome", "steps", "ret"):
        np.testing.assert_array_equal(getattr(on_ray, key), getattr(local, key), err_msg=key)
    np.testing.assert_allclose(on_ray.candidates, local.candidates, rtol=0, atol=1e-6)
