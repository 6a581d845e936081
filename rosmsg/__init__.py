"""The ROS 2 message library: the stack's messages to and from ROS 2 nodes that run rmw_zenoh,
without a ROS install (issue 11). Every node that speaks ROS imports it: the ros2 bridge
(services/ros2, a thin node over it), the simulator playing a ROS robot, the recorder's MCAP
channels and the tools. Import its modules directly; this package exports nothing.

    distro.py      ``RosDistro``: the distributions spoken (the bridge's contract reads it)
    typestore.py   ``typestore_for``: rosbags' message types per distribution, with the
                   vision_msgs definitions shipped in ``msg/`` registered
    wire.py        rmw_zenoh's keys (``data_key``), per-sample ``Attachment``, liveliness
                   tokens, GIDs and QoS strings (docs/ros2.md states the format)
    convert.py     ``cdr_encode``/``cdr_decode`` (garbage raises DecodeError) and the
                   translations of scans, 2D detections and twists (``*_to_ros``, ``*_from_ros``)
    images.py      frames to and from ``sensor_msgs`` Image and CompressedImage
    depth.py       depth images, ``CameraInfo`` and 3D detections
    graph.py       ``RosGraph``: a node in a ROS 2 graph (the session, its publishers and
                   subscribers, their liveliness tokens); the one module here that does I/O

Every module but ``graph.py`` imports no zenoh. The library imports ``common`` and, for the
depth columns and a camera's mounting, the detection library's public API (``perception``).
"""
