"""Runs protoc (grpcio-tools) on the repository's agent.proto. Imports nothing of ``ssrdrive``,
so that the package build (setup.py) can load it by path before the package exists."""

from pathlib import Path


def run_protoc(proto_root: Path, proto_file: Path, out: Path) -> None:
    """Generates ``out/ssrdrive/v1/agent_pb2.py`` and ``agent_pb2_grpc.py`` from ``proto_file``
    (found under ``proto_root``)."""
    try:
        from grpc_tools import protoc
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError(
            "ssrdrive generates its stubs with grpcio-tools: pip install ./proto/python, or "
            "pip install -r proto/python/requirements.txt to use it from a checkout"
        ) from error
    if not proto_file.exists():
        raise FileNotFoundError(f"{proto_file} is missing: build from the ssrdrive repository")
    out.mkdir(parents=True, exist_ok=True)
    include = str(Path(protoc.__file__).parent / "_proto")
    status = protoc.main(
        [
            "protoc",
            f"-I{proto_root}",
            f"-I{include}",
            f"--python_out={out}",
            f"--grpc_python_out={out}",
            str(proto_file),
        ]
    )
    if status != 0:
        raise RuntimeError(f"protoc failed on {proto_file} (exit {status})")
