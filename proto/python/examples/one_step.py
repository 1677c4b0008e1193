"""One step of a served agent from Python, on a synthetic frame.

    target/release/ssr-agent serve --listen 127.0.0.1:50051 &
    python3 proto/python/examples/one_step.py 127.0.0.1:50051

Frames are raw RGB8, width * height * 3 bytes per camera, at the size of the rig the server
expects (``episode.rig``); here every pixel is grey.
"""

import sys

from ssrdrive import AgentClient

address = sys.argv[1] if len(sys.argv) > 1 else "127.0.0.1:50051"
client = AgentClient(address)
client.wait_until_serving(timeout=60)  # NOT_SERVING until the model has warmed up
with client.start_episode() as episode:  # the rig the server expects; ends on exit
    frames = [bytes([100]) * (c.width * c.height * 3) for c in episode.rig]
    result = episode.step(
        images=frames,
        speed=0.0,
        pose=(0.0, 0.0, 0.0, 0.0),  # x, y, z (map frame, m), yaw (rad)
        command=4,  # LANEFOLLOW
        target_point=(15.0, 0.0),  # ego frame: 15 m ahead
    )
    print("control", result.control)
    print("first waypoints", result.trajectory[:2])
    print("step ms", result.timings["total_ms"])
client.close()
