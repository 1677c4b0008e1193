"""The CARLA leaderboard adapter with fake sensor data (CARLA itself is not installed): the
geometry conversions, TCP's route follower, and whole ticks against a real server."""

import math
import os
import unittest
from dataclasses import replace
from enum import Enum

from ssrdrive import carla_agent
from ssrdrive.carla_agent import (
    LAT_SCALE,
    LON_SCALE,
    RouteFollower,
    SsrAgent,
    compass_to_yaw,
    gnss_to_world,
    to_ego,
)
from ssrdrive.client import AgentClient, AgentError


class RoadOption(Enum):  # CARLA's agents.navigation.local_planner.RoadOption values
    VOID = -1
    LEFT = 1
    RIGHT = 2
    STRAIGHT = 3
    LANEFOLLOW = 4


class FakeImage:
    """Stands in for the numpy BGRA array CARLA hands over."""

    def __init__(self, width, height):
        self.data = bytes([90, 120, 150, 255]) * (width * height)

    def tobytes(self):
        return self.data


def gps(x, y):
    """CARLA GNSS (lat, lon) of a world point (x east, y north)."""
    return {"lat": y / LAT_SCALE, "lon": x / LON_SCALE, "z": 0.0}


class GeometryTest(unittest.TestCase):
    def test_gnss_and_compass_convert_to_the_world_frame(self):
        x, y = gnss_to_world(20.0 / LAT_SCALE, 10.0 / LON_SCALE)
        self.assertAlmostEqual(x, 10.0)
        self.assertAlmostEqual(y, 20.0)
        # Compass 0 faces north (+y): yaw pi/2. Compass pi/2 faces east: yaw 0.
        self.assertAlmostEqual(compass_to_yaw(0.0), math.pi / 2)
        self.assertAlmostEqual(compass_to_yaw(math.pi / 2), 0.0)
        # Facing north, a point to the east is on the right (negative y in the ego frame).
        forward, left = to_ego((5.0, 0.0), (0.0, 0.0), math.pi / 2)
        self.assertAlmostEqual(forward, 0.0)
        self.assertAlmostEqual(left, -5.0)

    def test_route_follower_skips_nodes_within_four_metres(self):
        plan = [((0.0, 0.0), 4), ((3.0, 0.0), 4), ((10.0, 0.0), 1), ((20.0, 0.0), 4)]
        follower = RouteFollower(plan)
        # (3, 0) is within 4 m of the start, so it is passed: the next node is (10, 0).
        self.assertEqual(follower.step((0.0, 0.0), 0.0), ((10.0, 0.0), 1))
        self.assertEqual(follower.step((5.0, 0.0), 0.0), ((10.0, 0.0), 1))
        # At x = 7, (10, 0) is within 4 m too: the target moves on to (20, 0).
        self.assertEqual(follower.step((7.0, 0.0), 0.0), ((20.0, 0.0), 4))

    def test_route_follower_does_not_skip_a_u_turn_loop_at_its_neck(self):
        # West into a loop, back east a lane's width beside the way in (sim-bridge's test).
        plan = [((10.0, 0.0), 4), ((-30.0, -1.0), 4), ((-1.0, -3.5), 4), ((50.0, -3.5), 4)]
        follower = RouteFollower(plan)
        # At the neck heading west, the way back's node (3.6 m off) is not passed.
        self.assertEqual(follower.step((0.0, 0.0), math.pi), ((-30.0, -1.0), 4))
        # Heading east on the way back, it is.
        self.assertEqual(follower.step((-2.0, -3.5), 0.0), ((50.0, -3.5), 4))


class AdapterTest(unittest.TestCase):
    def test_ticks_reach_the_server_and_return_control(self):
        self.assertIn("SSRDRIVE_SERVER", os.environ)
        agent = SsrAgent("")
        sensors = agent.sensors()
        camera = sensors[0]
        self.assertEqual(camera["type"], "sensor.camera.rgb")
        self.assertEqual((camera["width"], camera["height"], camera["x"], camera["z"]),
                         (320, 96, -1.5, 2.0))
        self.assertEqual({s["id"] for s in sensors[1:]}, {"imu", "gps", "speed"})
        plan = [(gps(0.0, 10.0 * i), RoadOption.LANEFOLLOW) for i in range(10)]
        agent.set_global_plan(plan, [None] * len(plan))
        for tick in range(3):
            north = 0.5 * tick
            input_data = {
                camera["id"]: (tick, FakeImage(camera["width"], camera["height"])),
                "gps": (tick, [north / LAT_SCALE, 0.0, 0.0]),
                "imu": (tick, [0.0, 0.0, 9.8, 0.0, 0.0, 0.0, 0.0]),  # compass 0: north
                "speed": (tick, {"speed": 5.0}),
            }
            control = agent.run_step(input_data, tick * 0.05)
            self.assertTrue(-1.0 <= control.steer <= 1.0)
            self.assertTrue(0.0 <= control.brake <= 1.0)
        # Facing north along a plan that runs north, the target point is straight ahead.
        node, command = agent.follower.step(gnss_to_world(1.0 / LAT_SCALE, 0.0), compass_to_yaw(0.0))
        forward, left = to_ego(node, (0.0, 1.0), compass_to_yaw(0.0))
        self.assertGreater(forward, 0.0)
        self.assertAlmostEqual(left, 0.0, places=6)
        self.assertEqual(command, 4)
        episode = agent.episode
        agent.destroy()
        self.assertIsNone(agent.episode)
        self.assertEqual(carla_agent.get_entry_point(), "SsrAgent")
        # destroy() closed the episode on the server: another client cannot end it again.
        other = AgentClient(os.environ["SSRDRIVE_SERVER"])
        with self.assertRaises(AgentError) as ended:
            replace(episode, client=other).end()
        self.assertEqual(ended.exception.code, "NOT_FOUND")
        other.close()


if __name__ == "__main__":
    unittest.main()
