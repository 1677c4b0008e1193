# ssr-agent: the gRPC agent server (ssrdrive.v1.AgentService) on the CPU backend.
# Build from the repository root, one of two ways:
#   docker build -f docker/ssr-agent.Dockerfile -t ssrdrive/ssr-agent .      # compiled in Docker
#   docker/local/build.sh      # a local base image and the binaries built on this host (no registry)
# Run (a checkpoint mounted at /models):
#   docker run --network host -v $PWD/checkpoints:/models:ro \
#     -e SSR_AGENT_CHECKPOINT=/models/ssr.safetensors ssrdrive/ssr-agent
ARG BASE=debian:bookworm-slim
ARG BINARIES=compiled

FROM rust:1.95-bookworm AS compiled
WORKDIR /src
COPY . .
# No protoc needed: the proto is compiled by protox at build time. The binary is stripped of
# the release profile's line tables (224 MB -> 25 MB).
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release -p ssr-agent \
    && mkdir -p /out && strip -o /out/ssr-agent target/release/ssr-agent

# The binary built on the host and staged by docker/local/build.sh (stripped).
FROM scratch AS host
COPY docker/local/bin/ssr-agent /out/ssr-agent

FROM ${BINARIES} AS binaries

FROM ${BASE}
COPY --from=binaries /out/ssr-agent /usr/local/bin/ssr-agent
# Every setting can also come from a TOML file (SSR_AGENT_CONFIG) or flags; see `ssr-agent serve --help`.
ENV SSR_AGENT_LISTEN=127.0.0.1:50051 \
    SSR_AGENT_METRICS_LISTEN=127.0.0.1:9090 \
    SSR_AGENT_LOG_FORMAT=json
EXPOSE 50051 9090
# SIGTERM drains: NOT_SERVING, stop accepting, finish in-flight steps, exit.
STOPSIGNAL SIGTERM
ENTRYPOINT ["ssr-agent", "serve"]
