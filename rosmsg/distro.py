"""The ROS 2 distributions the message library speaks (each has its own message types and type
hashes). Imports nothing: the ros2 bridge's contract reads it for its ``distro`` setting."""

from __future__ import annotations

from enum import StrEnum


class RosDistro(StrEnum):
    HUMBLE = "humble"
    JAZZY = "jazzy"
    KILTED = "kilted"
    ROLLING = "rolling"
