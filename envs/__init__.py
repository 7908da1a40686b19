"""MJCF scenes and assets, installed as ``lerobot_bboxpick.assets``."""
