"""Settings of the ``viewer`` service: the live Foxglove view (services/viewer).

Re-exported by common/settings.py, where the whole Config is assembled.
"""

from __future__ import annotations

from dataclasses import dataclass

from common.errors import ConfigError
from common.setting_checks import positive


def _within(name: str, value: float, lo: float, hi: float) -> None:
    if not lo <= value <= hi:
        raise ConfigError(f"viewer.{name} must be within {lo:g}..{hi:g}, got {value}")


@dataclass(frozen=True, slots=True, kw_only=True)
class ViewerSettings:
    """A Foxglove WebSocket server that shows the stack live (docs/viewer.md).

    It listens on ``host``:``port``; loopback by default, because the view carries the camera's
    images: to watch from a laptop, tunnel the port over SSH, or set ``host = "0.0.0.0"`` on a
    network you trust (the view is read-only, but anyone who reaches it sees the camera).
    Images are JPEG-encoded on the viewer's own thread at most ``image_rate_hz`` times a second
    at ``jpeg_quality``, scaled down to ``max_image_width`` pixels (0 keeps the frame's width);
    frames that arrive faster are dropped and counted. The metrics service is asked
    ``metrics_rate_hz`` times a second; the 3D scene (simulator only) is sent ``scene_rate_hz``
    times a second with the robot's last ``path_points`` positions as its path.
    """

    host: str = "127.0.0.1"
    port: int = 8765
    image_rate_hz: float = 5.0
    jpeg_quality: int = 70
    max_image_width: int = 640
    metrics_rate_hz: float = 1.0
    scene_rate_hz: float = 5.0
    path_points: int = 1000

    def __post_init__(self) -> None:
        if not self.host:
            raise ConfigError("viewer.host must not be empty")
        _within("port", self.port, 1, 65535)
        positive("viewer.image_rate_hz", self.image_rate_hz)
        _within("image_rate_hz", self.image_rate_hz, 0, 60)
        _within("jpeg_quality", self.jpeg_quality, 1, 100)
        if self.max_image_width != 0:
            _within("max_image_width", self.max_image_width, 64, 8192)
        positive("viewer.metrics_rate_hz", self.metrics_rate_hz)
        _within("metrics_rate_hz", self.metrics_rate_hz, 0, 10)
        positive("viewer.scene_rate_hz", self.scene_rate_hz)
        _within("scene_rate_hz", self.scene_rate_hz, 0, 50)
        _within("path_points", self.path_points, 2, 100_000)
