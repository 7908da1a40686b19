"""The lego_pick MuJoCo model: the MJCF from ``envs/lego_pick`` plus twelve DUPLO bricks.

The bricks are added here with ``mujoco.MjSpec`` from one brick definition rather than written out
twelve times in XML; their poses and colours are set per episode by the layout and randomisation.
``SceneIds`` gathers every index the rest of the simulator needs, so nobody looks names up twice.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import mujoco
import numpy as np

N_BRICKS = 12
# DUPLO 2x2 brick (FACTS.md section 3): body 31.8 x 31.8 x 19.2 mm, studs 9.4 mm across and
# 4.6 mm tall on a 16 mm pitch. The brick body frame is at the centre of its bottom face.
BRICK_HALF = np.array([0.0159, 0.0159, 0.0096])
STUD_RADIUS = 0.0047
STUD_HEIGHT = 0.0046
STUD_PITCH = 0.016
BRICK_HEIGHT = 2 * BRICK_HALF[2]  # stacking height: a stacked brick's bottom rests here
BRICK_DENSITY = 300.0  # kg/m^3 of the solid box: about 6 g, like a (hollow) DUPLO brick

# Twelve distinct colours; the names are used in the language task ("pick up the red block ...").
BRICK_COLORS: dict[str, tuple[float, float, float]] = {
    "red": (0.80, 0.08, 0.08),
    "orange": (0.95, 0.45, 0.05),
    "yellow": (0.95, 0.80, 0.05),
    "lime": (0.60, 0.85, 0.15),
    "green": (0.05, 0.50, 0.15),
    "teal": (0.05, 0.60, 0.60),
    "blue": (0.10, 0.30, 0.85),
    "navy": (0.08, 0.10, 0.40),
    "purple": (0.50, 0.15, 0.65),
    "pink": (0.95, 0.45, 0.70),
    "brown": (0.45, 0.25, 0.10),
    "white": (0.92, 0.92, 0.90),
}
COLOR_NAMES: tuple[str, ...] = tuple(BRICK_COLORS)

ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
FINGER_JOINTS = ("finger_left_joint", "finger_right_joint")
MAX_GRIPPER_WIDTH = 0.09
WRIST_CAMERA = "wrist_wide"


def asset_path(name: str) -> resources.abc.Traversable:
    """Path of a file in the packaged ``envs/lego_pick`` folder."""
    return resources.files("lerobot_bboxpick.assets") / "lego_pick" / name


def _add_brick(spec: mujoco.MjSpec, index: int) -> None:
    body = spec.worldbody.add_body(name=f"brick_{index}", pos=[0.3, 0.0, 0.05 * index])
    body.add_freejoint(name=f"brick_{index}_joint")
    common = {"condim": 4, "friction": [1.0, 0.02, 0.001], "density": BRICK_DENSITY}
    body.add_geom(
        name=f"brick_{index}_body",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=BRICK_HALF.tolist(),
        pos=[0, 0, BRICK_HALF[2]],
        **common,
    )
    # Studs are seen, not touched: a brick stacked on another sits on its body (the studs go into
    # the hollow underside, as real DUPLO interlocks), and cylinder contacts would cost more physics
    # time per step than everything else in the env.
    for sx in (-1, 1):
        for sy in (-1, 1):
            body.add_geom(
                name=f"brick_{index}_stud_{sx}{sy}",
                type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                size=[STUD_RADIUS, STUD_HEIGHT / 2, 0],
                pos=[sx * STUD_PITCH / 2, sy * STUD_PITCH / 2, BRICK_HEIGHT + STUD_HEIGHT / 2],
                contype=0,
                conaffinity=0,
                density=BRICK_DENSITY,
            )


def build_model() -> mujoco.MjModel:
    """Compile the scene MJCF with the twelve bricks."""
    with resources.as_file(asset_path("scene.xml")) as path:
        spec = mujoco.MjSpec.from_file(str(path))
    for i in range(N_BRICKS):
        _add_brick(spec, i)
    return spec.compile()


def build_robot_model() -> mujoco.MjModel:
    """The arm and gripper alone (no table, no bricks): the IK solver's model."""
    with resources.as_file(asset_path("robot.xml")) as path:
        return mujoco.MjModel.from_xml_path(str(path))


def brick_silhouette_points() -> np.ndarray:
    """Points, in the brick frame, whose projections bound the brick's image silhouette.

    The body's twelve edges and the studs' top rims: a fisheye bends straight edges, so corners
    alone would under-cover the curved outline.
    """
    t = np.linspace(0.0, 1.0, 7)
    hx, hy, hz = BRICK_HALF
    corners = np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (0.0, 2 * hz)])
    edges = []
    for a in range(8):
        for b in range(a + 1, 8):
            if np.count_nonzero(corners[a] != corners[b]) == 1:  # differ in one coordinate
                edges.append(corners[a] + t[:, None] * (corners[b] - corners[a]))
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    rims = [
        np.stack(
            [
                sx * STUD_PITCH / 2 + STUD_RADIUS * np.cos(ang),
                sy * STUD_PITCH / 2 + STUD_RADIUS * np.sin(ang),
                np.full_like(ang, BRICK_HEIGHT + STUD_HEIGHT),
            ],
            axis=1,
        )
        for sx in (-1, 1)
        for sy in (-1, 1)
    ]
    return np.concatenate(edges + rims, axis=0)


def lookup(model: mujoco.MjModel, kind: str, name: str) -> int:
    """Index of the ``kind`` (joint, body, geom, site, camera, actuator, light) called ``name``.

    Raises a KeyError listing the valid names instead of returning MuJoCo's -1, which would silently
    index the last element of every array it is used on.
    """
    objtype = getattr(mujoco.mjtObj, f"mjOBJ_{kind.upper()}", None)
    if objtype is None:
        raise ValueError(f"kind={kind!r} is not a MuJoCo object type (joint, body, geom, site, camera, ...)")
    index = mujoco.mj_name2id(model, objtype, name)
    if index < 0:
        count = {"light": model.nlight, "camera": model.ncam, "actuator": model.nu}.get(kind)
        count = count if count is not None else getattr(model, f"n{kind}")
        names = [mujoco.mj_id2name(model, objtype, i) for i in range(count)]
        raise KeyError(
            f"the model has no {kind} named {name!r}; its {kind}s: {', '.join(n for n in names if n)}"
        )
    return index


@dataclass(frozen=True)
class SceneIds:
    """Indices into a compiled lego_pick model."""

    arm_qpos: np.ndarray  # (6,) qpos addresses of the arm joints
    arm_dof: np.ndarray  # (6,) dof addresses of the arm joints
    finger_qpos: np.ndarray  # (2,)
    arm_actuators: np.ndarray  # (6,)
    finger_actuators: np.ndarray  # (2,)
    brick_bodies: np.ndarray  # (12,)
    brick_qpos: np.ndarray  # (12,) start of each brick's 7-float freejoint qpos
    brick_dof: np.ndarray  # (12,) start of each brick's 6 dofs
    brick_geoms: tuple[np.ndarray, ...]  # geoms of each brick (body + studs)
    brick_of_geom: np.ndarray  # (ngeom,) brick index of a geom, -1 when not a brick
    gripper_geoms: np.ndarray  # every geom of the gripper and fingers
    pad_geoms: np.ndarray  # (2,) left and right finger pads
    finger_geoms: tuple[np.ndarray, np.ndarray]  # geoms of the left / right finger
    tcp_site: int
    camera_site: int
    camera: int
    table_geom: int  # the drawn table (its material is randomised)
    table_top_geom: int  # the collision plane of the table top

    @staticmethod
    def of(model: mujoco.MjModel) -> SceneIds:
        """Look up every index once."""

        def jid(name: str) -> int:
            return lookup(model, "joint", name)

        def bid(name: str) -> int:
            return lookup(model, "body", name)

        def gid(name: str) -> int:
            return lookup(model, "geom", name)

        def aid(name: str) -> int:
            return lookup(model, "actuator", name)

        arm_j = [jid(n) for n in ARM_JOINTS]
        bricks = np.array([bid(f"brick_{i}") for i in range(N_BRICKS)])
        brick_j = [jid(f"brick_{i}_joint") for i in range(N_BRICKS)]
        brick_of_geom = np.full(model.ngeom, -1)
        brick_geoms = []
        for i, b in enumerate(bricks):
            geoms = np.flatnonzero(model.geom_bodyid == b)
            brick_of_geom[geoms] = i
            brick_geoms.append(geoms)

        def geoms_of_subtree(root: str) -> np.ndarray:
            root_id = bid(root)
            bodies = [b for b in range(model.nbody) if _is_descendant(model, b, root_id)]
            return np.flatnonzero(np.isin(model.geom_bodyid, bodies))

        return SceneIds(
            arm_qpos=model.jnt_qposadr[arm_j].copy(),
            arm_dof=model.jnt_dofadr[arm_j].copy(),
            finger_qpos=model.jnt_qposadr[[jid(n) for n in FINGER_JOINTS]].copy(),
            arm_actuators=np.array(
                [aid(n) for n in ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")]
            ),
            finger_actuators=np.array([aid("finger_left"), aid("finger_right")]),
            brick_bodies=bricks,
            brick_qpos=model.jnt_qposadr[brick_j].copy(),
            brick_dof=model.jnt_dofadr[brick_j].copy(),
            brick_geoms=tuple(brick_geoms),
            brick_of_geom=brick_of_geom,
            gripper_geoms=geoms_of_subtree("gripper"),
            pad_geoms=np.array([gid("finger_left_pad"), gid("finger_right_pad")]),
            finger_geoms=(geoms_of_subtree("finger_left"), geoms_of_subtree("finger_right")),
            tcp_site=lookup(model, "site", "tcp"),
            camera_site=lookup(model, "site", "camera"),
            camera=lookup(model, "camera", WRIST_CAMERA),
            table_geom=gid("table"),
            table_top_geom=gid("table_top"),
        )


def _is_descendant(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = model.body_parentid[body]
    return root == 0
