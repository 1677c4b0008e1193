"""Python client of the ssrdrive agent service (package ``ssrdrive.v1`` in ../ssrdrive/v1/agent.proto).

- :mod:`ssrdrive.client`: :class:`AgentClient` and :class:`Episode`, a small typed wrapper over
  the generated gRPC stubs.
- :mod:`ssrdrive.carla_agent`: ``SsrAgent``, a CARLA leaderboard ``AutonomousAgent`` that forwards
  camera, speed, pose (from GNSS and compass), command and target point to the server.

Frames and units are those of the proto: world frame = OpenDRIVE map frame (x east, y north, z up,
metres; a CARLA (x, y, yaw) is (x, -y, -yaw)); ego frame = x forward, y left; steer +1 = right.
"""

from ssrdrive.client import AgentClient, AgentError, Camera, Control, Episode, StepResult

__all__ = ["AgentClient", "AgentError", "Camera", "Control", "Episode", "StepResult"]
