"""Builds the package with its gRPC stubs: ``build_py`` runs protoc (grpcio-tools) on
../ssrdrive/v1/agent.proto into the build folder. Every build product (build folder, egg-info)
goes to a temporary folder, so that a read-only checkout installs and the source tree stays
clean."""

import tempfile
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
PROTO_ROOT = HERE.parent
PROTO_FILE = PROTO_ROOT / "ssrdrive" / "v1" / "agent.proto"


class BuildWithStubs(build_py):
    """The ordinary build, then the stubs into ``<build_lib>/ssrdrive/v1``."""

    def run(self):
        super().run()
        from grpc_tools import protoc

        if not PROTO_FILE.exists():
            raise FileNotFoundError(f"{PROTO_FILE} is missing: build from the ssrdrive repository")
        include = str(Path(protoc.__file__).parent / "_proto")
        status = protoc.main(
            [
                "protoc",
                f"-I{PROTO_ROOT}",
                f"-I{include}",
                f"--python_out={self.build_lib}",
                f"--grpc_python_out={self.build_lib}",
                str(PROTO_FILE),
            ]
        )
        if status != 0:
            raise RuntimeError(f"protoc failed on {PROTO_FILE} (exit {status})")


SCRATCH = tempfile.mkdtemp(prefix="ssrdrive-build-")

setup(
    cmdclass={"build_py": BuildWithStubs},
    options={"build": {"build_base": SCRATCH}, "egg_info": {"egg_base": SCRATCH}},
)
