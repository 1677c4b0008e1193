#!/usr/bin/env python3
"""Burn/PyTorch time ratios, measured back to back on this machine.

For each case, runs ``ssr-agent bench --json`` and ``torch_twin.py`` alternately for
``--rounds`` rounds (so both sides see the same machine load, round after round), takes each
side's median of its per-round medians, and prints the ratio Burn / PyTorch (below 1: Burn is
faster). Build first with ``cargo build --release -p ssr-agent``; PyTorch and numpy must be
installed (``python3 -m pip install torch numpy``).

    python3 agent/bench/ratio.py                       # the four standard cases, 3 rounds
    python3 agent/bench/ratio.py --cases cpu-default:8:train --rounds 5
"""

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

TWIN = Path(__file__).with_name("torch_twin.py")
STANDARD = ["cpu-default:1:forward", "cpu-default:8:forward", "paper:1:forward", "cpu-default:8:train"]


def run_json(command):
    """The last line a benchmark printed on stdout, as JSON."""
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(command)} failed ({done.returncode}):\n{done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def burn_ms(binary, config, batch, mode, iterations):
    command = [binary, "bench", "--config", config, "--json", "--iterations", str(iterations)]
    if mode == "train":
        # It reports the forward pass at batch 1 first; the training step is the last line.
        return run_json(command + ["--train", "--train-batch", str(batch)])["results"]["train_step_ms"]
    return run_json(command + ["--batch", str(batch)])["results"]["forward_ms"]


def torch_ms(config, batch, mode, iterations):
    command = [sys.executable, str(TWIN), "--config", config, "--batch", str(batch),
               "--iters", str(iterations), "--future-bev", "input"]
    return run_json(command + (["--train"] if mode == "train" else []))["median_ms"]


def parse_case(text):
    try:
        config, batch, mode = text.split(":")
        if mode not in ("forward", "train") or int(batch) < 1:
            raise ValueError
        return config, int(batch), mode
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected CONFIG:BATCH:forward|train")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ssr-agent", default="target/release/ssr-agent", help="the built binary")
    parser.add_argument("--cases", nargs="+", type=parse_case, default=[parse_case(c) for c in STANDARD],
                        metavar="CONFIG:BATCH:MODE", help="default: %(default)s")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--iterations", type=int, default=10, help="timed runs per side per round")
    parser.add_argument("--json", action="store_true", help="one JSON object per case")
    args = parser.parse_args()
    if not Path(args.ssr_agent).is_file():
        sys.exit(f"{args.ssr_agent}: no such binary; run `cargo build --release -p ssr-agent` first")

    if not args.json:
        print(f"{'case':<24} {'burn ms':>9} {'torch ms':>9} {'ratio':>6}   (median of {args.rounds} rounds)")
    for config, batch, mode in args.cases:
        burn, torch = [], []
        for _ in range(args.rounds):
            burn.append(burn_ms(args.ssr_agent, config, batch, mode, args.iterations))
            torch.append(torch_ms(config, batch, mode, args.iterations))
        b, t = statistics.median(burn), statistics.median(torch)
        case = f"{config}:{batch}:{mode}"
        if args.json:
            print(json.dumps(dict(case=case, burn_ms=burn, torch_ms=torch, burn_median_ms=b,
                                  torch_median_ms=t, ratio=b / t)))
        else:
            print(f"{case:<24} {b:>9.2f} {t:>9.2f} {b / t:>6.2f}", flush=True)


if __name__ == "__main__":
    main()
