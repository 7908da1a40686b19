"""Third-party output written straight to file descriptor 2 goes to the log, not to the console."""

import os
import sys

from lerobot_bboxpick.quiet import native_output_to


def test_native_output_goes_to_the_log_and_the_console_comes_back(tmp_path, capfd):
    log = tmp_path / "logs" / "collect.log"
    with native_output_to(log):
        os.write(2, b"[mp4 @ 0x1] Starting second pass: moving the moov atom\n")  # as FFmpeg does
        print("a Python-level bar", file=sys.stderr)
    os.write(2, b"our progress bar\n")
    captured = capfd.readouterr()
    assert "moov" not in captured.err and "Python-level" not in captured.err
    assert "our progress bar" in captured.err
    text = log.read_text()
    assert "moov atom" in text and "a Python-level bar" in text
