"""The ros2 bridge (issue 11): a thin node over the ROS 2 message library (rosmsg/) that carries
the stack's cameras, depth and laser in from a robot's ROS 2 graph and its detections, debug
images and commands out (``service.py``; its depth and 3D detections: ``depth_handlers.py``; the
debug image: ``debug_image.py``). Other packages read only its contract (``contract.py``).
"""
