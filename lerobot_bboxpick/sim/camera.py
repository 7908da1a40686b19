"""The fisheye wrist camera: lens model, wide-pinhole -> fisheye warp, and bbox projection.

One lens model serves the image and the bbox: the image is a wide pinhole render warped with
precomputed ``cv2.remap`` maps built from ``FisheyeLens.unproject``, and the bbox is the target's
silhouette points pushed through ``FisheyeLens.project``. So the box and the pixels agree by
construction, frame after frame.

Pixel coordinates follow OpenCV: pixel (u, v) has its centre at integer coordinates, u to the
right, v down. Camera frame follows OpenCV too: x right, y down, z forward (MuJoCo cameras look
along their -z with y up; ``WristCamera`` converts).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import mujoco
import numpy as np

from lerobot_bboxpick.sim.scene import lookup


@dataclass(frozen=True)
class FisheyeLens:
    """OpenCV fisheye (Kannala-Brandt) model: r = f * theta * (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8).

    With all k = 0 it is the equidistant model r = f * theta.
    """

    width: int = 224
    height: int = 224
    f: float = 88.0
    cx: float = 112.3
    cy: float = 111.7
    k: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def distort(self, theta: np.ndarray) -> np.ndarray:
        """theta_d(theta) of the Kannala-Brandt polynomial."""
        t2 = theta * theta
        k1, k2, k3, k4 = self.k
        return theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))

    def project(self, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project (N,3) camera-frame points; returns pixels (N,2) and the off-axis angle (N,)."""
        x, y, z = points_cam[:, 0], points_cam[:, 1], points_cam[:, 2]
        rxy = np.hypot(x, y)
        theta = np.arctan2(rxy, z)
        scale = np.where(rxy > 1e-12, self.f * self.distort(theta) / np.maximum(rxy, 1e-12), 0.0)
        return np.stack([self.cx + scale * x, self.cy + scale * y], axis=1), theta

    def unproject(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit rays (N,3) of pixels (N,2) and their off-axis angle (Newton on the polynomial); NaN where
        the polynomial cannot be inverted."""
        dx = (pixels[:, 0] - self.cx) / self.f
        dy = (pixels[:, 1] - self.cy) / self.f
        theta_d = np.hypot(dx, dy)
        # Start from a table of the monotonic part of the polynomial (a few degrees past what the
        # GoPro sees), then polish with Newton steps.
        grid = np.linspace(0.0, np.pi, 4001)
        table = self.distort(grid)
        monotonic = np.argmax(np.diff(table) <= 0) if np.any(np.diff(table) <= 0) else len(grid) - 1
        grid, table = grid[: monotonic + 1], table[: monotonic + 1]
        theta = np.interp(theta_d, table, grid)
        k1, k2, k3, k4 = self.k
        for _ in range(3):
            t2 = theta * theta
            slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            theta = np.clip(theta - (self.distort(theta) - theta_d) / slope, 0.0, grid[-1])
        # Past the polynomial's peak a pixel has no ray: mark those invalid.
        theta[(theta_d > table[-1]) | (np.abs(self.distort(theta) - theta_d) > 1e-6)] = np.nan
        s = np.where(theta_d > 1e-12, np.sin(theta) / np.maximum(theta_d, 1e-12), 1.0)
        rays = np.stack([dx * s, dy * s, np.cos(theta)], axis=1)
        return rays, theta


def gopro_hero10_umi_lens() -> FisheyeLens:
    """GoPro Hero 10 as UMI uses it: the 2.7k calibration resized to height 224, centre-cropped to 224.

    Calibration (FACTS.md section 2): 2704x2028, f 796.854, c (1354.427, 1011.485),
    k = (-0.021961, -0.018960, 0.001694, -0.000168).
    """
    scale = 224 / 2028
    crop_x = (2704 * scale - 224) / 2
    return FisheyeLens(
        f=796.854 * scale,
        cx=1354.427 * scale - crop_x,
        cy=1011.485 * scale,
        k=(-0.021961, -0.018960, 0.001694, -0.000168),
    )


LENSES = {
    "gopro_hero10": gopro_hero10_umi_lens,
    "equidistant": lambda: FisheyeLens(f=83.4, cx=112.3, cy=111.7),
}


@dataclass
class FisheyeWarp:
    """Precomputed remap from a square wide pinhole render (``render_size``, ``fovy_deg``) to the lens.

    Output pixels whose ray falls outside the pinhole view (beyond ~75 deg off-axis) are black,
    like the GoPro's dark corners.
    """

    lens: FisheyeLens
    render_size: int = 512
    fovy_deg: float = 140.0
    map_x: np.ndarray = field(init=False, repr=False)
    map_y: np.ndarray = field(init=False, repr=False)
    valid: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        u, v = np.meshgrid(np.arange(self.lens.width), np.arange(self.lens.height))
        rays, theta = self.lens.unproject(np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64))
        fp = self.pinhole_focal
        c = (self.render_size - 1) / 2
        z = np.maximum(np.nan_to_num(rays[:, 2]), 1e-9)
        px = np.nan_to_num(c + fp * rays[:, 0] / z, nan=-100.0)
        py = np.nan_to_num(c + fp * rays[:, 1] / z, nan=-100.0)
        inside = np.isfinite(theta) & (theta < np.pi / 2 - 1e-3) & (px >= 0) & (px <= self.render_size - 1)
        inside &= (py >= 0) & (py <= self.render_size - 1)
        px[~inside] = -100.0  # far outside: BORDER_CONSTANT gives black, no blending with edge pixels
        py[~inside] = -100.0
        shape = (self.lens.height, self.lens.width)
        self.map_x = px.reshape(shape).astype(np.float32)
        self.map_y = py.reshape(shape).astype(np.float32)
        self.valid = inside.reshape(shape)
        # Largest off-axis angle the pinhole render covers in every direction: beyond it a point
        # may fall in a black region, so it is not "in view".
        self.max_theta = float(np.arctan(np.tan(np.radians(self.fovy_deg) / 2)))

    @property
    def pinhole_focal(self) -> float:
        """Focal length in pixels of the wide pinhole render."""
        return (self.render_size / 2) / np.tan(np.radians(self.fovy_deg) / 2)

    def warp(self, image: np.ndarray) -> np.ndarray:
        """Warp an RGB pinhole render (bilinear)."""
        return cv2.remap(image, self.map_x, self.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

    def warp_labels(self, labels: np.ndarray, fill: int = -1) -> np.ndarray:
        """Warp an integer label image (nearest neighbour, no blending of ids)."""
        out = cv2.remap(
            labels.astype(np.float32),
            self.map_x,
            self.map_y,
            cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=float(fill),
        )
        return out.astype(np.int32)


@dataclass(frozen=True)
class BoxProjection:
    """A projected bbox in normalised [0,1] image coordinates and how much of the object is in view."""

    bbox: np.ndarray  # (4,) x0, y0, x1, y1, clipped; zeros when nothing is in view
    visibility: str  # "full", "partial" or "none"

    @property
    def in_view(self) -> bool:
        """True when any part of the object projects into the image."""
        return self.visibility != "none"


class WristCamera:
    """Renders the wrist fisheye view (and segmentation) and projects scene points into it."""

    def __init__(
        self,
        model: mujoco.MjModel,
        camera: str,
        camera_site: int,
        lens: FisheyeLens,
        render_size: int = 512,
        fovy_deg: float = 140.0,
        segmentation_supersample: int = 3,
    ) -> None:
        model.cam_fovy[lookup(model, "camera", camera)] = fovy_deg
        self.camera = camera
        self.camera_site = camera_site
        self.lens = lens
        self.warp = FisheyeWarp(lens, render_size=render_size, fovy_deg=fovy_deg)
        # Segmentation is a check of the image (tests, masks), so it renders finer than the RGB view:
        # nearest-neighbour labels from a coarse render would move object edges by up to a pixel.
        self.segmentation_warp = FisheyeWarp(
            lens, render_size=render_size * segmentation_supersample, fovy_deg=fovy_deg
        )
        self._renderer = mujoco.Renderer(model, height=render_size, width=render_size)
        self._seg_renderer: mujoco.Renderer | None = None
        self._model = model

    def render(self, data: mujoco.MjData) -> np.ndarray:
        """The (H, W, 3) uint8 fisheye image."""
        self._renderer.update_scene(data, camera=self.camera)
        return self.warp.warp(self._renderer.render())

    def render_pinhole(self, data: mujoco.MjData) -> np.ndarray:
        """The wide pinhole render before warping (the bare render the benchmark compares against)."""
        self._renderer.update_scene(data, camera=self.camera)
        return self._renderer.render()

    def render_geom_ids(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W) int32 geom id of each fisheye pixel, -1 for background."""
        if self._seg_renderer is None:
            size = self.segmentation_warp.render_size
            self._seg_renderer = mujoco.Renderer(self._model, height=size, width=size)
            self._seg_renderer.enable_segmentation_rendering()
        self._seg_renderer.update_scene(data, camera=self.camera)
        seg = self._seg_renderer.render()
        ids = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
        return self.segmentation_warp.warp_labels(ids)

    def world_to_camera(self, data: mujoco.MjData, points_world: np.ndarray) -> np.ndarray:
        """World points (N,3) into the OpenCV camera frame (the camera site's axes are x right, y down,
        z forward)."""
        R = data.site_xmat[self.camera_site].reshape(3, 3)
        return (points_world - data.site_xpos[self.camera_site]) @ R

    def project_world(self, data: mujoco.MjData, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N,2) of world points and their off-axis angles (N,)."""
        return self.lens.project(self.world_to_camera(data, points_world))

    def project_bbox(self, data: mujoco.MjData, points_world: np.ndarray) -> BoxProjection:
        """Bounding box of the projected points, clipped to the image.

        "full" when every point is in front of the camera within the rendered field of view and
        inside the image; "none" when no point is; the bbox is then all zeros, never made up.
        """
        pixels, theta = self.project_world(data, points_world)
        w, h = self.lens.width, self.lens.height
        # Pixel centres are integers, so the image spans [-0.5, w - 0.5] in these coordinates.
        in_image = (
            (theta < self.warp.max_theta)
            & (pixels[:, 0] >= -0.5)
            & (pixels[:, 0] <= w - 0.5)
            & (pixels[:, 1] >= -0.5)
            & (pixels[:, 1] <= h - 0.5)
        )
        if not in_image.any():
            return BoxProjection(np.zeros(4, dtype=np.float32), "none")
        front = theta < self.warp.max_theta
        pts = pixels[front] + 0.5  # pixel-edge coordinates: the image spans [0, w]
        # Snap to pixel edges: a pixel belongs to the object when its centre is inside the outline,
        # so the box of the object's pixels runs from round(min) to round(max) (what an annotator or
        # a tracker would draw on this image).
        x0, y0 = np.clip(np.round(pts.min(axis=0)), 0, [w, h])
        x1, y1 = np.clip(np.round(pts.max(axis=0)), 0, [w, h])
        bbox = np.array([x0 / w, y0 / h, x1 / w, y1 / h], dtype=np.float32)
        return BoxProjection(bbox, "full" if in_image.all() else "partial")

    def close(self) -> None:
        """Free the GL contexts."""
        self._renderer.close()
        if self._seg_renderer is not None:
            self._seg_renderer.close()
