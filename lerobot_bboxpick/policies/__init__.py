"""Policies provided by lerobot_bboxpick."""
