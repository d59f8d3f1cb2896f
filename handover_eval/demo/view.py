"""The demo's camera: a free MuJoCo camera that frames the handover, rendered offscreen.

The scene's named cameras (``overview``, ``walkby``) frame the person's whole walk, so the robot,
the bottle and the hand are small. :class:`FramedView` renders the env's own model and data
(``env.unwrapped.model`` / ``.data``; only the model's offscreen buffer size and multisampling are
set) through a free camera (``mjvCamera`` with
``lookat``, ``distance``, ``elevation`` and ``azimuth``) aimed at where the object changes hands:
the robot's ready pose (0.3, -0.4, 1.15) and the walkers' passing line (y about -0.9), from ahead
of the walker (who walks toward -x) and to their left, a little above: the walker comes toward
the camera with the robot on their right, and the hand, the bottle and the gripper are in view.
The scene has no skybox, so what lies beyond the floor renders black; those pixels are filled
with a light sky colour (:data:`SKY`).

Shadows and reflections are off and there is no multisampling: on a software renderer (llvmpipe
on 2 cores) that makes a frame about 4x cheaper. What remains is mostly the robot's visual meshes
(about 190,000 triangles), about 0.06 s of CPU per frame whatever its size. Offscreen rendering
needs ``MUJOCO_GL=egl`` or ``osmesa``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: Filled into the pixels the scene leaves empty (no geometry: the black beyond the floor).
SKY = (206, 216, 228)


@dataclass(frozen=True)
class CameraPose:
    """A free camera: the point it looks at (m), its distance (m) and angles (degrees; azimuth 90
    looks along +y, a negative elevation looks down)."""

    lookat: tuple[float, float, float] = (0.3, -0.65, 1.0)
    distance: float = 2.4
    elevation: float = -20.0
    azimuth: float = 30.0


@dataclass(frozen=True)
class ViewSize:
    """Pixels of one side's rendered scene (even: the mp4's frames need even sides)."""

    width: int = 560
    height: int = 420

    def __post_init__(self) -> None:
        for name, v in (("width", self.width), ("height", self.height)):
            if isinstance(v, bool) or int(v) != v or not 16 <= v <= 2048 or v % 2:
                raise ValueError(f"view {name} must be an even whole number of pixels in "
                                 f"[16, 2048], got {v!r}")


class FramedView:
    """Renders ``env``'s current state through the free camera :class:`CameraPose`.

    Args:
        env: a handover env (any wrapper of one); its model's offscreen buffer is enlarged to
            ``size`` if it is smaller (a visual setting, no physics changes).
        pose: the camera.
        size: the frame's pixels.
    """

    def __init__(self, env: Any, pose: CameraPose | None = None,
                 size: ViewSize | None = None) -> None:
        import mujoco

        pose = pose or CameraPose()
        size = size or ViewSize()
        base = env.unwrapped
        model = base.model
        vis = model.vis
        vis.global_.offwidth = max(int(vis.global_.offwidth), size.width)
        vis.global_.offheight = max(int(vis.global_.offheight), size.height)
        vis.quality.offsamples = 0
        self._data = base.data
        self._renderer = mujoco.Renderer(model, size.height, size.width)
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = pose.lookat
        cam.distance = pose.distance
        cam.elevation = pose.elevation
        cam.azimuth = pose.azimuth
        self.camera = cam
        self._off = (int(mujoco.mjtRndFlag.mjRND_SHADOW), int(mujoco.mjtRndFlag.mjRND_REFLECTION))

    def __call__(self) -> np.ndarray:
        """The current frame, (height, width, 3) uint8, its empty background filled with
        :data:`SKY`."""
        r = self._renderer
        r.update_scene(self._data, camera=self.camera)
        for flag in self._off:
            r.scene.flags[flag] = 0
        frame = r.render().copy()
        empty = (frame[..., 0] | frame[..., 1] | frame[..., 2]) == 0
        frame[empty] = SKY
        return frame

    def close(self) -> None:
        """Free the GL context."""
        self._renderer.close()
