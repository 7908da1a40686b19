"""The canary: overfit a few expert episodes of ONE scene, then pick in closed loop there.

It proves the chain data -> relative poses -> chunk execution -> absolute actions before anyone
trains at scale (a peer team's policies stopped 30 cm short of the brick because of such a break).
With ``--targets 2`` the episodes alternate between two designated bricks of that one scene (the seed's
target and its grid neighbour): the first frames of both kinds of episode are the same image, so only
the bbox tells the policy where to go, and the checkpoint's target sensitivity means something (a
one-target checkpoint has no reason to read the bbox at all).

    python -m lerobot_bboxpick.apps.canary record --root outputs/canary/data --seed 0 --episodes 5
    lerobot-train ... (see examples/canary.sh)
    python -m lerobot_bboxpick.apps.canary evaluate \
        --policy outputs/canary/train/checkpoints/last/pretrained_model
    python -m lerobot_bboxpick.apps.canary sensitivity --policy <the same checkpoint>
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from tqdm import tqdm

REPO_ID = "local/canary"


def grid_neighbour(layout) -> int:
    """The brick beside ``layout.target`` in its grid row (7.5 cm away), to the right unless at the edge."""
    from lerobot_bboxpick.sim.layouts import GRID_COLS

    first = layout.target
    return first + 1 if (first % GRID_COLS) < GRID_COLS - 1 else first - 1


def canary_targets(seed: int, count: int, setting: str = "grid_id") -> list[int]:
    """The designated bricks of the canary's scene: the seed's target, then (count=2) its grid neighbour."""
    from lerobot_bboxpick.sim.layouts import make_layout, scene_rng

    if count not in (1, 2):
        raise ValueError(f"targets={count} must be 1 (the seed's target) or 2 (it and its grid neighbour)")
    layout = make_layout(setting, scene_rng(setting, seed))
    return [layout.target, grid_neighbour(layout)][:count]


def record(root: Path, seed: int, episodes: int, setting: str = "grid_id", targets: int = 1) -> Path:
    """``episodes`` expert demonstrations of the scene of ``seed`` (the expert's own variation differs),
    designating the ``canary_targets`` in turn."""

    from lerobot_bboxpick.data.collect import record_episode
    from lerobot_bboxpick.data.features import create_dataset
    from lerobot_bboxpick.sim.env import LegoPickEnv

    bricks = canary_targets(seed, targets, setting)
    env = LegoPickEnv(setting=setting, terminate_on_lift=False)
    dataset = create_dataset(REPO_ID, root)
    for k in tqdm(range(episodes), desc="canary demos", unit="ep"):
        target = bricks[k % len(bricks)]
        frames, outcome = record_episode(env, seed, rng_seed=1000 + k, options={"target": target})
        if outcome != "pick":
            raise RuntimeError(f"expert failed on seed {seed}, brick {target} (variation {k}): {outcome}")
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
    n_action_steps: int | None = None,
    targets: int = 1,
) -> list[dict]:
    """Closed-loop runs of a checkpoint on the scene of ``seed``, designating the ``canary_targets`` in
    turn (as ``record`` did); one record per run ("pick" means the designated brick was lifted)."""
    from lerobot_bboxpick.eval.rollout import PolicyRunner, rollout

    bricks = canary_targets(seed, targets, setting)
    runner = PolicyRunner.from_pretrained(policy_path, n_action_steps=n_action_steps)
    records = []
    for run in tqdm(range(runs), desc="canary runs", unit="run"):
        target = bricks[run % len(bricks)]
        result = rollout(
            runner,
            setting=setting,
            seed=seed,
            policy_seed=run,
            video_path=None if video_dir is None else video_dir / f"run{run}_brick{target}.mp4",
            options={"target": target},
        )
        records.append(result)  # its "target" is the designated brick
    return records


def target_sensitivity(policy_path: Path, seed: int, samples: int = 5, setting: str = "grid_id") -> dict:
    """Does the bbox steer the policy? Paint a neighbour of the target in the target's colour (two
    identical bricks), then predict the first chunk with the bbox on one brick and on the other.

    Returns, for each designated brick, the chunk end point's distance (m) to both bricks, averaged
    over ``samples`` policy seeds, and ``shift_toward_new_box_m``: how far the end point moved toward the
    second brick when the bbox moved to it (the move projected on the first-to-second brick direction;
    > 0 means the bbox steers the policy).
    """
    import torch

    from lerobot_bboxpick.eval.rollout import PolicyRunner
    from lerobot_bboxpick.sim.env import LegoPickEnv
    from lerobot_bboxpick.sim.layouts import Layout, make_layout, scene_rng

    runner = PolicyRunner.from_pretrained(policy_path)
    layout = make_layout(setting, scene_rng(setting, seed))
    first, second = layout.target, grid_neighbour(layout)
    colors = list(layout.colors)
    colors[second] = colors[first]
    twins = Layout(layout.setting, layout.positions, layout.yaws, tuple(colors), first)
    env = LegoPickEnv(setting=setting)
    result = {"bricks": [first, second]}
    for designated in (first, second):
        ends = []
        for k in range(samples):
            obs, info = env.reset(seed=seed, options={"layout": twins, "target": designated})
            runner.reset()
            torch.manual_seed(k)
            batch = runner.observation_batch(obs, info["task"])
            stacked = {
                key: value[:, None].repeat_interleave(runner.policy.config.n_obs_steps, dim=1)
                for key, value in batch.items()
                if key in runner.policy._queues
            }
            chunk = runner.policy.predict_action_chunk(stacked)  # absolute poses
            ends.append(chunk[0, -1, :3].numpy())
        end = np.mean(ends, axis=0)
        result[f"bbox_on_{designated}"] = {
            "end_point": end.round(4).tolist(),
            f"distance_to_{first}_m": float(np.linalg.norm(end[:2] - env.brick_pose(first)[:2, 3])),
            f"distance_to_{second}_m": float(np.linalg.norm(end[:2] - env.brick_pose(second)[:2, 3])),
        }
    ends_xy = [np.array(result[f"bbox_on_{b}"]["end_point"][:2]) for b in (first, second)]
    direction = env.brick_pose(second)[:2, 3] - env.brick_pose(first)[:2, 3]
    result["shift_toward_new_box_m"] = float(
        (ends_xy[1] - ends_xy[0]) @ direction / np.linalg.norm(direction)
    )
    env.close()
    return result


def main(argv: list[str] | None = None) -> None:
    """``python -m lerobot_bboxpick.apps.canary record|evaluate``."""
    parser = argparse.ArgumentParser(
        prog="lerobot_bboxpick.apps.canary",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("--root", type=Path, required=True)
    rec.add_argument("--seed", type=int, default=0)
    rec.add_argument("--episodes", type=int, default=5)
    rec.add_argument("--targets", type=int, default=1, choices=(1, 2), help="designated bricks, in turn")
    ev = sub.add_parser("evaluate")
    ev.add_argument("--policy", type=Path, required=True)
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument("--runs", type=int, default=5)
    ev.add_argument("--video-dir", type=Path, default=None)
    ev.add_argument("--n-action-steps", type=int, default=None, help="override the checkpoint's value")
    ev.add_argument("--targets", type=int, default=1, choices=(1, 2), help="designated bricks, in turn")
    sens = sub.add_parser("sensitivity")
    sens.add_argument("--policy", type=Path, required=True)
    sens.add_argument("--seed", type=int, nargs="+", default=[0], help="one or more scenes")
    args = parser.parse_args(argv)
    if args.command == "record":
        print(record(args.root, args.seed, args.episodes, targets=args.targets))
    elif args.command == "sensitivity":
        shifts = []
        for seed in args.seed:
            result = target_sensitivity(args.policy, seed)
            print(json.dumps({"seed": seed, **result}), flush=True)
            shifts.append(result["shift_toward_new_box_m"])
        print(
            f"end point shift toward the new box: mean {np.mean(shifts) * 1000:.1f} mm, "
            f"positive in {sum(s > 0 for s in shifts)}/{len(shifts)} scenes"
        )
    else:
        records = evaluate(
            args.policy,
            args.seed,
            args.runs,
            video_dir=args.video_dir,
            n_action_steps=args.n_action_steps,
            targets=args.targets,
        )
        print(json.dumps(records, indent=1))
        print(f"picks: {sum(r['outcome'] == 'pick' for r in records)}/{len(records)}")


if __name__ == "__main__":
    main()
