"""The live view: the stack's camera, detections, scan, world and figures in Foxglove (issue 12).

``service.py`` owns the Zenoh session and the Foxglove WebSocket server; ``convert.py`` and
``scene.py`` turn our messages into Foxglove's, ``pairing.py`` pairs frames with the detections
made on them, ``channels.py`` names the channels and ``layout.py`` builds the Foxglove layout.
See docs/viewer.md.
"""
