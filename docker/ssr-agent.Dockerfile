# ssr-agent: the gRPC agent server (ssrdrive.v1.AgentService) on the CPU backend.
# Build from the repository root:
#   docker build -f docker/ssr-agent.Dockerfile -t ssrdrive/ssr-agent .
# Run (a checkpoint mounted at /models):
#   docker run -p 50051:50051 -p 9090:9090 -v $PWD/checkpoints:/models:ro \
#     -e SSR_AGENT_CHECKPOINT=/models/ssr.safetensors ssrdrive/ssr-agent
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
# No protoc needed: the proto is compiled by protox at build time. The binary is stripped of
# the release profile's line tables (224 MB -> 25 MB).
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release -p ssr-agent \
    && strip -o /usr/local/bin/ssr-agent target/release/ssr-agent

FROM debian:bookworm-slim
COPY --from=build /usr/local/bin/ssr-agent /usr/local/bin/ssr-agent
# Every setting can also come from a TOML file (SSR_AGENT_CONFIG) or flags; see `ssr-agent serve --help`.
ENV SSR_AGENT_LISTEN=0.0.0.0:50051 \
    SSR_AGENT_METRICS_LISTEN=0.0.0.0:9090 \
    SSR_AGENT_LOG_FORMAT=json
EXPOSE 50051 9090
# SIGTERM drains: NOT_SERVING, stop accepting, finish in-flight steps, exit.
STOPSIGNAL SIGTERM
ENTRYPOINT ["ssr-agent", "serve"]
