"""The generated protobuf and gRPC modules, (re)generated from the repository's proto file with
grpcio-tools when they are missing or older than the proto. Nothing is checked in."""

import importlib
import sys
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
PROTO_ROOT = PACKAGE_DIR.parents[1]
PROTO_FILE = PROTO_ROOT / "ssrdrive" / "v1" / "agent.proto"
GENERATED = [PACKAGE_DIR / "v1" / "agent_pb2.py", PACKAGE_DIR / "v1" / "agent_pb2_grpc.py"]


def _stale() -> bool:
    """Missing stubs, or stubs older than a proto file that is there to regenerate from."""
    if not all(path.exists() for path in GENERATED):
        return True
    if not PROTO_FILE.exists():
        return False
    return min(path.stat().st_mtime for path in GENERATED) < PROTO_FILE.stat().st_mtime


def generate() -> None:
    """Runs protoc (from grpcio-tools) on agent.proto into this package."""
    try:
        from grpc_tools import protoc
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError(
            "ssrdrive needs grpcio-tools to generate its stubs: "
            "pip install -r proto/python/requirements.txt"
        ) from error
    if not PROTO_FILE.exists():
        raise FileNotFoundError(f"{PROTO_FILE} is missing; use the client from the repository")
    include = str(Path(protoc.__file__).parent / "_proto")
    status = protoc.main(
        [
            "protoc",
            f"-I{PROTO_ROOT}",
            f"-I{include}",
            f"--python_out={PACKAGE_DIR.parent}",
            f"--grpc_python_out={PACKAGE_DIR.parent}",
            str(PROTO_FILE),
        ]
    )
    if status != 0:
        raise RuntimeError(f"protoc failed on {PROTO_FILE} (exit {status})")


def load():
    """Returns (agent_pb2, agent_pb2_grpc), generating them first if needed."""
    if _stale():
        generate()
        importlib.invalidate_caches()
    pb2 = importlib.import_module("ssrdrive.v1.agent_pb2")
    pb2_grpc = importlib.import_module("ssrdrive.v1.agent_pb2_grpc")
    return pb2, pb2_grpc


if __name__ == "__main__":
    generate()
    sys.stdout.write(f"generated {GENERATED[0].parent}\n")
