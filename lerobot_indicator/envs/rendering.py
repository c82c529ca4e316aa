"""Fast offscreen RGB-D rendering: one GL pass gives both colour and depth.

``mujoco.Renderer`` needs a second full render for depth and keeps shadows, reflections, skybox and
multisampling (all expensive in software EGL). Observations are compared bit for bit by the indicator
reward, and software GL is deterministic, so the same simulator state always renders the same bytes.

A renderer draws the geoms of the geometry groups it is given (our own scenes: ``RENDER_GROUP``) and no
sites, through a fixed camera of the model (by name) or a :class:`FreeCamera` (for models we did not
write, which have no suitable camera).
"""

from __future__ import annotations

import atexit
import contextlib
import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lerobot_indicator.envs.models import RENDER_GROUP

MM_PER_M = 1000.0
UINT16_MAX = np.iinfo(np.uint16).max


def area_downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """(H*factor, W*factor, ...) -> (H, W, ...): the mean of each factor x factor block (what torch's
    ``F.interpolate(mode="area")`` computes for an integer factor), rounded back for integer images."""
    if factor == 1:
        return image
    h, w = image.shape[0] // factor, image.shape[1] // factor
    blocks = image.reshape(h, factor, w, factor, *image.shape[2:]).mean(axis=(1, 3))
    if np.issubdtype(image.dtype, np.integer):
        return np.rint(blocks).astype(image.dtype)
    return blocks.astype(image.dtype)


def metres_to_uint16_mm(depth_m: np.ndarray, depth_min_m: float, depth_max_m: float) -> np.ndarray:
    """RealSense-style depth: uint16 millimetres, 0 where the depth is outside the sensor's range."""
    valid = (depth_m >= depth_min_m) & (depth_m <= depth_max_m)
    mm = np.rint(np.where(valid, depth_m, 0.0) * MM_PER_M)
    return np.clip(mm, 0, UINT16_MAX).astype(np.uint16)


# Renderers still open at interpreter exit are closed by ``atexit`` while EGL is still up; left to the garbage
# collector, mujoco's GLContext.__del__ prints a traceback during shutdown. The hook is registered after the
# first GL context exists, so it runs before mujoco's own exit hook (eglTerminate; atexit runs last-in first).
_OPEN: weakref.WeakSet[RGBDRenderer] = weakref.WeakSet()


def _close_open_renderers() -> None:
    for renderer in list(_OPEN):
        with contextlib.suppress(Exception):
            renderer.close()


@dataclass(frozen=True)
class FreeCamera:
    """MuJoCo's free camera: looks at ``lookat`` from ``distance`` m, ``azimuth`` / ``elevation`` in degrees
    (MuJoCo's convention: the view direction is (cos el cos az, cos el sin az, sin el)). Its vertical field of
    view is the model's ``vis.global_.fovy``."""

    lookat: tuple[float, float, float]
    distance: float
    azimuth: float
    elevation: float

    @classmethod
    def looking_from(cls, pos: Sequence[float], lookat: Sequence[float]) -> FreeCamera:
        """The free camera at ``pos`` looking at ``lookat`` (world frame, metres), image up towards +z."""
        view = [float(b) - float(a) for a, b in zip(pos, lookat, strict=True)]
        distance = math.sqrt(sum(v * v for v in view))
        if distance == 0.0:
            raise ValueError(f"camera pos {list(pos)} and lookat {list(lookat)} coincide")
        azimuth = math.degrees(math.atan2(view[1], view[0]))
        elevation = math.degrees(math.asin(view[2] / distance))
        return cls(tuple(float(v) for v in lookat), distance, azimuth, elevation)


class RGBDRenderer:
    """Offscreen renderer for one model (one GL context per env instance): the geoms of ``geom_groups``,
    no sites, seen through a fixed camera of the model or a :class:`FreeCamera`."""

    def __init__(
        self,
        model,
        width: int,
        height: int,
        max_geom: int = 2000,
        geom_groups: Sequence[int] = (RENDER_GROUP,),
    ):
        import mujoco

        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            model.vis.global_.offwidth = max(width, model.vis.global_.offwidth)
            model.vis.global_.offheight = max(height, model.vis.global_.offheight)
        self._mj = mujoco
        self.model = model
        self.width, self.height = width, height
        self._gl = mujoco.GLContext(width, height)
        self._gl.make_current()
        self._con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)
        self._scene = mujoco.MjvScene(model, maxgeom=max_geom)
        for flag in ("mjRND_SHADOW", "mjRND_REFLECTION", "mjRND_SKYBOX", "mjRND_FOG", "mjRND_HAZE"):
            self._scene.flags[getattr(mujoco.mjtRndFlag, flag)] = 0
        self._opt = mujoco.MjvOption()
        self._opt.geomgroup[:] = 0
        for group in geom_groups:
            self._opt.geomgroup[group] = 1
        self._opt.sitegroup[:] = 0
        self._cam = mujoco.MjvCamera()
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._rgb = np.empty((height, width, 3), dtype=np.uint8)
        self._zbuf = np.empty((height, width), dtype=np.float32)
        extent = model.stat.extent
        self._near = model.vis.map.znear * extent
        self._far = model.vis.map.zfar * extent
        if not _OPEN:
            atexit.unregister(_close_open_renderers)
            atexit.register(_close_open_renderers)
        _OPEN.add(self)

    def render(self, data, camera: str | FreeCamera, depth: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """(RGB uint8 HxWx3, depth in metres float32 HxW or None) for ``camera`` (the name of a fixed camera
        of the model, or a free camera) at ``data``'s state as it is: the caller runs ``mj_forward`` first
        when ``data``'s derived quantities may be stale."""
        mj = self._mj
        self._gl.make_current()
        if isinstance(camera, FreeCamera):
            self._cam.type = mj.mjtCamera.mjCAMERA_FREE
            self._cam.lookat[:] = camera.lookat
            self._cam.distance = camera.distance
            self._cam.azimuth = camera.azimuth
            self._cam.elevation = camera.elevation
        else:
            self._cam.type = mj.mjtCamera.mjCAMERA_FIXED
            self._cam.fixedcamid = self.model.camera(camera).id
        mj.mjv_updateScene(self.model, data, self._opt, None, self._cam, mj.mjtCatBit.mjCAT_ALL, self._scene)
        mj.mjr_render(self._rect, self._scene, self._con)
        mj.mjr_readPixels(self._rgb, self._zbuf if depth else None, self._rect, self._con)
        rgb = np.flipud(self._rgb).copy()
        if not depth:
            return rgb, None
        z = np.flipud(self._zbuf)
        # OpenGL z-buffer -> metric distance along the optical axis (as mujoco.Renderer does).
        depth_m = self._near / (1.0 - z * (1.0 - self._near / self._far))
        return rgb, depth_m.astype(np.float32)

    def close(self) -> None:
        if self._gl is not None:
            self._gl.make_current()
            self._con.free()
            self._gl.free()
            self._gl = None

    def __del__(self):
        # No contextlib here: at interpreter shutdown module globals may already be None.
        try:  # noqa: SIM105
            self.close()
        except Exception:  # GL may already be gone
            pass
