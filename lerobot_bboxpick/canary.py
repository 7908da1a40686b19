"""The canary (issue 4): overfit a few expert episodes of ONE scene, then pick in closed loop there.

It proves the chain data -> relative poses -> chunk execution -> absolute actions before anyone
trains at scale (a peer team's policies stopped 30 cm short of the brick because of such a break).

    python -m lerobot_bboxpick.canary record --root outputs/canary/data --seed 0 --episodes 5
    lerobot-train ... (see examples/canary.sh)
    python -m lerobot_bboxpick.canary evaluate --policy outputs/canary/train/checkpoints/last/pretrained_model
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from tqdm import tqdm

REPO_ID = "local/canary"


def record(root: Path, seed: int, episodes: int, setting: str = "grid_id") -> Path:
    """``episodes`` expert demonstrations of the scene of ``seed`` (the expert's own variation differs)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_bboxpick.data.collect import record_episode
    from lerobot_bboxpick.data.features import FPS, ROBOT_TYPE, dataset_features
    from lerobot_bboxpick.sim.env import LegoPickEnv

    env = LegoPickEnv(setting=setting, terminate_on_lift=False)
    dataset = LeRobotDataset.create(REPO_ID, FPS, dataset_features(), root=root, robot_type=ROBOT_TYPE)
    for k in tqdm(range(episodes), desc="canary demos", unit="ep"):
        frames, outcome = record_episode(env, seed, rng_seed=1000 + k)
        if outcome != "pick":
            raise RuntimeError(f"expert failed on seed {seed} (variation {k}): {outcome}")
        for frame in frames:
            dataset.add_frame(frame)
        dataset.save_episode()
    dataset.finalize()
    env.close()
    return root


def evaluate(
    policy_path: Path,
    seed: int,
    runs: int,
    setting: str = "grid_id",
    video_dir: Path | None = None,
    bbox_override: np.ndarray | None = None,
) -> list[dict]:
    """Closed-loop runs of a checkpoint on the scene of ``seed``; one record per run."""
    from lerobot_bboxpick.eval.rollout import PolicyRunner, rollout

    runner = PolicyRunner.from_pretrained(policy_path)
    records = []
    for run in tqdm(range(runs), desc="canary runs", unit="run"):
        result = rollout(
            runner,
            setting=setting,
            seed=seed,
            policy_seed=run,
            video_path=None if video_dir is None else video_dir / f"run{run}.mp4",
        )
        records.append(result)
    return records


def main(argv: list[str] | None = None) -> None:
    """``python -m lerobot_bboxpick.canary record|evaluate``."""
    parser = argparse.ArgumentParser(
        prog="lerobot_bboxpick.canary",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("--root", type=Path, required=True)
    rec.add_argument("--seed", type=int, default=0)
    rec.add_argument("--episodes", type=int, default=5)
    ev = sub.add_parser("evaluate")
    ev.add_argument("--policy", type=Path, required=True)
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument("--runs", type=int, default=5)
    ev.add_argument("--video-dir", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.command == "record":
        print(record(args.root, args.seed, args.episodes))
    else:
        records = evaluate(args.policy, args.seed, args.runs, video_dir=args.video_dir)
        print(json.dumps(records, indent=1))
        print(f"picks: {sum(r['outcome'] == 'pick' for r in records)}/{len(records)}")


if __name__ == "__main__":
    main()
