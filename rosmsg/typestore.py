"""The ROS 2 message types of each distribution, from rosbags, with vision_msgs added.

rosbags ships the standard packages (std_msgs, geometry_msgs, sensor_msgs, ...) of every
distribution but not vision_msgs; its 4.x definitions are shipped beside this module
(``msg/vision_msgs/*.msg``, identical in Humble, Jazzy, Kilted and Rolling) and registered here.
"""

from __future__ import annotations

import functools
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from rosmsg.distro import RosDistro

MSG_DIR = Path(__file__).with_name("msg")


def _newest_ros2_store() -> Stores:
    # Rolling has no store of its own: take the newest ROS 2 one (members are in release order).
    return [store for store in Stores if store.name.startswith("ROS2_")][-1]


_STORES: dict[RosDistro, Stores] = {
    RosDistro.HUMBLE: Stores.ROS2_HUMBLE,
    RosDistro.JAZZY: Stores.ROS2_JAZZY,
    RosDistro.KILTED: Stores.ROS2_KILTED,
    RosDistro.ROLLING: _newest_ros2_store(),
}


def store_name(distro: RosDistro) -> Stores:
    """The rosbags store that holds ``distro``'s message definitions."""
    return _STORES[RosDistro(distro)]


def shipped_msg_types() -> dict[str, str]:
    """Every ``.msg`` file shipped beside this module: ``pkg/msg/Name`` -> definition text."""
    return {
        f"{path.parent.name}/msg/{path.stem}": path.read_text(encoding="utf-8")
        for path in sorted(MSG_DIR.glob("*/*.msg"))
    }


@functools.cache
def typestore_for(distro: RosDistro) -> Typestore:
    """The rosbags typestore for ``distro``, with the shipped vision_msgs registered (cached).

    The store is shared by every caller: register nothing else into it.
    """
    store = get_typestore(store_name(distro))
    types = {}
    for name, text in shipped_msg_types().items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store
