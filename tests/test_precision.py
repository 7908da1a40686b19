"""The training precision follows the CPU: bf16 autocast only where bf16 is native."""

from lerobot_bboxpick import precision


def test_falls_back_to_float32_where_bf16_is_not_native(monkeypatch):
    monkeypatch.setattr(precision, "cpu_has_native_bf16", lambda: False)
    choice = precision.choose_precision()
    assert choice.use_amp is False and choice.name == "float32" and "no native bf16" in choice.reason
    # Asked for explicitly, the user's choice stands, with the warning in the reason.
    forced = precision.choose_precision(True)
    assert forced.use_amp is True and "emulates" in forced.reason


def test_uses_bf16_autocast_where_native(monkeypatch):
    monkeypatch.setattr(precision, "cpu_has_native_bf16", lambda: True)
    assert precision.choose_precision().use_amp is True
    assert precision.choose_precision(False).use_amp is False
