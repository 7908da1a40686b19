"""Per-episode domain randomisation: light direction and intensity, table tint, brick colour jitter.

Each brick keeps its colour class (a "red" brick stays recognisably red) so the language task stays
true; only hue, saturation and value move a little. Everything is drawn from the episode's rng.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import mujoco
import numpy as np

from lerobot_bboxpick.sim.scene import BRICK_COLORS, SceneIds, lookup


@dataclass(frozen=True)
class Appearance:
    """What the randomiser chose for one episode (recorded for reproducibility and debugging)."""

    light_dir: np.ndarray
    light_diffuse: float
    table_rgb: np.ndarray
    brick_rgb: np.ndarray  # (12, 3)


def jitter_color(rgb: tuple[float, float, float], rng: np.random.Generator) -> np.ndarray:
    """A colour near ``rgb`` in HSV (hue +-0.02, saturation and value +-12%)."""
    h, s, v = colorsys.rgb_to_hsv(*rgb)
    h = (h + rng.uniform(-0.02, 0.02)) % 1.0
    s = float(np.clip(s * rng.uniform(0.88, 1.12), 0, 1))
    v = float(np.clip(v * rng.uniform(0.88, 1.12), 0, 1))
    return np.array(colorsys.hsv_to_rgb(h, s, v))


class Randomizer:
    """Applies an appearance to the model; ``enabled=False`` gives the nominal look every episode."""

    def __init__(self, model: mujoco.MjModel, ids: SceneIds, enabled: bool = True) -> None:
        self.model = model
        self.ids = ids
        self.enabled = enabled
        self._light = lookup(model, "light", "key")
        self._table_mat = model.geom_matid[ids.table_geom]
        self._nominal_dir = model.light_dir[self._light].copy()
        self._nominal_diffuse = float(model.light_diffuse[self._light][0])
        self._nominal_table = model.mat_rgba[self._table_mat][:3].copy()

    def sample(self, colors: tuple[str, ...], rng: np.random.Generator) -> Appearance:
        """Draw an appearance for bricks of the given colour names."""
        nominal = np.array([BRICK_COLORS[c] for c in colors])
        if not self.enabled:
            return Appearance(self._nominal_dir, self._nominal_diffuse, self._nominal_table, nominal)
        d = self._nominal_dir + rng.uniform([-0.5, -0.5, 0.0], [0.5, 0.5, 0.3])
        return Appearance(
            light_dir=d / np.linalg.norm(d),
            light_diffuse=float(rng.uniform(0.4, 0.8)),
            table_rgb=np.clip(self._nominal_table * rng.uniform(0.8, 1.15, size=3), 0, 1),
            brick_rgb=np.array([jitter_color(BRICK_COLORS[c], rng) for c in colors]),
        )

    def apply(self, appearance: Appearance) -> None:
        """Write an appearance into the model."""
        self.model.light_dir[self._light] = appearance.light_dir
        self.model.light_diffuse[self._light] = appearance.light_diffuse
        self.model.mat_rgba[self._table_mat][:3] = appearance.table_rgb
        for geoms, rgb in zip(self.ids.brick_geoms, appearance.brick_rgb, strict=True):
            self.model.geom_rgba[geoms, :3] = rgb
