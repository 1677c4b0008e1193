# sim-bridge: the kinematic simulator, leaderboard-style scorer, load generator and replay.
# Build from the repository root, one of two ways:
#   docker build -f docker/sim-bridge.Dockerfile -t ssrdrive/sim-bridge .    # compiled in Docker
#   docker/local/build.sh      # a local base image and the binaries built on this host (no registry)
# Score the expert, or an agent server:
#   docker run -v $PWD/out:/work ssrdrive/sim-bridge
#   docker run --network host -v $PWD/out:/work ssrdrive/sim-bridge eval --agent grpc://127.0.0.1:50051 --out /work/results.json
ARG BASE=debian:bookworm-slim
ARG BINARIES=compiled

FROM rust:1.95-bookworm AS compiled
WORKDIR /src
COPY . .
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release -p sim-bridge \
    && mkdir -p /out && strip -o /out/sim-bridge target/release/sim-bridge

# The binary built on the host and staged by docker/local/build.sh (stripped).
FROM scratch AS host
COPY docker/local/bin/sim-bridge /out/sim-bridge

FROM ${BINARIES} AS binaries

FROM ${BASE}
COPY --from=binaries /out/sim-bridge /usr/local/bin/sim-bridge
WORKDIR /work
ENTRYPOINT ["sim-bridge"]
CMD ["eval", "--agent", "expert", "--routes", "town05-long-style", "--out", "/work/results.json", "--quiet"]
