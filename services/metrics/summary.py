"""What ``zstack query`` says to a person before the JSON (on stderr): the cameras announced
now, and every warning of the answer as a WARNING line, the pool's first. Pure: answer in, text
out."""

from __future__ import annotations

from common.contracts import AnnouncedCamera, MetricsAnswer


def camera_line(name: str, a: AnnouncedCamera, width: int) -> str:
    """One announced camera: name, size, rate, yaw, field of view, frame id, source."""
    size = f"{a['width']}x{a['height']}" if a["width"] else "size unknown"
    return (
        f"  {name:{width}}  {size:>12}  {a['rate_hz']:5.1f} Hz  yaw {a['mount_yaw_deg']:+4.0f} deg"
        f"  fov {a['hfov_deg']:3.0f} deg  frame_id {a['frame_id'] or '-'}"
        f"  source {a['source'] or '-'}"
    )


def summary(answer: MetricsAnswer, prefix: str) -> list[str]:
    """The lines for ``answer`` of the stack under ``prefix``."""
    out = []
    cameras = answer.get("cameras_announced")
    if cameras is not None:  # absent: a metrics service older than the announcements
        if cameras:
            out.append(f"cameras announced under {prefix}: {len(cameras)}")
            width = max(len(name) for name in cameras)
            out += [camera_line(name, a, width) for name, a in cameras.items()]
        else:
            out.append(
                f"WARNING no camera is announced under {prefix}: the detector, the controller "
                "and the metrics take their cameras from the announcements of the camera, the "
                "simulator, the ROS 2 bridge or zstack play"
            )
    out += [f"WARNING pool: {line}" for line in answer.get("pool_warnings", [])]
    out += [f"WARNING {name}: {text}" for name, text in answer.get("warnings", {}).items()]
    return out
