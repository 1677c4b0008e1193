#!/usr/bin/env python3
"""Fan a `sim-bridge eval` campaign out over a Ray cluster, one task per share, and merge.

Every task runs `sim-bridge eval ARGS --shard K/N --out OUT/part-K.json --resume` on whatever
node Ray gives it, so the split, the seeds and the scores are sim-bridge's own: the merged file
equals the one a single `sim-bridge eval ARGS` writes, run for run (but the wall-clock
`duration_system`). A share whose runs end "Failed - Agent crashed" is driven again with
`--resume` (which keeps the scored runs and drives the crashed ones), at most `--crash-retries`
times, as the leaderboard retries crashed routes; a task whose worker dies (a node lost, a process
killed) is retried by Ray and resumes from the part file the same way. When every share is in,
`sim-bridge results merge` joins the parts (and refuses parts of different campaigns, runs found
twice or missing runs).

    python3 ray_campaign.py --shards 8 --out campaign/ -- --routes town05-long-style --agent local --repetitions 3
    python3 ray_campaign.py --address ray://head:10001 --shards 64 --out /shared/c1 -- ...

Without `--address` it starts a Ray instance on this machine (loopback only). The part files
go to `--out`, which every node must see (a shared volume) when the cluster has several nodes.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import ray

# Linux prctl option: a signal delivered to this process when its parent dies.
PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """The eval dies with the Ray worker that started it, so a retried task never races an
    orphan writing the same part file (Linux; elsewhere the orphan finishes its run)."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except OSError:
        pass


def part_state(path: Path) -> tuple[int, int, int]:
    """(runs scored, runs of the share, runs whose agent crashed) of a part file; zeros when
    there is none yet."""
    try:
        results = json.loads(path.read_text())
    except FileNotFoundError:
        return 0, 0, 0
    checkpoint = results["_checkpoint"]
    done, total = checkpoint.get("progress") or [0, 0]
    crashed = sum(1 for r in checkpoint["records"] if "Agent crashed" in r["status"])
    return done, total, crashed


@ray.remote(max_retries=3)
def run_share(
    sim_bridge: str, eval_args: list[str], shard: int, shards: int, part: str, crash_retries: int
) -> dict:
    """Drive share `shard` of `shards` into `part`; returns what happened."""
    path = Path(part)
    # How many times Ray has started this task (a worker that died is retried): counted in a
    # file beside the part, which the retry finds.
    starts_file = Path(part + ".starts")
    starts = int(starts_file.read_text()) + 1 if starts_file.exists() else 1
    starts_file.write_text(str(starts))
    resumed = part_state(path)[0]
    flags = [f for f in ("--resume", "--quiet") if f not in eval_args]
    command = [sim_bridge, "eval", *eval_args, "--shard", f"{shard}/{shards}", "--out", part, *flags]
    for attempt in range(crash_retries + 1):
        started = time.monotonic()
        proc = subprocess.run(
            command, capture_output=True, text=True, preexec_fn=_die_with_parent
        )
        done, total, crashed = part_state(path)
        # A share with no runs (more shares than runs) is done when eval says so.
        if done == total and crashed == 0 and (total or proc.returncode == 0):
            return {
                "shard": shard,
                "runs": total,
                "attempts": attempt + 1,
                "starts": starts,
                "resumed": resumed,
                "seconds": time.monotonic() - started,
                # eval exits non-zero for routes it could not plan: scored as failed runs.
                "warnings": proc.stderr.strip()[-2000:] if proc.returncode else "",
            }
        if crashed == 0:
            raise RuntimeError(
                f"share {shard}/{shards}: `{' '.join(command)}` exited {proc.returncode} with "
                f"{done} of {total or '?'} runs scored:\n{proc.stderr.strip()[-4000:]}"
            )
    raise RuntimeError(
        f"share {shard}/{shards}: {crashed} runs still end 'Agent crashed' after "
        f"{crash_retries} retries:\n{proc.stderr.strip()[-4000:]}"
    )


def find_sim_bridge(given: str | None) -> str:
    """The sim-bridge binary: --sim-bridge, $SIM_BRIDGE, PATH, or this checkout's release build."""
    here = Path(__file__).resolve().parents[2] / "target" / "release" / "sim-bridge"
    for candidate in (given, os.environ.get("SIM_BRIDGE"), shutil.which("sim-bridge"), str(here)):
        if candidate and Path(candidate).is_file():
            return str(Path(candidate).resolve())
    sys.exit(
        "error: no sim-bridge binary: pass --sim-bridge PATH, set SIM_BRIDGE, put it on PATH, "
        "or build it (cargo build --release)"
    )


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, eval_args = (argv[: argv.index("--")], argv[argv.index("--") + 1 :]) if "--" in argv else (argv, [])
    parser = argparse.ArgumentParser(
        description="Run a sim-bridge eval campaign as Ray tasks (one per share) and merge the parts.",
        epilog="Everything after `--` goes to `sim-bridge eval` (routes, agent, repetitions, seed, ...).",
    )
    parser.add_argument("--out", required=True, type=Path,
                        help="folder for the part files and the merged results.json (shared by every node)")
    parser.add_argument("--shards", type=int, default=0,
                        help="how many shares [default: the cluster's CPUs / --cpus-per-share]")
    parser.add_argument("--cpus-per-share", type=float, default=1.0,
                        help="CPUs Ray reserves for each share's task (a local agent's server runs inside it)")
    parser.add_argument("--crash-retries", type=int, default=2,
                        help="times a share with 'Agent crashed' runs is driven again with --resume")
    parser.add_argument("--address", default=None,
                        help="a Ray cluster to join (e.g. ray://head:10001) [default: start one here]")
    parser.add_argument("--sim-bridge", default=None, help="the sim-bridge binary on every node")
    args = parser.parse_args(ours)
    for bad in ("--shard", "--out", "--suite"):
        if bad in eval_args:
            parser.error(f"{bad} is the driver's to set: leave it out of the eval arguments")
    if args.shards < 0 or args.crash_retries < 0 or args.cpus_per_share <= 0:
        parser.error("--shards and --crash-retries must be >= 0 and --cpus-per-share > 0")
    sim_bridge = find_sim_bridge(args.sim_bridge)
    args.out.mkdir(parents=True, exist_ok=True)

    if args.address:
        ray.init(address=args.address, log_to_driver=False)
    else:
        ray.init(include_dashboard=False, log_to_driver=False, _node_ip_address="127.0.0.1")
    shards = args.shards or max(1, int(ray.cluster_resources().get("CPU", 1) // args.cpus_per_share))
    parts = [args.out / f"part-{k:04d}-of-{shards:04d}.json" for k in range(shards)]
    task = run_share.options(num_cpus=args.cpus_per_share)
    pending = {
        task.remote(sim_bridge, eval_args, k, shards, str(part), args.crash_retries): k
        for k, part in enumerate(parts)
    }
    print(f"campaign: {shards} shares on Ray ({ray.cluster_resources().get('CPU', 0):.0f} CPUs), parts in {args.out}",
          flush=True)
    started = time.monotonic()
    failed = []
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        shard = pending.pop(ready[0])
        finished = shards - len(pending)
        try:
            report = ray.get(ready[0])
        except (ray.exceptions.RayError, RuntimeError) as error:
            failed.append(shard)
            print(f"[{finished}/{shards}] share {shard} FAILED: {error}", file=sys.stderr, flush=True)
            continue
        retried = f", {report['attempts']} attempts" if report["attempts"] > 1 else ""
        if report["starts"] > 1:
            retried += (f", started {report['starts']} times by Ray (a worker died), "
                        f"resumed with {report['resumed']} runs scored")
        print(f"[{finished}/{shards}] share {shard}: {report['runs']} runs in {report['seconds']:.0f} s{retried} "
              f"({time.monotonic() - started:.0f} s so far)", flush=True)
        if report["warnings"]:
            print(f"  share {shard} says: {report['warnings']}", file=sys.stderr, flush=True)
    ray.shutdown()
    present = [str(p) for p in parts if p.exists()]
    if failed:
        print(f"{len(failed)} shares failed ({failed}); merging what the others scored",
              file=sys.stderr, flush=True)
        if not present:
            return 1
    merge = [sim_bridge, "results", "merge", *present, "--out", str(args.out / "results.json")]
    code = subprocess.run(merge + (["--allow-missing"] if failed else [])).returncode
    return 1 if failed else code

if __name__ == "__main__":
    sys.exit(main())
