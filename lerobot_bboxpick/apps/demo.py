"""``lerobot_bboxpick demo``: scripted-expert rollouts in every setting, as video and pictures.

Writes into ``out_dir``: one MP4 per setting (wrist view, target bbox drawn), a contact sheet of the
six settings' first frames, a filmstrip of one episode, and ``outcomes.md`` / ``outcomes.csv``.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lerobot_bboxpick.sim.env import LegoPickEnv
from lerobot_bboxpick.sim.expert import ScriptedExpert
from lerobot_bboxpick.sim.layouts import SETTINGS
from lerobot_bboxpick.sim.outcome import OUTCOMES
from lerobot_bboxpick.viz import contact_sheet, label, save_mp4, save_png


def settings_sheet(seed: int = 0, scale: int = 2) -> np.ndarray:
    """The six settings' first wrist frames with the target bbox, labelled, in a 3x2 sheet."""
    tiles = []
    for setting in SETTINGS:
        env = LegoPickEnv(setting=setting)
        env.reset(seed=seed)
        tiles.append(label(env.render(), setting))
        env.close()
    return contact_sheet(tiles, columns=3, scale=scale)


def inputs_sheet(
    seed: int = 0, image_size: int = 64, crop_size: int = 48, context: float = 3.0, min_side: float = 0.1
) -> np.ndarray:
    """What the policy sees of each setting's first frame, one row per setting: the 224 px frame with the
    target's box, the policy image (centre crop resized to ``image_size``) and the target view
    (``crop_size`` px, ``context`` box sides), each shown at 224 px (nearest) so pixels stay pixels."""
    import cv2
    import torch

    from lerobot_bboxpick.keys import ENV_BBOX, ENV_CAMERA, ENV_PIXELS
    from lerobot_bboxpick.policies.bbox_diffusion.encoder import PairedAugment
    from lerobot_bboxpick.policies.bbox_diffusion.target_crop import crop_windows, target_windows
    from lerobot_bboxpick.viz import draw_bbox

    def shown(chw: torch.Tensor, side: int) -> np.ndarray:
        rgb = (chw.permute(1, 2, 0).clamp(0, 1).numpy() * 255).round().astype(np.uint8)
        return cv2.resize(rgb, (side, side), interpolation=cv2.INTER_NEAREST)

    tiles = []
    for setting in SETTINGS:
        env = LegoPickEnv(setting=setting)
        obs, _ = env.reset(seed=seed)
        env.close()
        frame, bbox = obs[ENV_PIXELS][ENV_CAMERA], obs[ENV_BBOX]
        side = frame.shape[0]
        image = torch.as_tensor(frame).permute(2, 0, 1)[None].float() / 255
        small, _ = PairedAugment().eval()(image, None, out_size=image_size)
        box = torch.as_tensor(bbox, dtype=torch.float32)[None]
        window = target_windows(box, *frame.shape[:2], context, min_side)
        crop = crop_windows(image, window, crop_size)
        tiles += [
            label(draw_bbox(frame.copy(), bbox, color=(255, 255, 0)), setting),
            label(shown(small[0], side), f"policy image {image_size} px"),
            label(shown(crop[0], side), f"target view {crop_size} px"),
        ]
    return contact_sheet(tiles, columns=3)


def run_demo(out_dir: Path, episodes: int = 1, seed: int = 0, settings: tuple[str, ...] = SETTINGS) -> Path:
    """Roll the scripted expert out ``episodes`` times per setting; return the outcomes table path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    firsts = []
    progress = tqdm(total=episodes * len(settings), desc="expert rollouts", unit="episode")
    for setting in settings:
        env = LegoPickEnv(setting=setting, terminate_on_lift=False)
        for k in range(episodes):
            episode_seed = seed + k
            env.reset(seed=episode_seed)
            expert = ScriptedExpert(np.random.default_rng(episode_seed))
            expert.reset(env)
            frames = [env.render()]
            info: dict = {}
            while not expert.done:
                _, _, _, _, info = env.step(expert.act())
                frames.append(env.render())
            if k == 0:
                firsts.append(label(frames[0].copy(), setting))
                save_mp4(out_dir / f"{setting}_seed{episode_seed}.mp4", frames, env.options.fps)
                if setting == settings[0]:
                    strip = [label(f.copy(), f"t={i / env.options.fps:.1f}s") for i, f in enumerate(frames)]
                    save_png(out_dir / "episode_filmstrip.png", contact_sheet(strip[::12], columns=6))
            rows.append(
                {
                    "setting": setting,
                    "seed": episode_seed,
                    "outcome": info["outcome"],
                    "steps": len(frames) - 1,
                    "task": info["task"],
                }
            )
            progress.update()
        env.close()
    progress.close()
    save_png(out_dir / "settings_contact_sheet.png", contact_sheet(firsts, columns=3, scale=2))
    with open(out_dir / "outcomes.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = ["| setting | " + " | ".join(OUTCOMES) + " |", "|---|" + "---|" * len(OUTCOMES)]
    for setting in settings:
        counts = [sum(r["setting"] == setting and r["outcome"] == o for r in rows) for o in OUTCOMES]
        table.append(f"| {setting} | " + " | ".join(str(c) for c in counts) + " |")
    path = out_dir / "outcomes.md"
    path.write_text(f"Scripted expert, episodes per setting: {episodes}\n\n" + "\n".join(table) + "\n")
    return path
