"""Keep third-party noise off the console: encoder log lines, dataset ``Map`` bars, library warnings.

Our own progress bars (tqdm on the parent's stderr) stay; what libraries print from C (the AV1
encoder writes straight to file descriptor 2) or through their own bars goes to a log file instead.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator
from pathlib import Path


def quiet_libraries() -> None:
    """Silence Hugging Face datasets' per-operation progress bars and chatty library loggers."""
    try:
        from datasets.utils.logging import disable_progress_bars

        disable_progress_bars()
    except ImportError:  # datasets is a LeRobot dependency; nothing to silence without it
        pass
    for name in ("datasets", "huggingface_hub", "lerobot.datasets", "torchcodec", "libav"):
        logging.getLogger(name).setLevel(logging.WARNING)
    try:  # FFmpeg's own log (e.g. the MP4 muxer's "Starting second pass" when LeRobot copies videos)
        import av

        av.logging.set_level(av.logging.ERROR)
    except (ImportError, AttributeError):
        pass


def redirect_native_output(log_file: str | Path) -> None:
    """Point this process's file descriptors 1 and 2 at ``log_file`` (appending).

    For worker processes only: C libraries (the video encoder) write to the descriptors directly, so
    Python-level redirection would not catch them. The parent keeps its console for the progress bars.
    """
    path = Path(log_file)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    for target in (1, 2):
        os.dup2(fd, target)
    os.close(fd)
    quiet_libraries()


@contextlib.contextmanager
def native_output_to(log_file: str | Path) -> Iterator[None]:
    """Send this process's file descriptor 2 (and Python's stderr) to ``log_file`` for the duration.

    For a parent between progress bars: LeRobot's video helpers restore FFmpeg's default log callback
    after each use, so the MP4 muxer's lines reach descriptor 2 whatever ``quiet_libraries`` set.
    """
    path = Path(log_file)
    path.parent.mkdir(parents=True, exist_ok=True)
    sys.stderr.flush()
    saved = os.dup(2)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        os.dup2(fd, 2)
        with open(path, "a") as log, contextlib.redirect_stderr(log):  # Python-level bars and warnings
            yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
        os.close(fd)
