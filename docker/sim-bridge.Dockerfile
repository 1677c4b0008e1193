# sim-bridge: the kinematic simulator and leaderboard-style scorer.
# Build from the repository root: docker build -f docker/sim-bridge.Dockerfile -t ssrdrive/sim-bridge .
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release -p sim-bridge

FROM debian:bookworm-slim
COPY --from=build /src/target/release/sim-bridge /usr/local/bin/sim-bridge
WORKDIR /work
ENTRYPOINT ["sim-bridge"]
CMD ["eval", "--agent", "expert", "--routes", "town05-long-style", "--out", "/work/results.json", "--quiet"]
