"""Which policies the dashboard can run: the scripted expert, checkpoint folders, the shipped checkpoint.

A checkpoint is any folder holding ``config.json`` and ``model.safetensors`` (what ``save_pretrained``
writes and ``lerobot-eval --policy.path`` loads). They are found under ``--checkpoints_dir`` or given
by path; "shipped" is the checkpoint under the repository's ``examples/``, listed only when one exists.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lerobot_bboxpick.apps.dashboard.errors import RequestError
from lerobot_bboxpick.shipped_checkpoints import SHIPPED_CHECKPOINT

EXPERT = "expert"
SHIPPED = "shipped"
CHECKPOINT_FILES = ("config.json", "model.safetensors")
MAX_LISTED = 200  # a huge outputs/ tree should not make the page's policy list unusable
EXAMPLES_DIR = Path(__file__).resolve().parents[3] / "examples"


@dataclass(frozen=True)
class PolicyChoice:
    """One runnable policy: ``id`` is what a run request names, ``path`` its folder (None: the expert)."""

    id: str
    label: str
    path: Path | None = None

    def as_json(self) -> dict:
        """How the API lists it."""
        return {"id": self.id, "label": self.label, "path": None if self.path is None else str(self.path)}


def is_checkpoint(path: Path) -> bool:
    """True when ``path`` is a folder with ``config.json`` and ``model.safetensors``."""
    return path.is_dir() and all((path / name).is_file() for name in CHECKPOINT_FILES)


def find_checkpoints(root: Path, limit: int = MAX_LISTED) -> list[Path]:
    """Checkpoint folders under ``root`` (itself too), sorted, at most ``limit``; skips hidden folders."""
    found: list[Path] = []
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        if all(name in files for name in CHECKPOINT_FILES):
            found.append(Path(folder))
            if len(found) >= limit:
                break
    return sorted(found)


class PolicyCatalog:
    """Lists and resolves policy choices; loads (and keeps) checkpoint runners."""

    def __init__(self, checkpoints_dir: Path | None = None, examples_dir: Path = EXAMPLES_DIR) -> None:
        if checkpoints_dir is not None and not Path(checkpoints_dir).is_dir():
            raise ValueError(f"checkpoints_dir={str(checkpoints_dir)!r} is not a folder")
        self.checkpoints_dir = None if checkpoints_dir is None else Path(checkpoints_dir).resolve()
        self.examples_dir = Path(examples_dir)
        self._runners: dict[tuple[Path, int], Any] = {}

    def shipped(self) -> Path | None:
        """The checkpoint under ``examples/``, if the repository has one: the main job's shipped one where
        it is there, else the first found."""
        preferred = self.examples_dir / SHIPPED_CHECKPOINT.name
        if (preferred / "config.json").is_file():
            return preferred
        found = find_checkpoints(self.examples_dir, limit=1) if self.examples_dir.is_dir() else []
        return found[0] if found else None

    def choices(self) -> list[PolicyChoice]:
        """Everything the page offers: the expert, the shipped checkpoint (if any), found checkpoints."""
        out = [PolicyChoice(EXPERT, "scripted expert")]
        shipped = self.shipped()
        if shipped is not None:
            out.append(PolicyChoice(SHIPPED, f"shipped checkpoint ({shipped.name})", shipped))
        if self.checkpoints_dir is not None:
            for path in find_checkpoints(self.checkpoints_dir):
                rel = path.relative_to(self.checkpoints_dir).as_posix()
                out.append(PolicyChoice(rel, rel, path))
        return out

    def resolve(self, spec: str, field: str = "policy") -> PolicyChoice:
        """The choice a run request names: "expert", "shipped", or a checkpoint folder (absolute, relative
        to the working folder, or relative to ``checkpoints_dir``); ``RequestError`` 404 when missing."""
        spec = spec.strip()
        if spec == EXPERT:
            return PolicyChoice(EXPERT, "scripted expert")
        if spec == SHIPPED:
            shipped = self.shipped()
            if shipped is None:
                raise RequestError(
                    f"{field}='shipped': no checkpoint ships with this repository (none under "
                    f"{self.examples_dir}); choose 'expert' or a checkpoint folder",
                    status=404,
                    field=field,
                )
            return PolicyChoice(SHIPPED, f"shipped checkpoint ({shipped.name})", shipped)
        if not spec:
            raise RequestError(f"{field} is empty: name 'expert' or a checkpoint folder", field=field)
        candidates = [Path(spec).expanduser()]
        if self.checkpoints_dir is not None and not Path(spec).is_absolute():
            candidates.append(self.checkpoints_dir / spec)
        for path in candidates:
            if is_checkpoint(path):
                return PolicyChoice(spec, spec, path.resolve())
        under = f"a folder under {self.checkpoints_dir}, " if self.checkpoints_dir else ""
        raise RequestError(
            f"{field}={spec!r}: no checkpoint there (a checkpoint folder holds "
            f"{' and '.join(CHECKPOINT_FILES)}; looked in {', '.join(str(p) for p in candidates)}); "
            f"valid: 'expert', {under}a checkpoint path",
            status=404,
            field=field,
        )

    def runner(self, choice: PolicyChoice, env: Any, slot: int = 0, field: str = "policy") -> Any:
        """A runner with ``reset()`` / ``act(obs, task)``: ``ExpertRunner`` on ``env``, or the checkpoint's
        ``PolicyRunner``, loaded once per ``slot`` and then kept (a policy keeps its action queue between
        steps, so two lanes running the same checkpoint need two runners)."""
        from lerobot_bboxpick.eval.rollout import ExpertRunner, PolicyRunner

        if choice.path is None:
            return ExpertRunner(env)
        key = (choice.path, slot)
        if key not in self._runners:
            try:
                self._runners[key] = PolicyRunner.from_pretrained(choice.path)
            except Exception as e:  # a broken folder is the user's input: report it, keep serving
                raise RequestError(
                    f"{field}={choice.id!r}: could not load the checkpoint at {choice.path}: "
                    f"{type(e).__name__}: {e}",
                    field=field,
                ) from e
        return self._runners[key]
