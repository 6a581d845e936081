"""The simulated world: a robot, people and obstacles on a floor, stepped in scenario time, and
what the robot's sensors see of it. Pure (no bus, no clock): the simulator (services/sim, a thin
node over it) and the tools (tools/scenarios, tools/benchmarks) import its modules directly.

    world.py      ``World``: the robot (a unicycle base), targets, obstacles, walls, drops, stepped
    scenarios.py  ``SCENARIOS``: the named worlds (``python -m tools.scenarios list``)
    cast.py       the scenarios' people (``person``, ``card``)
    rooms.py      rooms: walls, a doorway, every hazard kind, alice walking through
    crowds.py     crowds and occlusion: 3 to 5 people passing, swapping, a pillar, a fast turn
    walls.py      what a camera sees of the walls (``wall_view``: depth and colour per pixel)
    render.py     a camera's colour image of the world (``CameraSpec``, ``layout``)
    body.py       a person's body (``Body``: build, clothes, facing, gait; ``body_for``, ``people``)
    body_draw.py  a body's silhouette, colour and front surface at a yaw and a phase of the walk
    people.py     a body's pose before a camera, and its silhouette scaled to the image
    depth.py      the aligned depth image of the same instant, and its noise (``DepthNoise``)
    faults.py     the harder world's camera faults: flying pixels, bias, mirrors, blur, exposure
    floor.py      where the floor drops away (a drop is seen, never lasered)
    laser.py      the laser's scan (``LaserSpec``, ``cast``)

It imports only ``common``.
"""
