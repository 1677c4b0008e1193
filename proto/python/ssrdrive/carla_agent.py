"""A CARLA leaderboard (1.0) agent that drives through an ssrdrive server.

Run it like any leaderboard agent, with this package on the Python path::

    PYTHONPATH=proto/python:$PYTHONPATH SSRDRIVE_SERVER=localhost:50051 \\
        python leaderboard_evaluator.py --agent=proto/python/ssrdrive/carla_agent.py ...

The agent config file holds the server address (``host:port``); ``SSRDRIVE_SERVER`` overrides
it. Each tick the agent forwards the rig's camera images (CARLA's BGRA), the speedometer, the
pose from GNSS and compass, and the route follower's command and target point (TCP's: the next
plan node beyond 4 m, looking at most 50 m ahead), and returns the server's control.

Conversions (CARLA -> ssrdrive world frame, the OpenDRIVE map frame): GNSS latitude/longitude
become metres north/east with TCP's scale (x = lon * 111319.49, y = lat * 111324.61); CARLA's
compass (radians clockwise from north) becomes yaw = pi/2 - compass (counter-clockwise from east).
Without the leaderboard installed, a minimal stand-in base class with the same interface is
used (so the adapter can be tested with fake sensor data).
"""

from __future__ import annotations

import math
import os
from collections import deque
from types import SimpleNamespace

from ssrdrive.client import AgentClient, AgentError

try:  # pragma: no cover - only inside a CARLA leaderboard installation
    import carla
    from leaderboard.autoagents.autonomous_agent import AutonomousAgent, Track
except ImportError:
    carla = None

    class Track:  # the leaderboard's enum, as far as this agent uses it
        SENSORS = "SENSORS"

    class AutonomousAgent:
        """The leaderboard 1.0 AutonomousAgent interface used here."""

        def __init__(self, path_to_conf_file):
            self.track = Track.SENSORS
            self._global_plan = None
            self._global_plan_world_coord = None
            self.setup(path_to_conf_file)

        def set_global_plan(self, global_plan_gps, global_plan_world_coord):
            self._global_plan_world_coord = global_plan_world_coord
            self._global_plan = global_plan_gps

        def destroy(self):
            pass


#: Metres per degree of latitude and longitude in CARLA's GNSS (TCP's RoutePlanner scale).
LAT_SCALE = 111324.60662786
LON_SCALE = 111319.490945


def entry_point():
    return "SsrAgent"


def get_entry_point():
    return "SsrAgent"


def gnss_to_world(lat: float, lon: float):
    """(x east, y north) metres in the world frame from CARLA GNSS degrees."""
    return lon * LON_SCALE, lat * LAT_SCALE


def compass_to_yaw(compass: float) -> float:
    """World yaw (counter-clockwise from east) from CARLA's compass (clockwise from north)."""
    yaw = math.pi / 2 - compass
    return math.atan2(math.sin(yaw), math.cos(yaw))


def to_ego(point, position, yaw):
    """A world point in the ego frame (x forward, y left)."""
    dx, dy = point[0] - position[0], point[1] - position[1]
    c, s = math.cos(yaw), math.sin(yaw)
    return c * dx + s * dy, -s * dx + c * dy


class RouteFollower:
    """TCP's RoutePlanner.run_step: skip plan nodes within ``min_distance``, looking at most
    ``max_distance`` along the plan, and return the next one (position, command value).

    One departure from TCP, as sim-bridge's follower: a node that the plan reaches heading more
    than 120 degrees from the ego's ``yaw`` is not skipped, so that at the neck of a U-turn loop,
    where the way back runs beside the way in, the target does not jump past the loop."""

    def __init__(self, plan, min_distance: float = 4.0, max_distance: float = 50.0):
        if not plan:
            raise ValueError("the global plan is empty")
        self.route = deque(plan)
        self.min_distance = min_distance
        self.max_distance = max_distance

    def step(self, position, yaw: float):
        if len(self.route) == 1:
            return self.route[0]
        heading = (math.cos(yaw), math.sin(yaw))
        to_pop, farthest, cumulative = 0, -math.inf, 0.0
        for i in range(1, len(self.route)):
            if cumulative > self.max_distance:
                break
            (x0, y0), (x1, y1) = self.route[i - 1][0][:2], self.route[i][0][:2]
            length = math.hypot(x1 - x0, y1 - y0)
            cumulative += length
            against = (x1 - x0) * heading[0] + (y1 - y0) * heading[1] < -0.5 * length
            distance = math.dist(self.route[i][0], position)
            if distance <= self.min_distance and distance > farthest and not against:
                farthest, to_pop = distance, i
        for _ in range(to_pop):
            if len(self.route) > 2:
                self.route.popleft()
        return self.route[1]


def _command_value(option) -> int:
    """A RoadOption (enum with .value, or an int) as its CARLA value; VOID stays -1."""
    return int(getattr(option, "value", option))


class SsrAgent(AutonomousAgent):
    """Forwards every tick to the ssrdrive server (see the module doc)."""

    def setup(self, path_to_conf_file):
        self.track = Track.SENSORS
        target = os.environ.get("SSRDRIVE_SERVER")
        if not target and path_to_conf_file and os.path.exists(path_to_conf_file):
            with open(path_to_conf_file, encoding="utf-8") as config:
                target = config.read().strip()
        if not target:
            raise ValueError("no server address: set SSRDRIVE_SERVER or pass it as the agent config")
        self.client = AgentClient(target)
        self.client.wait_until_serving()
        self.rig = self.client.expected_rig()
        self.episode = None
        self.follower = None
        # Facing north until the compass says otherwise (TCP reads a NaN compass as north).
        self.yaw = math.pi / 2

    def sensors(self):
        cameras = [
            {
                "type": "sensor.camera.rgb",
                "id": c.id,
                "x": c.x, "y": c.y, "z": c.z,
                "roll": c.roll, "pitch": c.pitch, "yaw": c.yaw,
                "width": c.width, "height": c.height, "fov": c.fov,
            }
            for c in self.rig
        ]
        return cameras + [
            {"type": "sensor.other.imu", "id": "imu", "x": 0.0, "y": 0.0, "z": 0.0,
             "roll": 0.0, "pitch": 0.0, "yaw": 0.0, "sensor_tick": 0.05},
            {"type": "sensor.other.gnss", "id": "gps", "x": 0.0, "y": 0.0, "z": 0.0,
             "roll": 0.0, "pitch": 0.0, "yaw": 0.0, "sensor_tick": 0.01},
            {"type": "sensor.speedometer", "id": "speed", "reading_frequency": 20},
        ]

    def _start(self):
        plan = [
            (gnss_to_world(gps["lat"], gps["lon"]), _command_value(option))
            for gps, option in self._global_plan
        ]
        self.follower = RouteFollower(plan)
        self.episode = self.client.start_episode(self.rig, client="carla leaderboard")

    def run_step(self, input_data, timestamp):
        if self.episode is None:
            self._start()
        lat, lon = input_data["gps"][1][:2]
        position = gnss_to_world(lat, lon)
        compass = float(input_data["imu"][1][-1])
        if not math.isnan(compass):
            self.yaw = compass_to_yaw(compass)
        yaw = self.yaw
        speed = float(input_data["speed"][1]["speed"])
        node, command = self.follower.step(position, yaw)
        target_point = to_ego(node, position, yaw)
        images = [input_data[c.id][1] for c in self.rig]
        result = self.episode.step(
            images=images,
            speed=speed,
            pose=(position[0], position[1], 0.0, yaw),
            command=command,
            target_point=target_point,
            timestamp=timestamp,
            encoding="bgra8",
        )
        c = result.control
        if carla is not None:  # pragma: no cover
            return carla.VehicleControl(steer=c.steer, throttle=c.throttle, brake=c.brake)
        return SimpleNamespace(steer=c.steer, throttle=c.throttle, brake=c.brake)

    def destroy(self):
        """Ends the episode; never raises while the leaderboard cleans up."""
        if self.episode is not None:
            try:
                self.episode.end()
            except AgentError:
                pass
            self.episode = None
        self.client.close()
