"""The cameras the simulator renders: every camera of the config, from the same world. Pure.

The first camera (``stack.camera``, the [camera] table) is rendered as a one-camera simulator
always rendered it: ``sim.width`` x ``sim.height`` at ``sim.camera_rate_hz``. A further camera
(``[cameras.<name>]``) with a ``rate_hz`` of its own (one that differs from [camera]'s) is
rendered at that rate; one with [camera]'s rate, which it has unless it states another, is
rendered at the first camera's, ``sim.camera_rate_hz``: each at the rate the first runs at,
not some at [camera]'s and the first at the simulator's. It is rendered at its ``resize`` when
it sets one, else at the simulator's size. Every camera has its own field of view
(``hfov_deg``), mounting yaw (``mount_yaw_deg``), ``frame_id`` and ``jpeg_quality``; all stand
at the robot's centre, ``sim.camera_height_m`` above the floor. Frames are rendered in
scenario time, so no camera is rendered more often than ``sim.physics_hz``.
"""

from __future__ import annotations

from dataclasses import dataclass

from simworld.render import CameraSpec
from stack.config import Config


@dataclass(frozen=True, slots=True)
class SimCamera:
    """One camera as the simulator renders it, and what its frames carry."""

    name: str
    spec: CameraSpec
    rate_hz: float
    frame_id: str
    jpeg_quality: int

    # Where it stands as it is rendered (what its announcement says: common/camera_announce.py
    # ``Described``): at the base's centre, the spec's height up, looking its yaw.
    @property
    def mount_yaw_deg(self) -> float:
        return self.spec.mount_yaw_deg

    @property
    def hfov_deg(self) -> float:
        return self.spec.hfov_deg

    @property
    def mount_height_m(self) -> float:
        return self.spec.height_m

    @property
    def mount_x_m(self) -> float:
        return 0.0

    @property
    def mount_y_m(self) -> float:
        return 0.0


def sim_cameras(config: Config) -> list[SimCamera]:
    """Every configured camera, the first first (see the module's docstring for the rules)."""
    s = config.sim
    out = []
    for name, c in config.all_cameras.items():
        first = name == config.stack.camera
        width, height = (s.width, s.height) if first or c.resize == (0, 0) else c.resize
        spec = CameraSpec(width, height, c.hfov_deg, s.camera_height_m, c.mount_yaw_deg)
        own_rate = not first and c.rate_hz != config.camera.rate_hz
        rate = c.rate_hz if own_rate else s.camera_rate_hz
        out.append(SimCamera(name, spec, rate, c.frame_id, c.jpeg_quality))
    return out
