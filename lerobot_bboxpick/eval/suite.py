"""``bboxpick-suite``: matched-scene evaluation of policies (paper section 5.2, table 3).

    bboxpick-suite --policies=expert,outputs/train/checkpoints/last/pretrained_model \
        --settings=grid_id,identical_4 --episodes=30 --workers=2 --out_dir=outputs/suite
    bboxpick-suite ... --workers=32 --ray_address=auto   # episodes on a Ray cluster (docs/ray.md)

Every policy meets the same scenes: episode ``k`` of a setting resets the env with seed
``seed_start + k`` (test seeds >= 10000 by default, ``lerobot_bboxpick.seeds``; validation seeds
5000-9999 for choosing recipes; a suite on training seeds is warned about), and the policy's own noise
is seeded from the same number, so re-running a suite reproduces its scenes and, for a deterministic
policy, its outcomes. ``--bbox_source`` decides the box the policy sees: ``oracle`` (the simulator's),
``noisy`` (a person's, IoU ``--noisy_iou`` to the oracle box) or ``tracked`` (the first frame's box,
then the tracker). Episodes run in worker processes (each loads a policy once and keeps one env per
setting); results stream into ``episodes.jsonl`` as they finish, so an interrupted suite resumes where it
stopped. Every episode carries the run key of its policy: a digest of the checkpoint's weights and the
options that change behaviour (executed steps per chunk, max steps, bbox source); a re-run whose key
differs from the episodes already in ``out_dir`` is refused (``--fresh=true`` moves them aside and starts
over), so a table never mixes checkpoints. Written into ``out_dir``:

* ``episodes.jsonl``: one line per episode (policy, setting, seed, scene, target, outcome, steps, distance)
* ``table.md`` / ``table.csv``: Pick / Wrong / Contact / Empty per policy and setting, Wilson 95% intervals
* ``outcomes.png``: grouped bars of the same, with the intervals as error bars
* ``videos/<policy>/<setting>_seed<seed>.mp4``: the first ``videos`` episodes per setting, bbox drawn
"""

import contextlib
import csv
import hashlib
import io
import json
import logging
import math
import multiprocessing as mp
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import draccus
import numpy as np
from tqdm import tqdm

from lerobot_bboxpick import seeds
from lerobot_bboxpick.eval.bbox_source import DEFAULT_NOISY_IOU, check_bbox_source
from lerobot_bboxpick.parallel import check_ray, worker_pool
from lerobot_bboxpick.sim.layouts import SETTINGS, check_setting
from lerobot_bboxpick.sim.outcome import OUTCOMES
from lerobot_bboxpick.viz import THUMBNAIL_PX, outcome_bars, outcome_sheet, save_png

EXPERT = "expert"
log = logging.getLogger(__name__)


@dataclass
class SuiteConfig:
    """Options of ``bboxpick-suite``."""

    # Comma-separated policies: "expert" (the scripted upper bound) or checkpoint folders
    # (``.../pretrained_model``); "name=path" sets the row label.
    policies: str = EXPERT
    settings: str = ",".join(SETTINGS)
    episodes: int = 30
    # First episode seed: test seeds (10000+) for reported tables, validation seeds (5000-9999) for
    # choosing a recipe.
    seed_start: int = seeds.TEST_START
    workers: int = 2
    # Ray cluster the workers run on: "auto" (the one this machine joined with ray start),
    # "ray://<head>:10001" or "local" (a new Ray instance here); None: local processes. Checkpoints and
    # out_dir (videos) must be on a file system every node shares (docs/ray.md).
    ray_address: str | None = None
    # Rollout videos kept per policy and setting (the first seeds).
    videos: int = 2
    max_steps: int = 300
    # Executed steps per predicted chunk; None keeps each checkpoint's own setting.
    n_action_steps: int | None = None
    # Denoising steps per chunk instead of the checkpoint's (an inference-speed lever, docs/benchmarks.md).
    num_inference_steps: int | None = None
    # The policy's noise draws in an episode start at its seed + this offset (the scene stays the seed's):
    # a second run with another offset shows how many outcomes the sampling noise alone changes.
    policy_seed_offset: int = 0
    # Run bbox_diffusion UNets through ONNX Runtime (the onnx extra): the same chunks to < 1e-4, less time
    # per chunk on a CPU (docs/benchmarks.md).
    onnx_inference: bool = False
    # Q-reranking (paper section 4.2): every chunk is the argmax-Q of rerank_samples chunks the policy
    # draws, scored by this critic checkpoint (bboxpick-train-critic / bboxpick-train-mc-critic).
    critic_path: Path | None = None
    rerank_samples: int = 8
    # Bounded residuals added to every draw before reranking, <axis>:<amount> tried with + and - (e.g.
    # "yaw:0.35,x:0.03"; rl.chunk_perturbations); empty: the policy's draws only.
    rerank_perturbations: str = ""
    # Q-guided diffusion (paper section 4.2): with guidance_scale > 0 every draw is steered by the
    # critic's action gradient, at most guidance_max_step (scaled action units) per denoising step
    # (rl.q_guidance). With rerank_samples=1 the guided draw is executed as is.
    guidance_scale: float = 0.0
    guidance_max_step: float = 0.02
    # The bbox the policy sees: oracle, noisy or tracked (see the module docstring).
    bbox_source: str = "oracle"
    # Target IoU of the noisy bbox with the oracle one.
    noisy_iou: float = DEFAULT_NOISY_IOU
    out_dir: Path = Path("outputs/suite")
    # Keep episodes already in out_dir/episodes.jsonl (same policy label, setting, seed and run key).
    resume: bool = True
    # Move episodes of another run key (other weights or options) aside instead of refusing to run.
    fresh: bool = False

    def __post_init__(self) -> None:
        self.out_dir = Path(self.out_dir)
        self.critic_path = Path(self.critic_path) if self.critic_path is not None else None
        if self.critic_path is not None and not (self.critic_path / "config.json").is_file():
            raise ValueError(
                f"critic_path={self.critic_path} is not a critic checkpoint folder (no config.json)"
            )
        for name, minimum in (
            ("episodes", 1),
            ("workers", 1),
            ("max_steps", 1),
            ("videos", 0),
            ("rerank_samples", 1),
        ):
            value = getattr(self, name)
            if not isinstance(value, int) or value < minimum:
                raise ValueError(f"{name}={value!r} must be an integer >= {minimum}")
        if not isinstance(self.policy_seed_offset, int) or not 0 <= self.policy_seed_offset < 2**31 - 100_000:
            raise ValueError(
                f"policy_seed_offset={self.policy_seed_offset!r} must be an integer in [0, 2**31 - 100000)"
            )
        for name in ("n_action_steps", "num_inference_steps"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, int) or value < 1):
                raise ValueError(f"{name}={value!r} must be an integer >= 1 (or unset: the checkpoint's)")
        if self.rerank_perturbations:
            from lerobot_bboxpick.rl.chunk_perturbations import parse_perturbations

            parse_perturbations(self.rerank_perturbations, "rerank_perturbations")
        if self.guidance_scale < 0 or not 0 < self.guidance_max_step <= 1:
            raise ValueError(
                f"guidance_scale={self.guidance_scale!r} must be >= 0 and guidance_max_step="
                f"{self.guidance_max_step!r} in (0, 1]"
            )
        if self.guidance_scale > 0 and self.critic_path is None:
            raise ValueError("guidance_scale > 0 needs critic_path (the critic whose gradient guides)")
        check_bbox_source(self.bbox_source)
        check_ray(self.ray_address)
        if self.onnx_inference:  # before any worker starts: the missing extra named once
            from lerobot_bboxpick.policies.bbox_diffusion.onnx_runtime import require_onnxruntime

            require_onnxruntime()
        if not 0.0 < self.noisy_iou <= 1.0:
            raise ValueError(f"noisy_iou={self.noisy_iou!r} must be in (0, 1]")
        if not isinstance(self.seed_start, int) or self.seed_start < 0:
            raise ValueError(f"seed_start={self.seed_start!r} must be an integer >= 0")
        if not self.setting_list:
            raise ValueError(f"settings={self.settings!r} is empty; valid settings: {', '.join(SETTINGS)}")
        labels = [label for label, _ in self.policy_list]
        if not labels:
            raise ValueError("policies is empty; give 'expert' and/or checkpoint folders")
        if len(set(labels)) != len(labels):
            raise ValueError(f"policies have duplicate labels {labels}; name them with label=path")
        for label, path in self.policy_list:
            if path != EXPERT and not (Path(path) / "config.json").is_file():
                raise ValueError(
                    f"policies: {label}={path} is neither 'expert' nor a checkpoint folder with config.json"
                )

    @property
    def setting_list(self) -> tuple[str, ...]:
        """The settings named by ``settings``, validated."""
        return tuple(check_setting(s.strip()) for s in str(self.settings).split(",") if s.strip())

    @property
    def policy_list(self) -> list[tuple[str, str]]:
        """(label, path or 'expert') for each entry of ``policies``."""
        out = []
        for entry in (e.strip() for e in str(self.policies).split(",") if e.strip()):
            label, _, path = entry.rpartition("=") if "=" in entry else ("", "", entry)
            out.append((label or policy_label(path), path))
        return out


def weights_digest(path: str) -> str:
    """sha256 (16 hex digits) of a checkpoint's weight files, or ``"expert"``."""
    if path == EXPERT:
        return EXPERT
    digest = hashlib.sha256()
    files = sorted(Path(path).glob("*.safetensors"))
    if not files:
        raise ValueError(f"policies: {path} holds no *.safetensors weights")
    for file in files:
        with open(file, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()[:16]


def run_key(cfg: SuiteConfig, path: str) -> dict:
    """What decides a policy's episodes: its weights and the options that change its behaviour."""
    key: dict[str, Any] = {"weights": weights_digest(path), "max_steps": cfg.max_steps}
    key["bbox_source"] = cfg.bbox_source
    if cfg.bbox_source == "noisy":
        key["noisy_iou"] = cfg.noisy_iou
    if path != EXPERT:
        own = json.loads((Path(path) / "config.json").read_text()).get("n_action_steps")
        key["n_action_steps"] = cfg.n_action_steps if cfg.n_action_steps is not None else own
        if cfg.num_inference_steps is not None:  # absent otherwise: older tables' run keys stay valid
            key["num_inference_steps"] = cfg.num_inference_steps
        if cfg.policy_seed_offset:  # likewise
            key["policy_seed_offset"] = cfg.policy_seed_offset
        if cfg.onnx_inference:  # likewise; float rounding may still tip a rare outcome
            key["onnx_inference"] = True
        critic = critic_options(cfg)
        if critic is not None:
            key["critic"] = weights_digest(critic.pop("critic_path"))
            key.update({k: v for k, v in critic.items() if v})  # unset options: older run keys stay valid
    return key


def critic_options(cfg: SuiteConfig) -> dict | None:
    """How the critic is used (``load_runner``'s ``critic``), or None without ``critic_path``."""
    if cfg.critic_path is None:
        return None
    options = {
        "critic_path": str(cfg.critic_path),
        "rerank_samples": cfg.rerank_samples,
        "rerank_perturbations": cfg.rerank_perturbations,
        "guidance_scale": cfg.guidance_scale,
    }
    if cfg.guidance_scale > 0:
        options["guidance_max_step"] = cfg.guidance_max_step
    return options


def policy_label(path: str) -> str:
    """A short row label: ``.../<run>/checkpoints/<step>/pretrained_model`` -> ``<run>@<step>``."""
    if path == EXPERT:
        return EXPERT
    parts = Path(path).resolve().parts
    if "checkpoints" in parts:
        i = parts.index("checkpoints")
        return f"{parts[i - 1]}@{parts[i + 1]}"
    return Path(path).name


def scene_fingerprint(layout: Any) -> str:
    """A short hash of a scene (brick positions, yaws, colours, target): equal scenes, equal hash."""
    payload = json.dumps(
        [np.round(layout.positions, 5).tolist(), np.round(layout.yaws, 5).tolist(), list(layout.colors)]
        + [int(layout.target)]
    )
    return hashlib.sha1(payload.encode()).hexdigest()[:12]


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95% for z = 1.96)."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1 + z**2 / n
    centre = (p + z**2 / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


# ---------------------------------------------------------------- worker side
# Per worker process: the loaded checkpoint (one at a time) and one env per setting, reused across episodes.
_POLICIES: dict[tuple, Any] = {}
_ENVS: dict[tuple[str, int], Any] = {}


def load_runner(
    path: str,
    n_action_steps: int | None,
    env: Any,
    num_inference_steps: int | None = None,
    critic: dict | None = None,
    onnx_inference: bool = False,
) -> Any:
    """The runner of ``path`` (``expert`` or a checkpoint), loaded once per worker process and kept;
    with ``critic`` (``critic_options``) its chunks are Q-reranked among ``rerank_samples`` draws (and
    their ``rerank_perturbations`` residuals), each Q-guided when ``guidance_scale`` > 0."""
    from lerobot_bboxpick.eval.rollout import ExpertRunner, PolicyRunner

    if path == EXPERT:
        return ExpertRunner(env)
    key = (path, n_action_steps, num_inference_steps, json.dumps(critic, sort_keys=True), onnx_inference)
    if key not in _POLICIES:
        _POLICIES.clear()  # one checkpoint in memory per worker at a time
        with contextlib.redirect_stdout(io.StringIO()):  # LeRobot prints "Loading weights ..." per load
            runner = PolicyRunner.from_pretrained(
                path,
                n_action_steps=n_action_steps,
                num_inference_steps=num_inference_steps,
                onnx_inference=onnx_inference,
            )
        if critic is not None:
            if not hasattr(runner.policy, "chunk_selector"):
                raise ValueError(
                    f"critic_path: policy {path} ({runner.policy.name}) cannot rerank its chunks"
                )
            runner.policy.chunk_selector = critic_selector(**critic)
        _POLICIES[key] = runner
    return _POLICIES[key]


def critic_selector(
    critic_path: str,
    rerank_samples: int = 1,
    rerank_perturbations: str = "",
    guidance_scale: float = 0.0,
    guidance_max_step: float = 0.02,
) -> Any:
    """The chunk selector that uses the critic at ``critic_path`` as ``critic_options`` says."""
    from lerobot_bboxpick.rl.chunk_perturbations import parse_perturbations
    from lerobot_bboxpick.rl.modeling_iql_critic import IqlCriticModel
    from lerobot_bboxpick.rl.q_guidance import QGuidance
    from lerobot_bboxpick.rl.rerank import QRerankSelector

    model = IqlCriticModel.from_pretrained(critic_path)
    guidance = QGuidance(model, guidance_scale, guidance_max_step) if guidance_scale > 0 else None
    perturbations = parse_perturbations(rerank_perturbations, "rerank_perturbations")
    return QRerankSelector(model, rerank_samples, perturbations, guidance)


def _env(setting: str, max_steps: int) -> Any:
    from lerobot_bboxpick.sim.env import LegoPickEnv

    if (setting, max_steps) not in _ENVS:
        _ENVS[(setting, max_steps)] = LegoPickEnv(setting=setting, episode_length=max_steps)
    return _ENVS[(setting, max_steps)]


def run_episode(task: dict) -> dict:
    """One suite episode (runs in a worker): ``task`` holds label, path, setting, seed and options."""
    import torch

    from lerobot_bboxpick.eval.rollout import rollout

    torch.set_num_threads(task.get("threads", 1))
    from lerobot_bboxpick.eval.bbox_source import BboxSource

    env = _env(task["setting"], task["max_steps"])
    runner = load_runner(
        task["path"],
        task.get("n_action_steps"),
        env,
        task.get("num_inference_steps"),
        task.get("critic"),
        task.get("onnx_inference", False),
    )
    video = Path(task["video"]) if task.get("video") else None
    seed = task["seed"]
    source = BboxSource(task["run_key"]["bbox_source"], task["run_key"].get("noisy_iou", DEFAULT_NOISY_IOU))
    t0 = time.perf_counter()
    result = rollout(
        runner,
        setting=task["setting"],
        seed=seed,
        policy_seed=seed + task.get("policy_seed_offset", 0),
        video_path=video,
        env=env,
        bbox_source=source,
    )
    if task.get("frame"):  # the last wrist frame, for the outcome sheet
        save_png(
            task["frame"],
            cv2.resize(env.render(), (THUMBNAIL_PX, THUMBNAIL_PX), interpolation=cv2.INTER_AREA),
        )
    return {
        "policy": task["label"],
        "path": task["path"],
        "run_key": task["run_key"],
        "scene": scene_fingerprint(env.layout),
        **result,
        "seconds": round(time.perf_counter() - t0, 2),  # wall time in the worker (video writing included)
    }


# ---------------------------------------------------------------- parent side
def _tasks(cfg: SuiteConfig, done: set[tuple[str, str, int]], keys: dict[str, dict]) -> list[dict]:
    threads = max(1, (mp.cpu_count() or 1) // cfg.workers)
    tasks = []
    for label, path in cfg.policy_list:
        for setting in cfg.setting_list:
            for k in range(cfg.episodes):
                seed = cfg.seed_start + k
                if (label, setting, seed) in done:
                    continue
                video = cfg.out_dir / "videos" / label / f"{setting}_seed{seed}.mp4"
                tasks.append(
                    {
                        "label": label,
                        "path": path,
                        "setting": setting,
                        "seed": seed,
                        "max_steps": cfg.max_steps,
                        "n_action_steps": cfg.n_action_steps,
                        "num_inference_steps": cfg.num_inference_steps,
                        "policy_seed_offset": cfg.policy_seed_offset,
                        "onnx_inference": cfg.onnx_inference,
                        "critic": critic_options(cfg),
                        "run_key": keys[label],
                        "video": str(video) if k < cfg.videos else None,
                        "frame": str(frame_path(cfg.out_dir, label, setting, seed)),
                        "threads": threads,
                    }
                )
    return tasks


def frame_path(out_dir: Path, label: str, setting: str, seed: int) -> Path:
    """Where an episode's final-frame thumbnail is kept."""
    return out_dir / "frames" / label / f"{setting}_seed{seed}.png"


def write_outcome_sheets(records: list[dict], out_dir: Path, policies: list[str]) -> list[Path]:
    """``outcomes_<policy>.png`` per policy: every episode's last wrist frame, labelled with its seed and
    outcome and framed in the outcome's colour, ordered by setting name then seed (episodes without a
    thumbnail are left out)."""
    paths = []
    for policy in policies:
        tiles = []
        for r in sorted(
            (r for r in records if r["policy"] == policy), key=lambda r: (r["setting"], r["seed"])
        ):
            thumb = frame_path(out_dir, policy, r["setting"], r["seed"])
            if thumb.exists():
                image = cv2.cvtColor(cv2.imread(str(thumb)), cv2.COLOR_BGR2RGB)
                tiles.append((image, f"{r['seed']} {r['outcome']}", r["outcome"]))
        if tiles:
            paths.append(save_png(out_dir / f"outcomes_{policy}.png", outcome_sheet(tiles)))
    return paths


def read_episodes(path: Path) -> list[dict]:
    """The records of an ``episodes.jsonl`` (a torn last line from a kill is ignored)."""
    if not path.exists():
        return []
    records = []
    for line in path.read_text().splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            log.warning("ignoring a torn line in %s", path)
    return records


def run_suite(cfg: SuiteConfig) -> Path:
    """Run (or resume) the suite; write table, chart and JSONL into ``cfg.out_dir``; return table.md."""
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    jsonl = cfg.out_dir / "episodes.jsonl"
    wanted = {
        (label, s, cfg.seed_start + k)
        for label, _ in cfg.policy_list
        for s in cfg.setting_list
        for k in range(cfg.episodes)
    }
    seeds.warn_unless_held_out(cfg.seed_start, cfg.seed_start + cfg.episodes - 1, "bboxpick-suite")
    keys = {label: run_key(cfg, path) for label, path in cfg.policy_list}
    previous = read_episodes(jsonl)
    stale = [r for r in previous if r.get("policy") in keys and r.get("run_key") != keys[r["policy"]]]
    if stale and not cfg.fresh:
        old = stale[0]
        raise ValueError(
            f"out_dir={cfg.out_dir} holds {len(stale)} episodes of policy {old['policy']!r} run as "
            f"{old.get('run_key', '(no run key: an older suite)')}, but this run is {keys[old['policy']]}: "
            "a table would mix them. Choose another --out_dir, another label (label=path), or pass "
            "--fresh=true to move the old episodes aside and start over"
        )
    if stale or (previous and not cfg.resume):
        aside = jsonl.with_name(f"episodes.{time.strftime('%Y%m%d-%H%M%S')}.jsonl")
        jsonl.rename(aside)  # never deleted: a person may want the old run
        log.warning("moved %d earlier episodes aside to %s", len(previous), aside)
        previous = []
    kept = [r for r in previous if (r.get("policy"), r.get("setting"), r.get("seed")) in wanted]
    done = {(r["policy"], r["setting"], r["seed"]) for r in kept}
    if kept:
        log.info("resuming: %d of %d episodes already in %s", len(kept), len(wanted), jsonl)
    # Rewrite the file (dropping a torn last line; every other record stays, also those this suite does
    # not report), then append as episodes finish.
    jsonl.write_text("".join(json.dumps(r) + "\n" for r in previous))
    tasks = _tasks(cfg, done, keys)
    records = list(kept)
    with open(jsonl, "a") as sink, tqdm(total=len(wanted), initial=len(kept), desc="suite", unit="ep") as bar:

        def record(result: dict) -> None:
            records.append(result)
            sink.write(json.dumps(result) + "\n")
            sink.flush()
            picks = sum(r["outcome"] == "pick" for r in records)
            bar.set_postfix_str(f"pick {picks}/{len(records)}")
            bar.update()

        if cfg.workers == 1 and not cfg.ray_address:
            for task in tasks:
                record(run_episode(task))
        else:
            # Spawned (or Ray's) workers: a fresh GL context and torch per process, nothing inherited.
            with worker_pool(cfg.workers, cfg.ray_address, maxtasksperchild=None) as pool:
                for result in pool.imap_unordered(run_episode, tasks, chunksize=1):
                    record(result)
    source = cfg.bbox_source + (
        f" (IoU {cfg.noisy_iou:g} to the oracle box)" if cfg.bbox_source == "noisy" else ""
    )
    return write_report(
        records, cfg.out_dir, [label for label, _ in cfg.policy_list], cfg.setting_list, bbox_source=source
    )


def summarize(records: list[dict], policies: list[str], settings: tuple[str, ...]) -> list[dict]:
    """One row per (policy, setting): counts, rates and Wilson 95% intervals of each outcome."""
    rows = []
    for policy in policies:
        for setting in settings:
            group = [r for r in records if r["policy"] == policy and r["setting"] == setting]
            n = len(group)
            row: dict[str, Any] = {"policy": policy, "setting": setting, "episodes": n}
            for outcome in OUTCOMES:
                k = sum(r["outcome"] == outcome for r in group)
                low, high = wilson_interval(k, n)
                row[outcome] = k
                row[f"{outcome}_rate"] = round(k / n, 4) if n else 0.0
                row[f"{outcome}_ci_low"] = round(low, 4)
                row[f"{outcome}_ci_high"] = round(high, 4)
            # Episodes whose simulation blew up (env info "sim_unstable"): kept in the counts, flagged here.
            row["sim_unstable"] = sum(bool(r.get("sim_unstable", False)) for r in group)
            ious = [r["bbox_mean_iou"] for r in group if r.get("bbox_mean_iou") is not None]
            row["mean_bbox_iou"] = round(float(np.mean(ious)), 4) if ious else None
            distances = [r["final_distance_m"] for r in group]
            row["mean_final_distance_m"] = round(float(np.mean(distances)), 4) if n else None
            rows.append(row)
    return rows


def markdown_table(rows: list[dict]) -> str:
    """Paper-style table: one line per policy and setting, percentages with Wilson 95% intervals."""
    head = "| policy | setting | n | " + " | ".join(o.capitalize() for o in OUTCOMES) + " |"
    lines = [head, "|---|---|---|" + "---|" * len(OUTCOMES)]
    for row in rows:
        cells = [
            f"{100 * row[f'{o}_rate']:.0f}% [{100 * row[f'{o}_ci_low']:.0f}-{100 * row[f'{o}_ci_high']:.0f}]"
            for o in OUTCOMES
        ]
        lead = f"| {row['policy']} | {row['setting']} | {row['episodes']} | "
        lines.append(lead + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_report(
    records: list[dict],
    out_dir: Path,
    policies: list[str],
    settings: tuple[str, ...],
    bbox_source: str = "oracle",
) -> Path:
    """table.md, table.csv and outcomes.png from the episode records; returns table.md."""
    rows = summarize(records, policies, settings)
    with open(out_dir / "table.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    outcome_bars(rows, OUTCOMES, out_dir / "outcomes.png")
    write_outcome_sheets(records, out_dir, policies)
    used = sorted({r["seed"] for r in records})
    split_names = " + ".join(dict.fromkeys(seeds.split_of(x) for x in used)) + " seeds"
    header = (
        f"Outcomes per policy and setting over the same scenes (seeds {used[0]}-{used[-1]}, "
        f"{split_names}); bbox source: {bbox_source}; brackets: Wilson 95% interval.\n\n"
    )
    unstable = [f"{r['policy']}/{r['setting']}: {r['sim_unstable']}" for r in rows if r["sim_unstable"]]
    footer = ""
    if unstable:
        footer = (
            "\nEpisodes ended early because the simulation blew up (a brick faster than 5 m/s), "
            f"counted with the outcome tracked until then: {', '.join(unstable)}.\n"
        )
    path = out_dir / "table.md"
    path.write_text(header + markdown_table(rows) + "\n" + footer)
    return path


@draccus.wrap()
def main(cfg: SuiteConfig) -> None:
    """Entry point of ``bboxpick-suite``."""
    logging.basicConfig(level=logging.INFO)
    table = run_suite(cfg)
    print(table.read_text())
    print(
        "report (table.md, table.csv, outcomes.png, outcomes_<policy>.png, episodes.jsonl, videos/) in "
        f"{cfg.out_dir.resolve()}"
    )
