# sim-bridge: the kinematic simulator, leaderboard-style scorer, load generator and replay.
# Build from the repository root:
#   docker build -f docker/sim-bridge.Dockerfile -t ssrdrive/sim-bridge .
# Score the expert, or an agent server:
#   docker run -v $PWD/out:/work ssrdrive/sim-bridge
#   docker run -v $PWD/out:/work ssrdrive/sim-bridge eval --agent grpc://HOST:50051 --out /work/results.json
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release -p sim-bridge \
    && strip -o /usr/local/bin/sim-bridge target/release/sim-bridge

FROM debian:bookworm-slim
COPY --from=build /usr/local/bin/sim-bridge /usr/local/bin/sim-bridge
WORKDIR /work
ENTRYPOINT ["sim-bridge"]
CMD ["eval", "--agent", "expert", "--routes", "town05-long-style", "--out", "/work/results.json", "--quiet"]
