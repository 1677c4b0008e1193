"""The Python client against a real server (address in SSRDRIVE_SERVER; the Rust test
tests/tests/python.rs starts one and runs this suite)."""

import os
import unittest

from ssrdrive import AgentClient, AgentError


def grey(camera, channels=3):
    return bytes([100]) * (camera.width * camera.height * channels)


class ClientTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.client = AgentClient(os.environ["SSRDRIVE_SERVER"])
        cls.client.wait_until_serving(timeout=60)

    def test_info_names_the_model_and_rig(self):
        info = self.client.info()
        self.assertEqual(info.model, "ssr")
        self.assertEqual(info.config_name, "cpu-default")
        rig = self.client.expected_rig()
        self.assertEqual((rig[0].width, rig[0].height), (320, 96))

    def test_an_episode_steps_and_ends(self):
        with self.client.start_episode(client="python test") as episode:
            camera = episode.rig[0]
            for frame in range(3):
                result = episode.step(
                    images=[grey(camera)],
                    speed=4.0,
                    pose=(frame * 0.2, 0.0, 0.0, 0.0),
                    command=4,
                    target_point=(15.0, 0.0),
                    debug=frame == 2,
                )
                self.assertEqual(len(result.trajectory), 6)  # cpu-default plans 3 s
                self.assertTrue(-1.0 <= result.control.steer <= 1.0)
                self.assertTrue(0.0 <= result.control.throttle <= 1.0)
                self.assertGreater(result.timings["total_ms"], 0.0)
            self.assertEqual(len(result.debug.token_attention), 16)
            # BGRA8, CARLA's native format, is accepted too.
            episode.step(images=[grey(camera, 4)], speed=4.0, pose=(1.0, 0, 0, 0), command=4,
                         target_point=(15.0, 0.0), encoding="bgra8")
            self.assertEqual(episode.end(), 4)

    def test_waiting_for_a_missing_server_gives_up_with_the_reason(self):
        lost = AgentClient("127.0.0.1:1")
        with self.assertRaises(AgentError) as caught:
            lost.wait_until_serving(timeout=0.5)
        self.assertEqual(caught.exception.code, "UNAVAILABLE")
        self.assertIn("was not SERVING", caught.exception.message)
        lost.close()

    def test_errors_carry_the_status_and_the_reason(self):
        episode = self.client.start_episode()
        camera = episode.rig[0]
        with self.assertRaises(AgentError) as caught:
            episode.step(images=[b"\x00" * 10], speed=1.0, pose=(0, 0, 0, 0), command=4,
                         target_point=(10.0, 0.0))
        self.assertEqual(caught.exception.code, "INVALID_ARGUMENT")
        self.assertIn("got 10", caught.exception.message)
        with self.assertRaises(AgentError) as caught:
            episode.step(images=[grey(camera)], speed=1.0, pose=(0, 0, 0, 0), command=9,
                         target_point=(10.0, 0.0))
        self.assertIn("command 9", caught.exception.message)
        episode.end()
        with self.assertRaises(AgentError) as caught:
            episode.step(images=[grey(camera)], speed=1.0, pose=(0, 0, 0, 0), command=4,
                         target_point=(10.0, 0.0))
        self.assertEqual(caught.exception.code, "NOT_FOUND")
        with self.assertRaises(ValueError):
            episode.step(images=[], speed=1.0, pose=(0, 0, 0, 0), command=4, target_point=(1, 0))


if __name__ == "__main__":
    unittest.main()
