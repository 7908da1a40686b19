"""``bboxpick-compare``: suite runs side by side on the same scenes, each against a baseline.

    bboxpick-compare --runs="IL=outputs/suite_il,outputs/suite_il_more;AWR=outputs/suite_awr" \
        --out=docs/table.md

Reads the ``episodes.jsonl`` of each run's suite folders (several folders make one run, e.g. two suites
over different settings) and prints a markdown table: Pick per setting with its Wilson interval and the
Wrong rate, and, for every run after the first (the baseline), the scenes it picks and the baseline does
not (+) and the reverse (-). Scenes are matched by setting and seed, so the counts are paired: on 30
scenes a setting's intervals overlap for a 15-point change, while the paired counts show which scenes
moved. The last column pools every setting and gives the two-sided sign test of the gains against the
losses (ties, scenes both pick or both miss, carry no information). ``--by=target_yaw`` breaks each
run's settings down by how far the target is turned instead (``lerobot_bboxpick.eval.target_yaw``).
"""

from dataclasses import dataclass
from pathlib import Path

import draccus
from scipy.stats import binomtest

from lerobot_bboxpick.eval.suite import read_episodes, wilson_interval
from lerobot_bboxpick.eval.target_yaw import target_yaw_table
from lerobot_bboxpick.sim.layouts import SETTINGS

Scene = tuple[str, int]  # (setting, seed)
BY = ("setting", "target_yaw")  # the table's rows: bboxpick-compare --by


def load_outcomes(folders: list[Path]) -> dict[Scene, str]:
    """Each scene's outcome in the suites at ``folders`` (their ``episodes.jsonl``); a scene twice is an
    error. ``dir@label`` keeps only the episodes of that policy label (a suite run with several
    policies, e.g. ``expert,bbox_diffusion``)."""
    outcomes: dict[Scene, str] = {}
    for folder in folders:
        where, _, label = str(folder).partition("@")
        path = Path(where) / "episodes.jsonl"
        if not path.is_file():
            raise ValueError(f"runs: {where} has no episodes.jsonl (a bboxpick-suite --out_dir)")
        episodes = read_episodes(path)
        if label:
            labels = sorted({e.get("policy", "") for e in episodes})
            episodes = [e for e in episodes if e.get("policy") == label]
            if not episodes:
                raise ValueError(f"runs: {folder}: no episodes of policy {label!r}; policies: {labels}")
        for episode in episodes:
            scene = (episode["setting"], int(episode["seed"]))
            if scene in outcomes:
                raise ValueError(f"runs: scene {scene} appears twice in {', '.join(map(str, folders))}")
            outcomes[scene] = episode["outcome"]
    return outcomes


def paired_counts(
    run: dict[Scene, str], baseline: dict[Scene, str], setting: str | None = None
) -> tuple[int, int]:
    """(scenes ``run`` picks and ``baseline`` does not, the reverse) over the scenes both ran (of
    ``setting``; None: all)."""
    scenes = [s for s in run if s in baseline and (setting is None or s[0] == setting)]
    gains = sum(run[s] == "pick" != baseline[s] for s in scenes)
    losses = sum(baseline[s] == "pick" != run[s] for s in scenes)
    return gains, losses


def sign_test_p(gains: int, losses: int) -> float:
    """Two-sided exact sign test of ``gains`` against ``losses`` (1.0 when both are 0)."""
    return 1.0 if gains + losses == 0 else float(binomtest(gains, gains + losses, 0.5).pvalue)


def _cell(outcomes: list[str]) -> str:
    pick, wrong, n = outcomes.count("pick"), outcomes.count("wrong"), len(outcomes)
    low, high = wilson_interval(pick, n)
    return f"{100 * pick / n:.0f}% [{100 * low:.0f}-{100 * high:.0f}] ({100 * wrong / n:.0f}%)"


def comparison_table(runs: dict[str, dict[Scene, str]]) -> str:
    """The markdown table of ``runs`` (the first is the baseline): Pick [Wilson] (Wrong) per setting, and
    paired gains/losses against the baseline per setting and pooled, with the pooled sign test."""
    names = list(runs)
    baseline = runs[names[0]]
    present = {s for outcomes in runs.values() for s, _ in outcomes}
    settings = [s for s in SETTINGS if s in present]
    lines = [
        "| policy | " + " | ".join(settings) + " | all settings |",
        "|---|" + "---|" * (len(settings) + 1),
    ]
    for name in names:
        outcomes = runs[name]
        cells = []
        for setting in [*settings, None]:
            got = [o for (s, _), o in outcomes.items() if setting is None or s == setting]
            if not got:
                cells.append("-")
                continue
            text = _cell(got)
            if name != names[0]:
                gains, losses = paired_counts(outcomes, baseline, setting)
                text += f" +{gains}/-{losses}"
                if setting is None:
                    text += f", p = {sign_test_p(gains, losses):.2g}"
            cells.append(text)
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def parse_runs(spec: str) -> dict[str, list[Path]]:
    """``"NAME=dir[,dir...];NAME=dir..."`` as {name: folders}, in order (a name may hold "=")."""
    runs: dict[str, list[Path]] = {}
    for part in filter(None, (p.strip() for p in spec.split(";"))):
        name, sep, folders = part.rpartition("=")
        if not sep or not name.strip() or not folders.strip():
            raise ValueError(f"runs: {part!r} is not NAME=dir[,dir...]")
        runs[name.strip()] = [Path(f.strip()) for f in folders.split(",") if f.strip()]
    if len(runs) < 1:
        raise ValueError("runs is empty: give NAME=dir[,dir...];NAME=dir..., the baseline first")
    return runs


@dataclass
class CompareConfig:
    """Options of ``bboxpick-compare``."""

    # "NAME=dir[,dir...];NAME=dir...": suite folders per run, the baseline first; "dir@label" keeps only
    # that policy's episodes of a suite that ran several.
    runs: str = ""
    # Write the table here too (markdown); None: print only.
    out: Path | None = None
    # Rows of the table: "setting" (paired gains and losses against the first run) or "target_yaw" (each
    # run's Pick per setting and per bin of the target's yaw off the grid axes).
    by: str = "setting"

    def __post_init__(self) -> None:
        if self.by not in BY:
            raise ValueError(f"by={self.by!r}: allowed values are {', '.join(BY)}")


@draccus.wrap()
def main(cfg: CompareConfig) -> None:
    """Entry point of ``bboxpick-compare``."""
    runs = {name: load_outcomes(folders) for name, folders in parse_runs(cfg.runs).items()}
    table = comparison_table(runs) if cfg.by == "setting" else target_yaw_table(runs)
    if cfg.out is not None:
        Path(cfg.out).write_text(table)
    print(table, end="")


if __name__ == "__main__":
    main()
