"""The metrics service: FPS, latency per stage and end to end, detections per frame, and
counters, answered over Zenoh (docs/architecture.md). Accuracy on labelled data is a tool:
``tools/evaluation``."""
