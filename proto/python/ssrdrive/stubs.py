"""The generated protobuf and gRPC modules (``ssrdrive.v1.agent_pb2`` and ``agent_pb2_grpc``).

- Installed (``pip install ./proto/python``): the build generated them into the package.
- From a source checkout (``PYTHONPATH=proto/python``): they are generated at first import with
  grpcio-tools into a cache folder outside the source tree (``$SSRDRIVE_STUB_DIR``, else
  ``~/.cache/ssrdrive/stubs``), one per content of agent.proto, so a read-only checkout works
  and an edited proto is never served stale stubs. Nothing generated is checked in.
"""

import hashlib
import importlib
import os
import sys
from pathlib import Path

import ssrdrive
from ssrdrive._protoc import run_protoc

PACKAGE_DIR = Path(__file__).resolve().parent
PROTO_ROOT = PACKAGE_DIR.parents[1]
PROTO_FILE = PROTO_ROOT / "ssrdrive" / "v1" / "agent.proto"


def cache_root() -> Path:
    """Where stubs for a source checkout go."""
    override = os.environ.get("SSRDRIVE_STUB_DIR")
    if override:
        return Path(override)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "ssrdrive" / "stubs"


def _source_stubs() -> Path:
    """The cache folder holding stubs for this checkout's agent.proto, generated if missing."""
    digest = hashlib.sha256(PROTO_FILE.read_bytes()).hexdigest()[:16]
    folder = cache_root() / digest
    if not (folder / "ssrdrive" / "v1" / "agent_pb2_grpc.py").exists():
        # Generate beside, then rename: a concurrent import never sees half a folder.
        partial = folder.with_name(f".{digest}.{os.getpid()}")
        run_protoc(PROTO_ROOT, PROTO_FILE, partial)
        try:
            partial.rename(folder)
        except OSError:
            if not folder.exists():
                raise
    return folder


def load():
    """Returns (agent_pb2, agent_pb2_grpc)."""
    installed = (PACKAGE_DIR / "v1" / "agent_pb2.py").exists() and not PROTO_FILE.exists()
    if not installed:
        if not PROTO_FILE.exists():
            raise FileNotFoundError(
                f"{PROTO_FILE} is missing and no built stubs are installed: "
                "pip install ./proto/python from the ssrdrive repository"
            )
        extra = str(_source_stubs() / "ssrdrive")
        if extra not in ssrdrive.__path__:
            # First, so that stubs an older version generated into the source tree lose.
            ssrdrive.__path__.insert(0, extra)
        importlib.invalidate_caches()
    pb2 = importlib.import_module("ssrdrive.v1.agent_pb2")
    pb2_grpc = importlib.import_module("ssrdrive.v1.agent_pb2_grpc")
    return pb2, pb2_grpc


if __name__ == "__main__":
    sys.stdout.write(f"stubs in {_source_stubs()}\n")
