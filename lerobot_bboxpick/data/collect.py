"""``bboxpick-collect``: scripted-expert demonstrations into a LeRobotDataset v3.

    bboxpick-collect --repo_id=local/lego_pick_expert --root=outputs/datasets/expert \
        --settings=grid_id --episodes=50 --workers=2
    bboxpick-collect ... --split=validation   # an evaluation dataset from seeds 5000-9999
    bboxpick-collect ... --workers=16 --ray_address=auto   # workers on a Ray cluster (docs/ray.md)

Demonstrations come from the training seeds (0-4999, ``lerobot_bboxpick.seeds``); a seed at or above
5000 is refused unless ``--split`` says the dataset is for validation or test.

How it stays safe to interrupt:
* Work is split into shards of a few seeds. A worker records a shard as its own small
  LeRobotDataset in ``<root>.collect/shard_<first seed>.partial``, finalizes it, writes the list of
  seeds it attempted (kept or not) to ``seeds.json``, and only then renames it to ``shard_<first seed>``.
  A crash mid-episode leaves a ``.partial`` folder that the next run deletes and redoes.
* ``--resume=true`` reads the finished shards' ``seeds.json`` and attempts only the seeds not yet
  attempted, so no episode is recorded twice.
* The dataset at ``root`` is LeRobot's own aggregation of the finished shards, built in a temporary
  folder and swapped in whole: it is never half-written.
Only episodes the expert completes with outcome "pick" are kept unless ``--keep_failed=true`` (then
every attempt is kept, labelled by its ``episode.outcome`` column, for offline RL).
"""

import json
import logging
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import draccus
import numpy as np
from tqdm import tqdm

from lerobot_bboxpick import seeds
from lerobot_bboxpick.data.features import (
    EPISODE_OUTCOME,
    create_dataset,
    make_frame,
    outcome_code,
)
from lerobot_bboxpick.parallel import check_ray, worker_pool
from lerobot_bboxpick.quiet import native_output_to, quiet_libraries, redirect_native_output
from lerobot_bboxpick.sim.expert import TURNS
from lerobot_bboxpick.sim.layouts import SETTINGS, check_setting
from lerobot_bboxpick.sim.outcome import OUTCOMES

SHARD_SIZE = 5
log = logging.getLogger(__name__)


@dataclass
class CollectConfig:
    """Options of ``bboxpick-collect``."""

    repo_id: str = "local/lego_pick_expert"
    root: Path = Path("outputs/datasets/lego_pick_expert")
    # Comma-separated settings; episode seeds cycle through them
    # (the seed modulo their count picks the setting).
    settings: str = "grid_id"
    # Episodes to end up with in the dataset (kept ones).
    episodes: int = 50
    # Seed split the episodes come from (lerobot_bboxpick.seeds): "train" (0-4999) for demonstrations;
    # "validation" (5000-9999) or "test" (10000+) only when making an evaluation dataset.
    split: str = "train"
    # First seed; None starts at the split's first seed. Every seed used must lie in ``split``.
    seed_start: int | None = None
    workers: int = 1
    # Ray cluster the workers run on: "auto" (the one this machine joined with ray start),
    # "ray://<head>:10001" or "local" (a new Ray instance here); None: local processes. The shards are
    # written by the workers, so root must be on a file system every node shares (docs/ray.md).
    ray_address: str | None = None
    keep_failed: bool = False
    # Fraction of episodes that start with an unrecorded off-course lead-in and record the expert's
    # recovery from there (lerobot_bboxpick.data.recovery); 0: plain demos.
    recovery: float = 0.0
    # When the expert turns the gripper onto the brick: "early" (on the way, from the start) or "late"
    # (above the brick, where the wrist camera sees its yaw; lerobot_bboxpick.sim.expert).
    expert_turn: str = "early"
    resume: bool = False
    # Episodes per shard: the most work an interruption can lose.
    shard_size: int = SHARD_SIZE
    push_to_hub: bool = False
    # Where the workers' own output (the video encoder's log lines) goes; None: <root>.collect/workers.log.
    log_file: Path | None = None

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        self.log_file = Path(self.log_file) if self.log_file else self.work_dir / "workers.log"
        if not self.setting_list:
            raise ValueError(f"settings={self.settings!r} is empty; valid settings: {', '.join(SETTINGS)}")
        for name, minimum in (("episodes", 1), ("workers", 1), ("shard_size", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or value < minimum:
                raise ValueError(f"{name}={value!r} must be an integer >= {minimum}")
        if not 0.0 <= self.recovery <= 1.0:
            raise ValueError(f"recovery={self.recovery!r} must be a fraction in [0, 1]")
        if self.expert_turn not in TURNS:
            raise ValueError(f"expert_turn={self.expert_turn!r}: allowed values are {', '.join(TURNS)}")
        seeds.check_split(self.split)
        check_ray(self.ray_address)
        if self.seed_start is None:
            self.seed_start = seeds.SPLITS[self.split][0]
        # At least the first `episodes` seeds are used; more when the expert fails some.
        seeds.check_seeds_in_split(self.seed_start, self.seed_start + self.episodes - 1, self.split)

    @property
    def setting_list(self) -> tuple[str, ...]:
        """The settings named by ``settings``, validated."""
        return tuple(check_setting(s.strip()) for s in str(self.settings).split(",") if s.strip())

    @property
    def work_dir(self) -> Path:
        """Where the shards live (beside ``root``)."""
        return self.root.with_name(self.root.name + ".collect")

    def setting_of(self, seed: int) -> str:
        """The setting an episode seed is recorded in."""
        return self.setting_list[seed % len(self.setting_list)]


class EpisodeRecorder:
    """What a shard worker runs for each seed: ``bboxpick-collect``'s scripted expert, or a policy.

    A recorder goes to spawned worker processes, so it must pickle (a module-level dataclass does).
    """

    # Facts that decide the recorded episodes (e.g. a checkpoint's weights), written with every seed's
    # record in ``seeds.json`` so that a resumed run can refuse to mix two kinds; None: nothing to check.
    run_key: dict | None = None

    def make_env(self, setting: str) -> Any:
        """A new env of ``setting`` (one per setting and worker, reused for every seed)."""
        raise NotImplementedError

    def __call__(self, env: Any, seed: int) -> tuple[list[dict], str] | tuple[list[dict], str, dict]:
        """Record the episode of ``seed`` on ``env``: its ``make_frame`` dicts (none: nothing to keep)
        and its outcome, and optionally more facts for the seed's record in ``seeds.json``."""
        raise NotImplementedError


@dataclass(frozen=True)
class ExpertRecorder(EpisodeRecorder):
    """The scripted expert, run until its plan is done (it carries the brick away after the pick);
    ``turn``: when it turns the gripper onto the brick (``ScriptedExpert``)."""

    turn: str = "early"

    @property
    def run_key(self) -> dict | None:
        """Late-turn demos must not be mixed with early-turn ones (early: None, as before the option)."""
        return None if self.turn == "early" else {"expert_turn": self.turn}

    def make_env(self, setting: str) -> Any:
        """An env that keeps running after a lift, so the expert's plan completes."""
        from lerobot_bboxpick.sim.env import LegoPickEnv

        return LegoPickEnv(setting=setting, terminate_on_lift=False)

    def __call__(self, env: Any, seed: int) -> tuple[list[dict], str]:
        """``record_episode`` of the expert."""
        return record_episode(env, seed, turn=self.turn)


def expert_recorder(recovery: float, turn: str = "early") -> EpisodeRecorder:
    """The scripted expert's recorder: plain demos, or that fraction of recovery demos."""
    if recovery <= 0:
        return ExpertRecorder(turn=turn)
    from lerobot_bboxpick.data.recovery import RecoveryRecorder  # it builds on this module

    return RecoveryRecorder(turn=turn, fraction=recovery)


@dataclass(frozen=True)
class ShardTask:
    """One worker job: record ``seeds`` into ``path``."""

    path: Path
    seeds: tuple[int, ...]
    settings: tuple[str, ...]
    repo_id: str
    keep_failed: bool
    log_file: Path | None = None
    recorder: EpisodeRecorder = ExpertRecorder()


def step_frame(obs: dict, info: dict, action: np.ndarray, reward: float, next_info: dict) -> dict:
    """Frame ``t`` of an episode: the observation before step ``t`` (``obs``, ``info``), the action
    executed at step ``t``, and that step's reward and success (``next_info``). ``next.done`` and
    ``episode.outcome`` are set by ``close_episode`` once the episode is over."""
    return make_frame(
        obs["pixels"]["wrist"],
        obs["agent_pos"],
        obs["bbox"],
        action,
        info["task"],
        reward=reward,
        done=False,
        success=next_info["is_success"],
        seed=info["seed"],
        setting=info["setting"],
        target=info["target"],
    )


def close_episode(frames: list[dict], outcome: str) -> tuple[list[dict], str]:
    """Mark the last frame done and label every frame with the episode's ``outcome``; return both."""
    if not frames:
        raise ValueError("an episode needs at least one frame (one env step)")
    frames[-1]["next.done"][:] = True
    for f in frames:  # the outcome is known once the episode is over
        f[EPISODE_OUTCOME][:] = outcome_code(outcome)
    return frames, outcome


def record_episode(
    env, seed: int, rng_seed: int | None = None, options: dict | None = None, turn: str = "early"
) -> tuple[list[dict], str]:
    """Run the scripted expert on ``env`` for ``seed``; return the frames and the outcome.

    ``rng_seed`` seeds the expert's own variation (speed, approach offset); default: ``seed``.
    ``options`` go to ``env.reset`` (e.g. ``{"target": k}`` to designate another brick of the scene).
    ``turn``: when the expert turns the gripper onto the brick (``ScriptedExpert``).
    """
    from lerobot_bboxpick.sim.expert import ScriptedExpert

    obs, info = env.reset(seed=seed, options=options)
    expert = ScriptedExpert(np.random.default_rng(seed if rng_seed is None else rng_seed), turn=turn)
    expert.reset(env)
    return run_expert(env, obs, info, expert)


def run_expert(env, obs: dict, info: dict, expert: Any) -> tuple[list[dict], str]:
    """Record ``expert``'s plan (already made from the env's current state, whose observation is
    ``obs``/``info``) until it is done or the episode ends; return the frames and the outcome."""
    frames = []
    while not expert.done:
        action = expert.act()
        next_obs, reward, terminated, truncated, next_info = env.step(action)
        frames.append(step_frame(obs, info, action, reward, next_info))
        obs, info = next_obs, next_info
        if terminated or truncated:
            break
    return close_episode(frames, info["outcome"])


def record_shard(task: ShardTask) -> list[dict]:
    """Worker: record a shard with ``task.recorder``; returns one record per attempted seed."""

    import lerobot_bboxpick  # noqa: F401  (MUJOCO_GL before mujoco, in spawned workers too)

    if task.log_file is not None:
        redirect_native_output(task.log_file)

    partial = task.path.with_name(task.path.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    dataset = None
    envs: dict[str, Any] = {}
    records = []
    for seed, setting in zip(task.seeds, task.settings, strict=True):
        if setting not in envs:
            envs[setting] = task.recorder.make_env(setting)
        frames, outcome, *details = task.recorder(envs[setting], seed)
        kept = bool(frames) and (task.keep_failed or outcome == "pick")
        if kept:
            if dataset is None:
                dataset = create_dataset(task.repo_id, partial)
            for frame in frames:
                dataset.add_frame(frame)
            dataset.save_episode()
        record = {"seed": seed, "setting": setting, "outcome": outcome, "kept": kept, "frames": len(frames)}
        record.update(*details)
        if task.recorder.run_key is not None:
            record["run_key"] = task.recorder.run_key
        records.append(record)
    for env in envs.values():
        env.close()
    if dataset is not None:
        dataset.finalize()
    partial.mkdir(parents=True, exist_ok=True)
    (partial / "seeds.json").write_text(json.dumps(records, indent=1))
    partial.rename(task.path)  # the shard exists only once it is complete
    return records


def finished_shards(work_dir: Path) -> list[Path]:
    """Completed shard folders, in seed order (unfinished ``.partial`` ones are not listed)."""
    if not work_dir.exists():
        return []
    shards = [p for p in work_dir.iterdir() if p.is_dir() and not p.name.endswith(".partial")]
    return sorted(shards, key=lambda p: int(p.name.split("_")[1]))


def attempted(work_dir: Path) -> list[dict]:
    """Records of every seed attempted by finished shards."""
    return [r for shard in finished_shards(work_dir) for r in json.loads((shard / "seeds.json").read_text())]


def check_resumable(cfg: CollectConfig, key: dict | None) -> None:
    """Refuse to add episodes of another recorder (another checkpoint, options or recovery fraction) to
    shards already recorded: a dataset must not mix them unnoticed."""
    stale = [r for r in attempted(cfg.work_dir) if r.get("run_key") != key]
    if stale:
        raise ValueError(
            f"root={cfg.root}: {len(stale)} episodes in {cfg.work_dir} were recorded as "
            f"{stale[0].get('run_key', '(no run key: plain expert demos)')}, but this run is "
            f"{key if key is not None else '(no run key: plain expert demos)'}; choose another --root "
            "(or the same recorder and options)"
        )


def aggregate_roots(repo_id: str, roots: Sequence[Path], dest: Path) -> int:
    """LeRobot's ``aggregate_datasets`` of the datasets at ``roots`` (in that order) into ``dest``, built in
    a temporary folder and swapped in whole; returns the episode count."""
    from lerobot.datasets.aggregate import aggregate_datasets

    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    aggregate_datasets(
        repo_ids=[repo_id] * len(roots), roots=list(roots), aggr_repo_id=repo_id, aggr_root=tmp
    )
    old = dest.with_name(dest.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if dest.exists():
        dest.rename(old)
    tmp.rename(dest)
    shutil.rmtree(old, ignore_errors=True)
    info = json.loads((dest / "meta" / "info.json").read_text())
    return int(info["total_episodes"])


def aggregate(cfg: CollectConfig, merge_with: Sequence[Path] = ()) -> int:
    """Rebuild ``root`` from the datasets ``merge_with`` (first) and the finished shards with LeRobot's
    aggregation; returns the episode count."""
    shards = [s for s in finished_shards(cfg.work_dir) if (s / "meta" / "info.json").exists()]
    if not shards:
        raise RuntimeError(f"no episode was kept in {cfg.work_dir}; nothing to aggregate")
    return aggregate_roots(cfg.repo_id, [*merge_with, *shards], cfg.root)


def collect(
    cfg: CollectConfig, recorder: EpisodeRecorder | None = None, merge_with: Sequence[Path] = ()
) -> dict:
    """Collect until ``cfg.episodes`` episodes are kept; returns a summary.

    ``recorder`` records each seed (default: the scripted expert, with ``cfg.recovery`` of its episodes
    recovery demos, ``expert_recorder``); the datasets at
    ``merge_with`` are aggregated into ``root`` before the recorded episodes.
    """
    recorder = recorder or expert_recorder(cfg.recovery, cfg.expert_turn)
    if cfg.root.exists() and not cfg.resume:
        raise FileExistsError(
            f"root={cfg.root} already exists; pass --resume=true to continue that collection "
            "or choose another --root"
        )
    if cfg.work_dir.exists() and not cfg.resume:
        raise FileExistsError(
            f"{cfg.work_dir} holds shards of an interrupted collection; pass --resume=true to finish it"
        )
    cfg.work_dir.mkdir(parents=True, exist_ok=True)
    print(f"collect: workers' own output (video encoder) -> {cfg.log_file}", flush=True)
    for stale in cfg.work_dir.glob("*.partial"):  # an interrupted shard: redo it
        shutil.rmtree(stale)
    check_resumable(cfg, recorder.run_key)
    records = attempted(cfg.work_dir)
    kept = sum(r["kept"] for r in records)
    next_seed = max([cfg.seed_start - 1] + [r["seed"] for r in records]) + 1
    progress = tqdm(total=cfg.episodes, initial=min(kept, cfg.episodes), desc="episodes kept", unit="ep")
    # Fresh processes (spawned, or Ray's): each opens its own EGL context.
    with worker_pool(cfg.workers, cfg.ray_address) as pool:
        while kept < cfg.episodes:
            batch = list(range(next_seed, next_seed + cfg.episodes - kept))
            # Expert failures use up seeds: refuse to spill over into the next split.
            seeds.check_seeds_in_split(cfg.seed_start, batch[-1], cfg.split)
            next_seed += len(batch)
            tasks = [
                ShardTask(
                    path=cfg.work_dir / f"shard_{chunk[0]:08d}",
                    seeds=tuple(chunk),
                    settings=tuple(cfg.setting_of(s) for s in chunk),
                    repo_id=cfg.repo_id,
                    keep_failed=cfg.keep_failed,
                    log_file=cfg.log_file,
                    recorder=recorder,
                )
                for chunk in (batch[i : i + cfg.shard_size] for i in range(0, len(batch), cfg.shard_size))
            ]
            for shard_records in pool.imap_unordered(record_shard, tasks):
                records.extend(shard_records)
                n = sum(r["kept"] for r in shard_records)
                kept += n
                progress.update(n)
                progress.set_postfix(attempted=len(records))
    progress.close()
    quiet_libraries()
    cfg.log_file.parent.mkdir(parents=True, exist_ok=True)
    with native_output_to(cfg.log_file):  # LeRobot's copy bars, FFmpeg's muxer lines
        total = aggregate(cfg, merge_with)
    outcomes = {o: sum(r["outcome"] == o for r in records) for o in OUTCOMES}
    summary = {"root": str(cfg.root), "episodes": total, "attempted": len(records), "outcomes": outcomes}
    if cfg.push_to_hub:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        LeRobotDataset(cfg.repo_id, root=cfg.root).push_to_hub()
    return summary


@draccus.wrap()
def main(cfg: CollectConfig) -> None:
    """Entry point of ``bboxpick-collect``."""
    logging.basicConfig(level=logging.INFO)
    summary = collect(cfg)
    print(json.dumps(summary, indent=1))
