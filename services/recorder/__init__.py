"""The recorder: the stack's keys to MCAP, recordings back onto the bus, runs compared.

channels.py   what each message becomes in a file: ROS 2 CDR with ros2msg schemas where a
              ROS type exists (the bridge's topics), JSON on the stack's key otherwise
writer.py     the bounded queue, the writer thread, chunks flushed as they finish
reading.py    reading ours and rosbag2's MCAP files; corrupt, truncated, foreign: one line
timing.py     a replay's clock and restamping
runs.py, compare.py, plots.py   a recorded run; matching detections, commands, latency
service.py    the bus I/O: record, and play what play.py reads back at its recorded timing
play.py       a recording's frames and scans, restamped, for service.py to publish
bench.py      the stack with and without the recorder, side by side
"""
