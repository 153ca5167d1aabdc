"""Headless RGB-D and segmentation rendering of the overhead camera (one GL render per frame)."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from pushtoknow.common.errors import RenderingUnavailableError

GL_HELP = (
    "headless OpenGL is unavailable (MUJOCO_GL={gl!r}): {err}. Install Debian's "
    "'libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0' and set MUJOCO_GL=egl "
    "(or install 'libosmesa6' and set MUJOCO_GL=osmesa) before starting Python."
)

try:
    import mujoco
except Exception as _e:  # mujoco loads the GL backend named by MUJOCO_GL at import time
    raise RenderingUnavailableError(GL_HELP.format(gl=os.environ.get("MUJOCO_GL"), err=_e)) from _e


class OverheadRenderer:
    """Renders RGB (uint8) and metric depth (float32, metres along the optical axis) together,
    and the object's segmentation on demand, from the model's camera "overhead"."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, object_geoms):
        self.model, self.width, self.height = model, width, height
        self._gl = None
        try:
            self._gl = mujoco.GLContext(width, height)
            self._gl.make_current()
            self._con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        except Exception as e:  # each GL backend fails with its own exception type
            raise RenderingUnavailableError(
                GL_HELP.format(gl=os.environ.get("MUJOCO_GL"), err=f"{type(e).__name__}: {e}")
            ) from e
        self._scene = mujoco.MjvScene(model, maxgeom=256)
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._cam.fixedcamid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "overhead")
        self._opt = mujoco.MjvOption()
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._rgb = np.empty((height, width, 3), dtype=np.uint8)
        self._depth = np.empty((height, width), dtype=np.float32)
        self._object_geoms = np.asarray(sorted(object_geoms))
        extent = model.stat.extent
        self._near = model.vis.map.znear * extent
        self._far = model.vis.map.zfar * extent

    def _draw(self, data: mujoco.MjData, rect: mujoco.MjrRect | None = None) -> None:
        self._gl.make_current()
        mujoco.mjv_updateScene(
            self.model, data, self._opt, None, self._cam, mujoco.mjtCatBit.mjCAT_ALL, self._scene
        )
        mujoco.mjr_render(self._rect if rect is None else rect, self._scene, self._con)

    def rgbd(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """(H, W, 3) uint8 RGB and (H, W) float32 depth in metres."""
        self._draw(data)
        mujoco.mjr_readPixels(self._rgb, self._depth, self._rect, self._con)
        rgb = np.flipud(self._rgb).copy()
        d = np.flipud(self._depth)
        depth = self._near / (1.0 - d * (1.0 - self._near / self._far))
        return rgb, depth.astype(np.float32)

    def segmentation(self, data: mujoco.MjData, scale: int = 1) -> np.ndarray:
        """(scale·H, scale·W) bool mask of the object's geoms, rendered at `scale` × the image
        resolution (the model's offscreen buffer must be that large)."""
        flags = self._scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = 1
        flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = 1
        h, w = scale * self.height, scale * self.width
        if w > self.model.vis.global_.offwidth or h > self.model.vis.global_.offheight:
            raise ValueError(
                f"a {w} × {h} segmentation exceeds the model's offscreen buffer "
                f"({self.model.vis.global_.offwidth} × {self.model.vis.global_.offheight})"
            )
        buf = self._rgb if scale == 1 else np.empty((h, w, 3), dtype=np.uint8)
        try:
            self._draw(data, mujoco.MjrRect(0, 0, w, h))
            mujoco.mjr_readPixels(buf, None, mujoco.MjrRect(0, 0, w, h), self._con)
        finally:
            flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = 0
            flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = 0
        px = np.flipud(buf).astype(np.int64)
        idx = px[..., 0] + px[..., 1] * 256 + px[..., 2] * 65536 - 1  # index into scene.geoms
        ngeom = self._scene.ngeom
        geom_of = np.full(ngeom + 1, -1, dtype=np.int64)
        for i in range(ngeom):
            g = self._scene.geoms[i]
            if g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                geom_of[i] = g.objid
        idx = np.where((idx >= 0) & (idx < ngeom), idx, ngeom)
        return np.isin(geom_of[idx], self._object_geoms)

    def close(self) -> None:
        if getattr(self, "_gl", None) is not None:
            self._con.free()
            self._gl.free()
            self._gl = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
