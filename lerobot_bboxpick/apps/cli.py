"""The ``lerobot_bboxpick`` command: ``run`` (the main job: collect -> train -> suite), ``demo`` (expert
rollouts), ``bench``, ``sheet`` (settings picture, or the policy's inputs), ``trace`` (where a policy
closes the gripper, relative to its target), ``turn-fit`` (how much of the demos' turn a policy
reproduces on their own frames)."""

from __future__ import annotations

import argparse
from pathlib import Path

from lerobot_bboxpick.sim.layouts import SETTINGS, check_setting


def _settings(text: str) -> tuple[str, ...]:
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    try:
        return tuple(check_setting(s) for s in names)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _seeds(text: str) -> list[int]:
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not comma-separated integers") from None
    if not seeds:
        raise argparse.ArgumentTypeError("give at least one seed")
    return seeds


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``lerobot_bboxpick`` console script."""
    parser = argparse.ArgumentParser(prog="lerobot_bboxpick", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="the main job: collect expert demos, lerobot-train, bboxpick-suite")
    run.add_argument(
        "--profile",
        choices=("quick", "full", "practical"),
        default="quick",
        help="quick: the 15-minute first run; full: the paper protocol (grid demos); practical: every layout",
    )
    run.add_argument("--out-dir", type=Path, default=Path("outputs/main"))
    run.add_argument("--bbox-mode", choices=("mask", "lowdim", "none"), default="mask", help="ablations")
    run.add_argument(
        "--amp",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="train under bf16 autocast (lerobot-train --policy.use_amp); default: the profile's choice",
    )
    run.add_argument(
        "--train-seed",
        type=int,
        default=None,
        help="lerobot-train's --seed (default: the profile's, 1000); repeat a recipe with another seed",
    )
    demo = sub.add_parser("demo", help="scripted-expert rollouts per setting: MP4s, contact sheet, table")
    demo.add_argument("--out-dir", type=Path, default=Path("outputs/demo"))
    demo.add_argument("--episodes", type=_positive, default=1, help="episodes per setting")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--settings", type=_settings, default=SETTINGS, help="comma-separated settings")
    bench = sub.add_parser("bench", help="env steps/s per setting next to the bare render rate")
    bench.add_argument("--steps", type=_positive, default=120)
    bench.add_argument("--settings", type=_settings, default=SETTINGS)
    bench.add_argument("--out", type=Path, default=Path("outputs/bench/env.md"))
    bench.add_argument("--policies", action="store_true", help="also time bbox_diffusion and stock diffusion")
    bench.add_argument(
        "--policy-steps", type=_positive, default=8, help="timed training steps per policy for --policies"
    )
    bench.add_argument(
        "--collect", action="store_true", help="also time bboxpick-collect with 1 and 2 workers"
    )
    bench.add_argument("--suite", action="store_true", help="also time bboxpick-suite on a CPU-preset policy")
    bench.add_argument(
        "--inference", action="store_true", help="also time the inference levers (ms per chunk) side by side"
    )
    bench.add_argument(
        "--training", action="store_true", help="also time the training levers and the data loader"
    )
    bench.add_argument(
        "--threads", type=_positive, default=None, help="torch threads for --inference (default: torch's)"
    )
    bench.add_argument(
        "--all", action="store_true", help="--policies --training --inference --collect --suite"
    )
    sheet = sub.add_parser("sheet", help="PNG contact sheet of the six settings' first wrist frames")
    sheet.add_argument("--out", type=Path, default=None, help="default: examples/<sheet name>.png")
    sheet.add_argument("--seed", type=int, default=0)
    sheet.add_argument(
        "--inputs",
        action="store_true",
        help="instead: what the policy sees per setting (frame, 64 px policy image, 48 px target view)",
    )
    trace = sub.add_parser(
        "trace", help="per episode: where the gripper closes relative to the target (mm, deg)"
    )
    trace.add_argument("--policy", required=True, help="a checkpoint folder (pretrained_model) or 'expert'")
    trace.add_argument("--setting", type=lambda text: _settings(text)[0], default="random_id")
    trace.add_argument("--seeds", type=_seeds, required=True, help="comma-separated scene seeds")
    trace.add_argument(
        "--num-inference-steps", type=_positive, default=None, help="default: the checkpoint's"
    )
    trace.add_argument("--out", type=Path, default=None, help="also write the markdown table here")
    turn_fit = sub.add_parser(
        "turn-fit", help="teacher forcing: how much of the demos' turn the policy's chunk reproduces"
    )
    turn_fit.add_argument("--policy", required=True, help="a checkpoint folder (pretrained_model)")
    turn_fit.add_argument("--dataset", type=Path, required=True, help="a LeRobotDataset root (its demos)")
    turn_fit.add_argument("--settings", type=_settings, default=_settings("random_id,pile_id"))
    turn_fit.add_argument(
        "--frames", type=_seeds, default=[0, 16, 32], help="comma-separated frame offsets into each episode"
    )
    turn_fit.add_argument(
        "--num-inference-steps", type=_positive, default=None, help="default: the checkpoint's"
    )
    turn_fit.add_argument("--out", type=Path, default=None, help="also write the markdown table here")
    args = parser.parse_args(argv)

    if args.command == "run":
        from lerobot_bboxpick.apps.main_job import run_pipeline, what_next

        overrides = {"bbox_mode": args.bbox_mode}
        if args.amp is not None:
            overrides["use_amp"] = args.amp
        if args.train_seed is not None:
            overrides["train_seed"] = args.train_seed
        table = run_pipeline(args.profile, args.out_dir, **overrides)
        print(table.read_text())
        print(what_next(table, table.parent.parent / "train" / "checkpoints" / "last" / "pretrained_model"))
    elif args.command == "demo":
        from lerobot_bboxpick.apps.demo import run_demo

        table = run_demo(args.out_dir, episodes=args.episodes, seed=args.seed, settings=args.settings)
        print(table.read_text())
        print(f"videos, contact sheet and tables in {args.out_dir.resolve()}")
    elif args.command == "bench":
        from lerobot_bboxpick.apps.bench import bench_table

        table = bench_table(args.settings, steps=args.steps)
        if args.all:
            args.policies = args.training = args.inference = args.collect = args.suite = True
        if args.policies:
            from lerobot_bboxpick.apps.bench import bench_policies

            table += "\n\n" + bench_policies(training_steps=args.policy_steps)
        if args.training:
            from lerobot_bboxpick.apps.bench import bench_training_levers

            table += "\n\n" + bench_training_levers()
        if args.inference:
            from lerobot_bboxpick.apps.bench import bench_inference_levers

            table += "\n\n" + bench_inference_levers(threads=args.threads)
        if args.collect:
            from lerobot_bboxpick.apps.bench import bench_collect

            table += "\n\n" + bench_collect()
        if args.suite:
            from lerobot_bboxpick.apps.bench import bench_suite

            table += "\n\n" + bench_suite()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(table + "\n")
        print(table)
    elif args.command == "trace":
        from lerobot_bboxpick.eval.trace import run_trace, write_trace

        write_trace(run_trace(args.policy, args.setting, args.seeds, args.num_inference_steps), args.out)
    elif args.command == "turn-fit":
        from lerobot_bboxpick.eval.trace import write_trace
        from lerobot_bboxpick.eval.turn_fit import run_turn_fit

        table = run_turn_fit(args.policy, args.dataset, args.settings, args.frames, args.num_inference_steps)
        write_trace(table, args.out)
    else:
        from lerobot_bboxpick.apps.demo import inputs_sheet, settings_sheet
        from lerobot_bboxpick.viz import save_png

        if args.inputs:
            out, picture = Path("examples/policy_inputs_sheet.png"), inputs_sheet(seed=args.seed)
        else:
            out, picture = Path("examples/settings_contact_sheet.png"), settings_sheet(seed=args.seed)
        print(save_png(args.out or out, picture))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
