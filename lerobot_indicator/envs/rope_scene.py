"""MJCF for the rope-push scene: robosuite's table arena, a 15-link rope and a floating Sawyer-style pusher.

MuJoCo 3 dropped ``composite type="rope"`` (the authors' model), so the rope is rebuilt as the
equivalent explicit chain: capsule links (radius 0.01 m, half-length 0.015 m, spacing 0.04 m, so
neighbours overlap like the old composite), ball joints with damping 0.005 between links and a free
joint on the first link. An explicit chain rather than the cable composite keeps every link a plain
body whose centre is a geom position (the 45-/30-number state) and needs no elasticity plugin; being
jointed in generalised coordinates, links cannot come apart.

The pusher is the authors' "floating gripper": a mocap body shaped like the Sawyer's closed two-finger
gripper in its fixed (vertical) orientation, moved kinematically. It collides with the rope only (a
mocap body is welded to the world for collision filtering, so it never hits the table). Its body origin
is the bottom centre of the fingers, so its height is the end-effector height of the push.

Solver settings differ from robosuite's defaults for speed (the rope is light and slow): Euler
integration (joint damping is still implicit), pyramidal friction cones, impratio 1, condim 3 (the
authors used 4; torsional friction costs ~40% per step and hardly matters for a rope pushed sideways).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

from lerobot_indicator.envs._robosuite import require_robosuite
from lerobot_indicator.envs.models import HIDDEN_GROUP, RENDER_GROUP, add_fixed_camera


@dataclass(frozen=True)
class RopeGeometry:
    """Rope, table and pusher dimensions (authors' rope; table surface at robosuite's default height)."""

    n_links: int = 15
    spacing: float = 0.04
    radius: float = 0.01
    half_length: float = 0.015
    joint_damping: float = 0.005
    friction: float = 1.0
    table_top_z: float = 0.8
    table_half_extent: float = 0.8
    # Pusher (closed Sawyer fingers seen from above): half sizes in x, y, z.
    pusher_half_size: tuple[float, float, float] = (0.012, 0.02, 0.04)
    # Where the pusher waits between pushes: outside the camera's view and above everything.
    park_pos: tuple[float, float, float] = (0.0, 1.5, 1.6)

    def __post_init__(self):
        if self.n_links < 2:
            raise ValueError(f"rope n_links must be >= 2, got {self.n_links}")
        for key in ("spacing", "radius", "half_length"):
            if getattr(self, key) <= 0:
                raise ValueError(f"rope {key} must be > 0, got {getattr(self, key)}")

    @property
    def rope_length(self) -> float:
        return self.spacing * (self.n_links - 1)


ROPE_LINK_RGBA = "0.85 0.25 0.1 1"
PUSHER_RGBA = "0.15 0.15 0.15 1"
# How the links are coloured: "single" (ROPE_LINK_RGBA for all) or "tab20" (link i in matplotlib's tab20
# colour i, as the authors' rope env colours its links differently; render-only, the physics is the same).
LINK_COLOURS = ("single", "tab20")


def check_link_colours(scheme: str) -> None:
    """Raise one line naming the field when ``scheme`` is not one of :data:`LINK_COLOURS`."""
    if scheme not in LINK_COLOURS:
        raise ValueError(f"link_colours: unknown {scheme!r}; expected one of {LINK_COLOURS}")


# Where the pusher rests between pushes, so what the camera shows of it: "out_of_view" (parked outside the
# view: images show the table and the rope only) or "push_end" (lifted above the end point of the last
# push that ran, as an arm that stays where its push ended; the images then show where the policy pushed).
PUSHER_RESTS = ("out_of_view", "push_end")


def check_pusher_rest(rest: str) -> None:
    """Raise one line naming the field when ``rest`` is not one of :data:`PUSHER_RESTS`."""
    if rest not in PUSHER_RESTS:
        raise ValueError(f"pusher_rest: unknown {rest!r}; expected one of {PUSHER_RESTS}")


def link_colours_rgba(scheme: str, n_links: int) -> list[tuple[float, float, float, float]]:
    """One RGBA per link for ``scheme`` (one of :data:`LINK_COLOURS`)."""
    check_link_colours(scheme)
    if scheme == "single":
        return [tuple(float(v) for v in ROPE_LINK_RGBA.split())] * n_links
    from matplotlib import colormaps  # "tab20"

    palette = colormaps["tab20"].colors
    if n_links > len(palette):
        raise ValueError(f"link_colours 'tab20' has {len(palette)} colours, the rope has {n_links} links")
    return [(*palette[i], 1.0) for i in range(n_links)]


def link_geom_name(i: int) -> str:
    return f"rope_g{i}"


PUSHER_BODY = "pusher"


def _rope_xml(geom: RopeGeometry) -> str:
    """Nested chain of bodies; link 0 carries the free joint, link i>0 a ball joint at its joint point."""
    z = geom.table_top_z + geom.radius
    x0 = -geom.rope_length / 2
    contact = f'condim="3" friction="{geom.friction} 0.005 0.0001" solref="0.01 1" solimp="0.95 0.95 0.01"'
    capsule = (
        '<geom name="{name}" type="capsule" '
        f'fromto="{-geom.half_length} 0 0 {geom.half_length} 0 0" size="{geom.radius}" '
        f'rgba="{ROPE_LINK_RGBA}" {contact} density="1000"/>'
    )
    parts = [f'<body name="rope_b0" pos="{x0} 0 {z}"><freejoint name="rope_free"/>']
    parts.append(capsule.format(name=link_geom_name(0)))
    for i in range(1, geom.n_links):
        parts.append(
            f'<body name="rope_b{i}" pos="{geom.spacing} 0 0">'
            f'<joint name="rope_j{i}" type="ball" pos="{-geom.spacing / 2} 0 0" '
            f'damping="{geom.joint_damping}" armature="1e-5"/>' + capsule.format(name=link_geom_name(i))
        )
    parts.append("</body>" * geom.n_links)
    return "".join(parts)


def _pusher_xml(geom: RopeGeometry) -> str:
    hx, hy, hz = geom.pusher_half_size
    px, py, pz = geom.park_pos
    contact = f'condim="3" friction="{geom.friction} 0.005 0.0001" solref="0.01 1" solimp="0.95 0.95 0.01"'
    visual = f'contype="0" conaffinity="0" group="{RENDER_GROUP}"'
    return (
        f'<body name="{PUSHER_BODY}" mocap="true" pos="{px} {py} {pz}">'
        f'<geom name="pusher_collision" type="box" size="{hx} {hy} {hz}" pos="0 0 {hz}" '
        f'group="{HIDDEN_GROUP}" {contact}/>'
        # Visual: two fingers (the collision box split in two) under the gripper palm.
        f'<geom name="pusher_finger_l" type="box" size="{hx} {hy / 2 - 0.002} {hz}" pos="0 {hy / 2 + 0.002} {hz}" '
        f'{visual} rgba="{PUSHER_RGBA}"/>'
        f'<geom name="pusher_finger_r" type="box" size="{hx} {hy / 2 - 0.002} {hz}" pos="0 {-hy / 2 - 0.002} {hz}" '
        f'{visual} rgba="{PUSHER_RGBA}"/>'
        f'<geom name="pusher_palm" type="box" size="0.03 0.045 0.02" pos="0 0 {2 * hz + 0.02}" '
        f'{visual} rgba="0.3 0.3 0.3 1"/>'
        "</body>"
    )


def build_rope_model(
    geom: RopeGeometry,
    camera: tuple[str, tuple[float, float, float], tuple[float, float, float], float],
    timestep: float = 0.005,
    link_colours: str = "single",
):
    """Compile the scene with one fixed camera ``(name, pos, lookat, fovy_deg)`` (the shared camera config)
    and the links coloured by ``link_colours`` (:data:`LINK_COLOURS`)."""
    rgba = link_colours_rgba(link_colours, geom.n_links)
    require_robosuite()
    from robosuite.models.arenas import TableArena
    from robosuite.models.world import MujocoWorldBase

    world = MujocoWorldBase()
    arena = TableArena(
        table_full_size=(2 * geom.table_half_extent, 2 * geom.table_half_extent, 0.05),
        table_offset=(0, 0, geom.table_top_z),
    )
    world.merge(arena)
    for snippet in (_rope_xml(geom), _pusher_xml(geom)):
        world.worldbody.append(ET.fromstring(snippet))
    add_fixed_camera(world.worldbody, *camera)
    option = world.root.find("option")
    for key, value in {
        "timestep": str(timestep),
        "integrator": "Euler",
        "cone": "pyramidal",
        "impratio": "1",
    }.items():
        option.set(key, value)
    model = world.get_model(mode="mujoco")
    model.vis.quality.offsamples = 0  # no multisampling in the offscreen buffer (as the reach scene)
    # Rope links are group 0 in the XML (robosuite's base counts only group-0 geoms for inertia);
    # moving them to the render group afterwards changes nothing physical.
    for i in range(geom.n_links):
        model.geom_group[model.geom(link_geom_name(i)).id] = RENDER_GROUP
        model.geom_rgba[model.geom(link_geom_name(i)).id] = rgba[i]
    return model
