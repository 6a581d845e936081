"""Sizes no real message reaches, shared by the decoders and the setting checks without numpy
(the settings are loaded by the e-stop command, which must start fast)."""

from __future__ import annotations

# The most detections one message carries; a Boxes in memory (the decoder's candidates) may
# hold more.
MAX_DETECTIONS = 10000
# Limits that no real camera reaches; anything above is garbage, not a frame.
MAX_IMAGE_SIDE = 16384
# Named per-detection columns (common/boxes.py): how many one Boxes carries, and a name's length.
MAX_COLUMNS = 16
MAX_COLUMN_NAME_CHARS = 64

#: The detector's default pixel budget per frame: 2**25, 32 Mpx. It admits every real camera
#: up to 8K UHD (7680x4320, 33.2 Mpx) and 4096x4096 inspection cameras, and bounds one decoded
#: BGR frame to 96 MiB, where a 16384x16384 JPEG header (the largest a Frame may claim)
#: would make the decoder allocate 768 MiB and more.
DEFAULT_MAX_FRAME_PIXELS = 1 << 25
