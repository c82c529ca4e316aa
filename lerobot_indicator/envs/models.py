"""Scene composition (robosuite models, no robosuite task logic) for the Sawyer table tasks.

robosuite's split: models describe the world, tasks add logic. We compose the MJCF with robosuite's
``Sawyer``/``TableArena``/``ManipulationTask`` and then run raw MuJoCo ourselves, adding what makes it
fast: a mocap body welded to the gripper site (Gym Fetch style end-effector control instead of a Python
OSC every substep), gravity compensation, and an optional light render set (primitive collision shapes
instead of the ~290k-triangle visual meshes) for the offscreen camera. Only render-only fields
(geom group / colour) differ between render sets, so the physics is the same.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lerobot_indicator.envs._robosuite import require_robosuite

# Geom groups as seen by our cameras: RENDER_GROUP is drawn, HIDDEN_GROUP is not.
RENDER_GROUP = 1
HIDDEN_GROUP = 3
EE_SITE = "gripper0_right_grip_site"
MOCAP_BODY = "ee_mocap"
ROBOT_PREFIXES = ("robot0_", "gripper0_", "fixed_mount0_")
# Sawyer-like colours for the light render set (red links, dark grey wrist/gripper, grey mount).
LIGHT_COLOURS = {
    "robot0_": (0.75, 0.1, 0.1, 1.0),
    "gripper0_": (0.2, 0.2, 0.2, 1.0),
    "fixed_mount0_": (0.35, 0.35, 0.35, 1.0),
}


@dataclass(frozen=True)
class SceneSpec:
    """What the compiled scene needs; every field is honoured by :func:`build_sawyer_table_model`."""

    timestep: float = 0.005
    table_full_size: tuple[float, float, float] = (0.8, 0.8, 0.05)
    table_height: float = 0.8
    cameras: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float], float], ...] = ()
    light_render: bool = True
    # Pull towards the home posture (N m / rad): keeps the 7-DoF null space from wandering between episodes.
    joint_stiffness: float = 50.0


def _lookat_xyaxes(pos: np.ndarray, lookat: np.ndarray) -> str:
    forward = lookat - pos
    forward /= np.linalg.norm(forward)
    up = np.array([0.0, 0.0, 1.0])
    if abs(forward @ up) > 0.999:  # looking straight down: use +x as the image "up"
        up = np.array([1.0, 0.0, 0.0])
    x = np.cross(forward, up)
    x /= np.linalg.norm(x)
    y = np.cross(x, forward)
    return " ".join(f"{v:.6f}" for v in (*x, *y))


def add_fixed_camera(worldbody, name: str, pos, lookat, fovy: float) -> None:
    """Append a fixed MJCF camera at ``pos`` looking at ``lookat`` with vertical field of view ``fovy``."""
    import xml.etree.ElementTree as ET

    p, la = np.asarray(pos, float), np.asarray(lookat, float)
    ET.SubElement(
        worldbody,
        "camera",
        name=name,
        mode="fixed",
        pos=" ".join(f"{v:.6f}" for v in p),
        xyaxes=_lookat_xyaxes(p, la),
        fovy=f"{fovy:.6f}",
    )


def sawyer_table_xml(spec: SceneSpec) -> str:
    """MJCF of a Sawyer (default Rethink gripper and mount) at a table, with a mocap-welded end effector."""
    require_robosuite()
    import xml.etree.ElementTree as ET

    from robosuite.models.arenas import TableArena
    from robosuite.models.bases import robot_base_factory
    from robosuite.models.grippers import gripper_factory
    from robosuite.models.robots import Sawyer
    from robosuite.models.tasks import ManipulationTask

    robot = Sawyer()
    robot.add_base(base=robot_base_factory(robot.default_base, idn=0))
    robot.update_joints()
    robot.update_actuators()
    robot.add_gripper(gripper_factory(robot.default_gripper["right"], idn="0_right"), robot.eef_name["right"])
    robot.set_base_xpos(robot.base_xpos_offset["table"](spec.table_full_size[0]))
    arena = TableArena(table_full_size=spec.table_full_size, table_offset=(0, 0, spec.table_height))
    arena.set_origin([0, 0, 0])
    task = ManipulationTask(mujoco_arena=arena, mujoco_robots=[robot])

    mocap = ET.SubElement(task.worldbody, "body", name=MOCAP_BODY, mocap="true", pos="0 0 1")
    ET.SubElement(mocap, "site", name=f"{MOCAP_BODY}_site", size="0.005", group=str(HIDDEN_GROUP))
    # Stiff, position-first weld (torquescale < 1): the gripper follows the mocap within mm everywhere
    # in the documented workspace while its orientation stays fixed to within a few degrees.
    ET.SubElement(
        task.equality,
        "weld",
        site1=f"{MOCAP_BODY}_site",
        site2=EE_SITE,
        solref="0.01 1",
        solimp="0.99 0.99 0.001",
        torquescale="0.3",
    )
    for camera in spec.cameras:
        add_fixed_camera(task.worldbody, *camera)
    return task.get_xml()


def build_sawyer_table_model(spec: SceneSpec):
    """Compile the scene and set the model fields robosuite's XML cannot express for us."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(sawyer_table_xml(spec))
    model.opt.timestep = spec.timestep
    model.vis.quality.offsamples = 0  # no multisampling in the offscreen buffer
    for b in range(model.nbody):
        if model.body(b).name.startswith(ROBOT_PREFIXES):
            model.body_gravcomp[b] = 1.0  # the mocap weld moves the arm; gravity would only bias it
    home = np.asarray(_sawyer_home_qpos())
    for i, q in enumerate(home):
        joint = model.joint(f"robot0_right_j{i}")
        model.jnt_stiffness[joint.id] = spec.joint_stiffness
        model.qpos_spring[joint.qposadr[0]] = q
    _assign_render_groups(model, spec.light_render)
    return model


def _sawyer_home_qpos() -> tuple[float, ...]:
    from robosuite.models.robots import Sawyer

    return tuple(float(v) for v in Sawyer().init_qpos)


def arm_qpos_addresses(model) -> np.ndarray:
    return np.array([model.joint(f"robot0_right_j{i}").qposadr[0] for i in range(7)])


def home_qpos(model) -> np.ndarray:
    """Full qpos with the arm at robosuite's Sawyer home posture (gripper fingers at 0)."""
    qpos = model.qpos0.copy()
    qpos[arm_qpos_addresses(model)] = _sawyer_home_qpos()
    return qpos


def _assign_render_groups(model, light: bool) -> None:
    """Decide, per geom, whether our cameras draw it (render-only fields; contacts are unaffected).

    ``light``: robot/gripper/mount drawn with their primitive collision shapes, everything else with its
    non-mesh visual geoms (table top, legs, floor). Otherwise: robosuite's visual geoms (meshes).
    """
    import mujoco

    for g in range(model.ngeom):
        body = model.body(model.geom_bodyid[g]).name
        is_robot = body.startswith(ROBOT_PREFIXES)
        is_collision = model.geom_group[g] == 0
        is_visual = model.geom_group[g] == 1
        is_mesh = model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
        light_show = (is_robot and is_collision) or (not is_robot and is_visual and not is_mesh)
        show = light_show if light else is_visual
        model.geom_group[g] = RENDER_GROUP if show else HIDDEN_GROUP
        if light and show and is_robot:
            model.geom_matid[g] = -1
            prefix = next(p for p in ROBOT_PREFIXES if body.startswith(p))
            model.geom_rgba[g] = LIGHT_COLOURS[prefix]
