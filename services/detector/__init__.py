"""The detector service: the newest frame of every camera it serves in, detections out on the
bus (docs/detector.md). ``service.py`` wires it (the bus I/O, the rounds, the pool's
membership), ``pool.py`` is the pool's assignment, ``schedule.py`` the per-camera slots and
fair rounds. Detection itself is the library in perception/; the service loads only what
``zstack prepare`` made (perception.load).
"""
