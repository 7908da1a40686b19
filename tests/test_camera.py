"""The fisheye lens model, the warp, and the projection of known points into rendered images."""

import cv2
import mujoco
import numpy as np
import pytest

from lerobot_bboxpick.sim.camera import FisheyeLens, WristCamera, gopro_hero10_umi_lens
from lerobot_bboxpick.sim.scene import WRIST_CAMERA, asset_path


def test_gopro_lens_matches_umi_intrinsics_at_224():
    lens = gopro_hero10_umi_lens()
    assert lens.f == pytest.approx(88.0, abs=0.05)
    assert (lens.cx, lens.cy) == pytest.approx((112.3, 111.7), abs=0.05)


@pytest.mark.parametrize("lens", [gopro_hero10_umi_lens(), FisheyeLens(f=83.4)])
def test_projection_agrees_with_opencv_fisheye(lens):
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.3, -0.3, 0.05], [0.3, 0.3, 0.6], size=(200, 3))
    K = np.array([[lens.f, 0, lens.cx], [0, lens.f, lens.cy], [0, 0, 1]])
    expected, _ = cv2.fisheye.projectPoints(pts[:, None, :], np.zeros(3), np.zeros(3), K, np.array(lens.k))
    got, _ = lens.project(pts)
    assert np.abs(got - expected[:, 0, :]).max() < 1e-6


def test_unproject_inverts_project():
    lens = gopro_hero10_umi_lens()
    rng = np.random.default_rng(1)
    pixels = rng.uniform(0, 224, size=(2000, 2))
    rays, theta = lens.unproject(pixels)
    radius = np.hypot(pixels[:, 0] - lens.cx, pixels[:, 1] - lens.cy)
    # Inside the image circle every pixel has a ray, up to ~100 deg off-axis (the GoPro's ~165 deg view).
    inside = radius < 115
    assert np.isfinite(theta[inside]).all() and np.degrees(np.nanmax(theta)) > 100
    back, _ = lens.project(rays[inside])
    assert np.abs(back - pixels[inside]).max() < 1e-6
    # Past the polynomial's peak (the black corners) there is no ray, and we say so with NaN.
    assert np.isnan(theta[radius > 125]).all()


def _marker_model(n: int) -> tuple[mujoco.MjModel, list[int]]:
    """The scene with small white spheres (mocap bodies we can place anywhere)."""
    with __import__("importlib").resources.as_file(asset_path("scene.xml")) as path:
        spec = mujoco.MjSpec.from_file(str(path))
    for i in range(n):
        body = spec.worldbody.add_body(name=f"marker_{i}", mocap=True)
        body.add_geom(
            name=f"marker_{i}",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[0.007, 0, 0],
            rgba=[1, 1, 1, 1],
            contype=0,
            conaffinity=0,
        )
    model = spec.compile()
    return model, [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"marker_{i}") for i in range(n)]


def test_known_points_land_on_the_predicted_pixel():
    """Render spheres at known 3D points; their segmented centroid is where the lens formula says."""
    offsets = np.array([[0.0, 0.0], [0.08, 0.03], [-0.1, -0.06], [0.16, 0.1], [-0.2, 0.15], [0.05, -0.2]])
    model, geoms = _marker_model(len(offsets))
    data = mujoco.MjData(model)
    cam_site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "camera")
    data.qpos[:6] = [-2.39, -2.54, 2.55, -2.18, -1.03, -0.65]
    mujoco.mj_forward(model, data)
    camera = WristCamera(model, WRIST_CAMERA, cam_site, gopro_hero10_umi_lens())
    R = data.site_xmat[cam_site].reshape(3, 3)
    depth = 0.2
    centres = np.array([data.site_xpos[cam_site] + R @ np.array([dx, dy, depth]) for dx, dy in offsets])
    data.mocap_pos[:] = centres
    mujoco.mj_forward(model, data)
    ids_img = camera.render_geom_ids(data)
    predicted, theta = camera.project_world(data, centres)
    errors = []
    for g, p in zip(geoms, predicted, strict=True):
        vs, us = np.nonzero(ids_img == g)
        assert len(us) >= 5, f"marker geom {g} not visible"
        errors.append(np.hypot(us.mean() - p[0], vs.mean() - p[1]))
    camera.close()
    assert np.degrees(theta).max() > 35  # the check reaches well off-axis, where the fisheye bends most
    print("marker centroid errors (px):", np.round(errors, 3), "off-axis (deg):", np.degrees(theta).round(1))
    assert max(errors) < 1.0, errors
