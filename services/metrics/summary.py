"""What ``zstack query`` says to a person before the JSON (on stderr): the cameras announced
now, the depth figures when a camera has depth, and every warning of the answer as a WARNING
line, the pool's first. Pure: answer in, text out."""

from __future__ import annotations

from common.contracts import AnnouncedCamera, MetricsAnswer


def camera_line(name: str, a: AnnouncedCamera, width: int) -> str:
    """One announced camera: name, size, rate, yaw, field of view, frame id, source, and
    whether it has depth, and where it stands (when it has depth or a known position)."""
    size = f"{a['width']}x{a['height']}" if a["width"] else "size unknown"
    where = (a.get("mount_x_m", 0.0), a.get("mount_y_m", 0.0), a.get("mount_height_m", 0.0))
    return (
        f"  {name:{width}}  {size:>12}  {a['rate_hz']:5.1f} Hz  yaw {a['mount_yaw_deg']:+4.0f} deg"
        f"  fov {a['hfov_deg']:3.0f} deg  frame_id {a['frame_id'] or '-'}"
        f"  source {a['source'] or '-'}"
        + ("  depth" if a.get("depth") else "")
        + ("  at x {:+.2f} y {:+.2f} height {:.2f} m".format(*where) if any(where) else "")
    )


def depth_lines(answer: MetricsAnswer) -> list[str]:
    """The depth figures, when a camera has depth or the detector took depth images: the
    depth images taken, the colour frames with none in time (pairing misses), the depth
    stage's time, then each depth camera's."""
    announced = answer.get("cameras_announced", {})
    with_depth = [name for name, a in announced.items() if a.get("depth")]
    frames = answer.get("depth_frames", 0)
    if not with_depth and not frames:
        return []
    stage = answer["latency_ms"].get("depth", {})
    out = [
        f"depth: {frames} depth images, {answer.get('depth_unpaired', 0)} colour frames "
        f"without depth in time, depth stage p50 {stage.get('p50', 0.0):.1f} ms "
        f"p95 {stage.get('p95', 0.0):.1f} ms"
    ]
    cameras = answer.get("cameras", {})
    for name in with_depth:
        c = cameras.get(name)
        if c is not None:
            out.append(
                f"  {name}: {c.get('depth_frames', 0)} depth images, "
                f"{c.get('depth_unpaired', 0)} without depth"
            )
    return out


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
    out += depth_lines(answer)
    out += [f"WARNING pool: {line}" for line in answer.get("pool_warnings", [])]
    out += [f"WARNING {name}: {text}" for name, text in answer.get("warnings", {}).items()]
    return out
