"""The virtual laser scan of a depth camera (the library behind the scan stage): a depth image
in, a ``LaserScan`` in the robot's frame out, the way depthimage_to_laserscan turns a depth
image into a scan, with the floor taken out by the camera's mounting. Pure numpy: no bus, no
clock; it imports ``common`` and ``perception``'s public API, never a service.

    frame.py     the samples a scan is made from, whether a frame can be trusted
                 (``implausible``), what a camera cannot see below it (``blind_zone``)
    observe.py   what one frame shows (floor, obstacles, drop-offs, holes) and its scan
    trust.py     whose depth is believed (the announced session, not from the future, one
                 stream per camera)
    local_map.py the depth cameras' short memory: a rolling map of the floor round the robot,
                 moved by the commands sent (Odometry), read as a scan of what it remembers
"""
