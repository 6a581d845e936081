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
