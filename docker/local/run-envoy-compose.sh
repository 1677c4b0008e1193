#!/usr/bin/env bash
# End to end on this machine, without a registry: builds the images (docker/local/build.sh),
# runs docker/compose.envoy.yaml (two agent replicas behind Envoy and an evaluation through
# Envoy, every container on the host network), then the same evaluation straight at one
# replica, and compares the two results files run for run. Runs outside CI: 4 min 15 s on 2
# cores with the images built (docker/README.md has the figures).
#
#   docker/local/run-envoy-compose.sh                      # town05-short-style, 6 routes
#   ROUTES="--routes town05-long-style" docker/local/run-envoy-compose.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
ROUTES=${ROUTES:---routes town05-short-style --limit 6}
COMPOSE=${COMPOSE:-$(command -v docker-compose > /dev/null && echo docker-compose || echo "docker compose")}
started=$(date +%s)
docker/local/build.sh
mkdir -p out/envoy
rm -f out/envoy/through-envoy.json out/envoy/direct.json

run() {  # $1: the agent's address, $2: the results file (in out/envoy)
    EVAL_ARGS="eval --agent $1 $ROUTES --jobs 2 --out /work/$2 --quiet" \
        $COMPOSE -f docker/compose.envoy.yaml up --no-build --abort-on-container-exit \
        --exit-code-from eval > "out/envoy/${2%.json}.log" 2>&1
    $COMPOSE -f docker/compose.envoy.yaml down > /dev/null 2>&1
}
run grpc://127.0.0.1:8080 through-envoy.json
run grpc://127.0.0.1:50061 direct.json
python3 - <<'PY'
import json
def load(name):
    def strip(v):
        if isinstance(v, dict):
            return {k: strip(x) for k, x in v.items() if k != "duration_system"}
        if isinstance(v, list):
            return [strip(x) for x in v]
        return v
    return strip(json.load(open(f"out/envoy/{name}")))
envoy, direct = load("through-envoy.json"), load("direct.json")
for name, results in (("through Envoy", envoy), ("straight at agent-1", direct)):
    scores = results["_checkpoint"]["global_record"]["scores"]
    print(f"{name:20} DS {scores['score_composed']:.2f}  RC {scores['score_route']:.2f}  "
          f"IS {scores['score_penalty']:.3f}  ({len(results['_checkpoint']['records'])} runs)")
same = envoy["_checkpoint"]["records"] == direct["_checkpoint"]["records"]
print("the runs are identical" if same else "THE RUNS DIFFER")
raise SystemExit(0 if same else 1)
PY
echo "took $(( $(date +%s) - started )) s"
