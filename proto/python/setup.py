"""Builds the package with its gRPC stubs: ``build_py`` runs protoc (grpcio-tools) on
../ssrdrive/v1/agent.proto into the build folder. Every build product (build folder, egg-info)
goes to a temporary folder, so that a read-only checkout installs and the source tree stays
clean."""

import importlib.util
import tempfile
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
PROTO_ROOT = HERE.parent
PROTO_FILE = PROTO_ROOT / "ssrdrive" / "v1" / "agent.proto"


def _run_protoc():
    """``ssrdrive/_protoc.py``'s ``run_protoc``, loaded by path (the package is not built yet)."""
    spec = importlib.util.spec_from_file_location("_protoc", HERE / "ssrdrive" / "_protoc.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.run_protoc


class BuildWithStubs(build_py):
    """The ordinary build, then the stubs into ``<build_lib>/ssrdrive/v1``."""

    def run(self):
        super().run()
        _run_protoc()(PROTO_ROOT, PROTO_FILE, Path(self.build_lib))


SCRATCH = tempfile.mkdtemp(prefix="ssrdrive-build-")

setup(
    cmdclass={"build_py": BuildWithStubs},
    options={"build": {"build_base": SCRATCH}, "egg_info": {"egg_base": SCRATCH}},
)
