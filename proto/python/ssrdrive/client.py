"""A small typed wrapper over the generated ``ssrdrive.v1.AgentService`` stubs.

    client = AgentClient("localhost:50051")
    client.wait_until_serving()
    with client.start_episode() as episode:          # the rig the server expects
        result = episode.step(images=[rgb_bytes], speed=5.0, pose=(x, y, 0.0, yaw),
                              command=4, target_point=(12.0, 0.5))
        result.control.steer, result.trajectory

Errors come back as :class:`AgentError` carrying the gRPC status code name and the server's
message (which names the field or camera at fault).
"""

from __future__ import annotations

import os
import time
import uuid
from dataclasses import dataclass, field
from typing import Optional, Sequence

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from ssrdrive.stubs import load

pb, pb_grpc = load()

ENCODINGS = {
    "rgb8": pb.IMAGE_ENCODING_RGB8,
    "bgra8": pb.IMAGE_ENCODING_BGRA8,
    "png": pb.IMAGE_ENCODING_PNG,
    "jpeg": pb.IMAGE_ENCODING_JPEG,
}


class AgentError(Exception):
    """A refused or failed call: ``code`` is the gRPC status name (e.g. ``INVALID_ARGUMENT``)."""

    def __init__(self, code: str, message: str):
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message


# Metadata every call of an episode carries: a key chosen here, which a load balancer in front
# of several servers hashes to keep the episode on the replica holding its temporal state
# (ssrdrive_proto::EPISODE_KEY_HEADER; docker/envoy/).
EPISODE_KEY_HEADER = "x-ssrdrive-episode-key"
# Metadata the server answers with: its replica id.
REPLICA_HEADER = "x-ssrdrive-replica"


def _call(function, request, timeout, key: Optional[str] = None):
    metadata = ((EPISODE_KEY_HEADER, key),) if key else None
    try:
        return function(request, timeout=timeout, metadata=metadata)
    except grpc.RpcError as error:
        raise AgentError(error.code().name, error.details() or "") from error


@dataclass(frozen=True)
class Camera:
    """One camera in CARLA's sensor description (CARLA's frame, degrees, pixels)."""

    id: str
    x: float
    y: float
    z: float
    roll: float
    pitch: float
    yaw: float
    width: int
    height: int
    fov: float

    def to_proto(self):
        return pb.CameraSpec(**self.__dict__)

    @staticmethod
    def from_proto(spec) -> "Camera":
        return Camera(
            spec.id, spec.x, spec.y, spec.z, spec.roll, spec.pitch, spec.yaw,
            spec.width, spec.height, spec.fov,
        )


@dataclass(frozen=True)
class Control:
    """Steer in [-1, 1] (+1 = full right), throttle and brake in [0, 1]."""

    steer: float
    throttle: float
    brake: float


@dataclass(frozen=True)
class StepResult:
    control: Control
    #: Planned waypoints, ego frame (x forward, y left), metres, every 0.5 s.
    trajectory: list
    #: Milliseconds by phase (queue, decode, model, control, total) and the batch size.
    timings: dict
    #: The raw debug message when asked for (token attention maps, both branches).
    debug: Optional[object] = None


def _images(images: Sequence, rig: Sequence[Camera], encoding: str):
    if encoding not in ENCODINGS:
        raise ValueError(f"encoding {encoding!r} is not one of {sorted(ENCODINGS)}")
    if len(images) != len(rig):
        raise ValueError(f"the rig has {len(rig)} camera(s) but {len(images)} image(s) came")
    out = []
    for image, camera in zip(images, rig):
        data = image if isinstance(image, (bytes, bytearray)) else image.tobytes()
        out.append(
            pb.Image(
                camera_id=camera.id,
                width=camera.width,
                height=camera.height,
                encoding=ENCODINGS[encoding],
                data=bytes(data),
            )
        )
    return out


@dataclass
class Episode:
    """One open episode; steps must go in increasing frame order."""

    client: "AgentClient"
    id: str
    rig: list
    idle_timeout_s: float
    key: str = ""
    _frame: int = field(default=0)

    def step(
        self,
        images: Sequence,
        speed: float,
        pose: Sequence[float],
        command: int,
        target_point: Sequence[float],
        frame_index: Optional[int] = None,
        timestamp: Optional[float] = None,
        encoding: str = "rgb8",
        debug: bool = False,
    ) -> StepResult:
        """One tick. ``images``: one per rig camera, bytes or arrays with ``tobytes()``;
        ``pose``: (x, y, z, yaw) in the world frame; ``command``: a RoadOption value;
        ``target_point``: (x, y) in the ego frame."""
        frame = self._frame if frame_index is None else frame_index
        x, y, z, yaw = pose
        request = pb.StepRequest(
            episode_id=self.id,
            frame_index=frame,
            timestamp_s=frame * 0.05 if timestamp is None else timestamp,
            images=_images(images, self.rig, encoding),
            speed_mps=speed,
            pose=pb.Pose(x=x, y=y, z=z, yaw=yaw),
            command=command,
            target_point=pb.EgoPoint(x=target_point[0], y=target_point[1]),
            debug=debug,
        )
        answer = _call(self.client.stub.Step, request, self.client.timeout, self.key)
        self._frame = frame + 1
        t = answer.timings
        return StepResult(
            control=Control(answer.control.steer, answer.control.throttle, answer.control.brake),
            trajectory=[(p.x, p.y) for p in answer.trajectory],
            timings={
                "queue_ms": t.queue_ms,
                "decode_ms": t.decode_ms,
                "model_ms": t.model_ms,
                "control_ms": t.control_ms,
                "total_ms": t.total_ms,
                "batch_size": t.batch_size,
            },
            debug=answer.debug if answer.HasField("debug") else None,
        )

    def end(self) -> int:
        """Closes the episode; returns the steps it ran."""
        answer = _call(
            self.client.stub.EndEpisode,
            pb.EndEpisodeRequest(episode_id=self.id),
            self.client.timeout,
            self.key,
        )
        return answer.steps

    def __enter__(self) -> "Episode":
        return self

    def __exit__(self, *exc) -> None:
        try:
            self.end()
        except AgentError:
            pass


class AgentClient:
    """A connection to an agent server at ``target`` (``host:port``, ``grpc://`` optional)."""

    def __init__(self, target: str, timeout: float = 30.0, max_message_mib: int = 64):
        address = target.removeprefix("grpc://").removeprefix("http://")
        limit = max_message_mib << 20
        self.channel = grpc.insecure_channel(
            address,
            options=[
                ("grpc.max_send_message_length", limit),
                ("grpc.max_receive_message_length", limit),
            ],
        )
        self.stub = pb_grpc.AgentServiceStub(self.channel)
        self.timeout = timeout
        self.target = address

    def wait_until_serving(self, timeout: float = 120.0) -> None:
        """Waits until ``grpc.health.v1.Health/Check`` reports the server SERVING (it reports
        NOT_SERVING while it loads and warms up the model)."""
        health = health_pb2_grpc.HealthStub(self.channel)
        deadline = time.monotonic() + timeout
        last = "no answer yet"
        while time.monotonic() < deadline:
            try:
                reply = health.Check(health_pb2.HealthCheckRequest(), timeout=2.0)
                if reply.status == health_pb2.HealthCheckResponse.SERVING:
                    return
                last = health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status)
            except grpc.RpcError as error:
                last = error.code().name
            time.sleep(0.2)
        raise AgentError("UNAVAILABLE", f"{self.target} was not SERVING within {timeout} s ({last})")

    def info(self):
        """The server's AgentInfo message (model, config, expected rig, limits)."""
        return _call(self.stub.GetAgentInfo, pb.GetAgentInfoRequest(), self.timeout)

    def expected_rig(self) -> list:
        return [Camera.from_proto(c) for c in self.info().expected_rig.cameras]

    def start_episode(
        self,
        rig: Optional[Sequence[Camera]] = None,
        seed: Optional[int] = None,
        fusion_alpha: Optional[float] = None,
        client: str = "python",
    ) -> Episode:
        """Opens an episode for ``rig`` (default: the rig the server expects)."""
        rig = list(rig) if rig is not None else self.expected_rig()
        overrides = pb.EpisodeOverrides()
        if fusion_alpha is not None:
            overrides.fusion_alpha = fusion_alpha
        request = pb.StartEpisodeRequest(
            rig=pb.Rig(cameras=[c.to_proto() for c in rig]),
            overrides=overrides,
            client=client,
        )
        if seed is not None:
            request.seed = seed
        key = f"py-{os.getpid():x}-{uuid.uuid4().hex}"
        answer = _call(self.stub.StartEpisode, request, self.timeout, key)
        return Episode(self, answer.episode_id, rig, answer.idle_timeout_s, key)

    def close(self) -> None:
        self.channel.close()
