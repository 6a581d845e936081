"""A recorded RGB-D camera: a folder of colour images with a folder of 16-bit depth PNGs.

``camera.source`` is the colour folder, ``camera.depth_source`` the depth folder. A colour
image is paired with the depth PNG of the same file stem (``rgb/000042.jpg`` with
``depth/000042.png``): pairing by name survives a missing or extra file, where pairing by
order would shift every later pair. A colour image with no depth PNG of its stem is published
without depth (counted: ``depth_missing``); a depth PNG that is not 16-bit single-channel,
cannot be decoded or is not the colour image's size is logged and counted (``bad_depth``), and
that colour image goes without depth.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from common.errors import ConfigError, ImageError
from common.images import Image
from services.camera.depth import DepthImage, check_depth_png, intrinsics_for
from services.camera.sources import FolderSource, FrameSource

DEPTH_SUFFIX = ".png"


class DepthFolder:
    """The 16-bit PNGs of a folder, by file stem."""

    def __init__(self, folder: Path) -> None:
        if not folder.is_dir():
            raise ConfigError(f"camera.depth_source {str(folder)!r}: no such folder")
        self._by_stem = {
            p.stem: p
            for p in sorted(folder.iterdir())
            if p.suffix.lower() == DEPTH_SUFFIX and p.is_file()
        }
        if not self._by_stem:
            raise ConfigError(f"camera.depth_source {str(folder)!r}: no {DEPTH_SUFFIX} files")
        self.description = f"depth folder {folder} ({len(self._by_stem)} PNGs)"

    def __len__(self) -> int:
        return len(self._by_stem)

    def read(self, stem: str, colour_size: tuple[int, int]) -> np.ndarray | None:
        """The (h, w) uint16 depth of ``stem``; None when there is no such PNG; ImageError
        naming the file when it cannot be used (see :func:`check_depth_png`)."""
        path = self._by_stem.get(stem)
        if path is None:
            return None
        try:
            data = np.fromfile(path, dtype=np.uint8)
        except OSError as exc:
            raise ImageError(f"{path}: cannot read ({exc.strerror or exc})") from exc
        decoded = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if decoded is None:
            raise ImageError(f"{path}: not a decodable PNG")
        try:
            return check_depth_png(decoded, colour_size)
        except ImageError as exc:
            raise ImageError(f"{path}: {exc}") from exc


class FolderWithDepth:
    """A colour folder source whose frames each come with the depth PNG of their stem."""

    live = False
    has_depth = True

    def __init__(
        self,
        colour: FolderSource,
        depth: DepthFolder,
        *,
        scale_m: float,
        intrinsics: tuple[float, float, float, float],
        hfov_deg: float,
    ) -> None:
        self._colour = colour
        self._depth = depth
        self._scale_m = scale_m
        self._intrinsics = intrinsics
        self._hfov_deg = hfov_deg
        self._last: tuple[str, tuple[int, int]] | None = None
        self.description = f"{colour.description} with {depth.description}"

    def read(self) -> Image | None:
        image = self._colour.read()
        path = self._colour.last_path
        self._last = None
        if image is not None and path is not None:
            self._last = (path.stem, (int(image.shape[1]), int(image.shape[0])))
        return image

    def depth(self) -> DepthImage | None:
        """The depth of the colour image read last; None when its stem has no PNG."""
        if self._last is None:
            return None
        stem, (width, height) = self._last
        data = self._depth.read(stem, (width, height))
        if data is None:
            return None
        fx, fy, cx, cy = intrinsics_for(self._intrinsics, self._hfov_deg, width, height)
        return DepthImage(data=data, scale_m=self._scale_m, fx=fx, fy=fy, cx=cx, cy=cy)

    def close(self) -> None:
        self._colour.close()


def with_depth_folder(
    source: FrameSource,
    folder: str,
    *,
    scale_m: float,
    intrinsics: tuple[float, float, float, float],
    hfov_deg: float,
) -> FolderWithDepth:
    """``source`` (a folder of colour images) paired with the depth PNGs of ``folder``;
    ConfigError with one line when either is not a folder."""
    if not isinstance(source, FolderSource):
        source.close()
        raise ConfigError(
            f"camera.depth_source needs camera.source to be a folder of colour images, "
            f"got {source.description}"
        )
    depth = DepthFolder(Path(folder).expanduser())
    return FolderWithDepth(source, depth, scale_m=scale_m, intrinsics=intrinsics, hfov_deg=hfov_deg)
