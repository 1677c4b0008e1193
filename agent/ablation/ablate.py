#!/usr/bin/env python3
"""The paper's ablations in closed loop: STL, FFP, the number of scene tokens and what the
navigation gate reads.

For each variant and training seed this trains the network with the bundled recipe on the same
data and step budget (`ssr-agent train`), gives the checkpoint the bundled controller settings
(`ssr-agent control`: safety stop on), drives it on the Town05-style long and short routes
(`sim-bridge eval --agent local`) and reads its open-loop validation from the checkpoint
(`ssr-agent inspect`). Then every variant's network is timed in one sitting (`ssr-agent bench`:
forward pass at batch 1 and 8, a training step at batch 8), in interleaved rounds so that the
machine's drift falls on all of them alike: timing.json, redone whenever a variant joins (delete
it to time again on a quiet machine). One table covers every run found under --out:
ablation.md and ablation.json, with a second that sets each variant against full SSR drive by
drive (same route and repetition, each side's seeds averaged), its DS difference and a 95 %
interval.

Every variant starts from the same perception, the bundled checkpoint's backbone, BEV encoder
and occupancy head (`--init-perception`), and draws its scene tokens, navigation gate, heads
and FFP from its seed: the bundled lineage is 118,000 steps (18 h on two cores), too much to
repeat per variant, while the planner side, where the variants differ, trains in the budget.
The perception learnt with STL, FFP and 16 tokens, which favours the full network a little
and leaves the no-FFP variant only the planner-side half of FFP's effect (its gradient into
the BEV during these steps).

Every stage writes into --out/<variant>/seed-<k>/ and is skipped once its output is complete;
training and evaluation continue from where they stopped (`--resume`), and a `done` file marks a
run whose evaluations all finished (only those enter the table). A killed run therefore
continues when the same command is run again. `--keep DIR` copies each finished run's figures
(not its checkpoints: about 110 kB a run) and timing.json into DIR, from which
`--table-only --out DIR` rebuilds the same table; agent/ablation/results is this project's.
Standard library only.

    python3 agent/ablation/ablate.py --data data/train-v5 --out runs/ablation
    python3 agent/ablation/ablate.py --data data/train-v5 --out runs/ablation \\
        --variants full,no-ffp --seeds 1          # a second seed for two of them
    python3 agent/ablation/ablate.py --out runs/ablation --table-only
    python3 agent/ablation/ablate.py --out agent/ablation/results --table-only
"""

import argparse
import json
import os
import random
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

# Variant name -> the `ssr-agent train` flags that make it (full SSR: 16 tokens, STL, FFP, a
# gate on the command and the target point).
VARIANTS = {
    "full": [],
    "no-stl": ["--no-stl"],
    "no-ffp": ["--no-ffp"],
    "tokens-4": ["--tokens", "4"],
    "tokens-8": ["--tokens", "8"],
    "tokens-32": ["--tokens", "32"],
    "tokens-64": ["--tokens", "64"],
    "gate-command": ["--gate-command-only"],
}

# The bundled recipe's last stage (agent/README.md, "Training"): the flags every variant shares.
RECIPE = [
    "--lr", "3e-4", "--warmup-steps", "500", "--history-dropout", "0.1", "--history", "link",
    "--hazard-weight", "0.5", "--occupancy-weight", "1.0",
    "--checkpoint-every", "1000", "--validate-every", "2500",
]
# 80,000 sample passes of the planner side on the shared perception.
DEFAULT_STEPS = 10000
ROUTE_SETS = ["town05-long-style", "town05-short-style"]
# Controller settings of the bundled agent, given to every variant's checkpoint.
BUNDLED_CONTROL = '{"safety": {"enabled": true}, "turn_lead": "plan"}'
# What the table is built from: a finished run's files apart from its checkpoints and logs.
FIGURES = ["inspect.txt", "model.json", *(f"eval-{routes}.json" for routes in ROUTE_SETS), "done"]


# The workspace's release binaries and bundled checkpoint, wherever the script is run from.
REPOSITORY = Path(__file__).resolve().parents[2]
DEFAULT_BIN = REPOSITORY / "target" / "release"
DEFAULT_PERCEPTION = REPOSITORY / "agent" / "models" / "ssr-cpu-default.safetensors"


def main():
    args = parse_args()
    if not args.table_only:
        args.out.mkdir(parents=True, exist_ok=True)
        for variant in args.variants:
            for seed in args.seeds:
                run_variant(args, variant, seed)
                keep(args, Path(variant) / f"seed-{seed}", FIGURES)
    runs = list(runs_under(args.out))
    if not runs:
        sys.exit(f"ablate.py: no finished runs under {args.out}")
    if not args.table_only:
        time_variants(args, runs)
        keep(args, Path("."), ["timing.json"])
    timing = read_timing(args.out)
    rows = [collect(run, timing.get(run.parent.name)) for run in runs]
    write_table(args.out, rows)


def parse_args():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path,
                        help="dataset from `sim-bridge collect` (required unless --table-only)")
    parser.add_argument("--out", type=Path, default=Path("runs/ablation"),
                        help="where every run and the table go (default: %(default)s)")
    parser.add_argument("--variants", default=",".join(VARIANTS), type=variant_list,
                        help=f"comma separated, of: {', '.join(VARIANTS)} (default: all)")
    parser.add_argument("--seeds", default="0", type=seed_list,
                        help="training seeds, e.g. 0,1 (default: %(default)s)")
    parser.add_argument("--steps", type=positive, default=DEFAULT_STEPS,
                        help="training steps of 8 samples (default: %(default)s)")
    parser.add_argument("--perception", type=Path, default=DEFAULT_PERCEPTION,
                        help="checkpoint every variant's perception starts from "
                             "(default: the bundled one)")
    parser.add_argument("--repetitions", type=positive, default=3,
                        help="repetitions of each evaluation (default: %(default)s)")
    parser.add_argument("--jobs", type=positive, default=2,
                        help="runs at once in each evaluation (default: %(default)s)")
    parser.add_argument("--limit", type=positive, help="only the first N routes of each set (smoke runs)")
    parser.add_argument("--timeout", type=float, help="end every route after S simulated seconds (smoke runs)")
    parser.add_argument("--bench-iterations", type=positive, default=20,
                        help="timed runs per bench measurement (default: %(default)s)")
    parser.add_argument("--bench-rounds", type=positive, default=3,
                        help="interleaved timing rounds over every variant (default: %(default)s)")
    parser.add_argument("--bin", type=Path, default=DEFAULT_BIN,
                        help="folder of the ssr-agent and sim-bridge binaries (default: %(default)s)")
    parser.add_argument("--keep", type=Path,
                        help="also copy every finished run's figures and timing.json here "
                             "(small enough to commit; --table-only --out KEEP rebuilds the table)")
    parser.add_argument("--table-only", action="store_true",
                        help="only rebuild the table from the runs under --out")
    args = parser.parse_args()
    if args.table_only:
        return args
    if args.data is None:
        parser.error("--data is required (or --table-only)")
    if not (args.data / "manifest.json").is_file():
        parser.error(f"{args.data / 'manifest.json'} is missing: --data takes a folder "
                     "written by `sim-bridge collect`")
    if not args.perception.is_file():
        parser.error(f"{args.perception} is missing: --perception takes a checkpoint")
    for name in ("ssr-agent", "sim-bridge"):
        if not (args.bin / name).is_file():
            parser.error(f"{args.bin / name} is missing: build with "
                         "`cargo build --release -p ssr-agent -p sim-bridge` or pass --bin")
    return args


def positive(text):
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive whole number, got '{text}'")
    return value


def variant_list(text):
    names = [v for v in text.split(",") if v]
    unknown = [v for v in names if v not in VARIANTS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"unknown variant {', '.join(unknown) or '(none)'}; known: {', '.join(VARIANTS)}")
    return names


def seed_list(text):
    try:
        seeds = [int(s) for s in text.split(",") if s]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0:
        raise argparse.ArgumentTypeError(f"seeds must be whole numbers 0 or more, got '{text}'")
    return seeds


def run_variant(args, variant, seed):
    run = args.out / variant / f"seed-{seed}"
    run.mkdir(parents=True, exist_ok=True)
    tool = lambda name: str(args.bin / name)
    label = f"[{variant} seed {seed}]"

    final = run / "train" / "final.safetensors"
    if not final.is_file():
        resume = ["--resume"] if (run / "train" / "resume").is_dir() else []
        step(label, "train", run / "train.log",
             [tool("ssr-agent"), "train", "--data", str(args.data), "--out", str(run / "train"),
              "--steps", str(args.steps), "--seed", str(seed), "--quiet",
              "--init-perception", str(args.perception),
              *RECIPE, *VARIANTS[variant], *resume])

    agent = run / "agent.safetensors"
    if not agent.is_file():
        step(label, "control", run / "control.log",
             [tool("ssr-agent"), "control", str(final), "--set", BUNDLED_CONTROL,
              "--out", str(agent)])

    info = run / "inspect.txt"
    if not info.is_file():
        step(label, "inspect", info, [tool("ssr-agent"), "inspect", str(agent)], stdout_only=True)

    model = run / "model.json"
    if not model.is_file():
        model.write_text(json.dumps(checkpoint_field(info, "config")))

    done = run / "done"
    if done.is_file():
        return
    for routes in ROUTE_SETS:
        out = run / f"eval-{routes}.json"
        flags = ["--limit", str(args.limit)] if args.limit else []
        flags += ["--timeout", str(args.timeout)] if args.timeout else []
        step(label, f"eval {routes}", run / f"eval-{routes}.log",
             [tool("sim-bridge"), "eval", "--agent", "local", "--routes", routes,
              "--repetitions", str(args.repetitions), "--jobs", str(args.jobs), "--quiet",
              "--resume", "--out", str(out), *flags],
             env={"SSR_AGENT_CHECKPOINT": str(agent), "SSR_AGENT_BIN": tool("ssr-agent")},
             append=True)
    # Every evaluation exited 0, so every run is scored (a killed one leaves a partial JSON).
    done.touch()


def keep(args, folder, names):
    """Copies `names` from --out/`folder` to --keep/`folder` once the last of them exists."""
    source = args.out / folder
    if args.keep is None or not (source / names[-1]).is_file():
        return
    (args.keep / folder).mkdir(parents=True, exist_ok=True)
    for name in names:
        shutil.copyfile(source / name, args.keep / folder / name)


def step(label, what, log, command, env=None, append=False, stdout_only=False):
    """Runs `command` with its output (`stdout_only`: its stdout; stderr goes to the terminal)
    in `log`; a failure stops the script, naming the log."""
    print(f"{label} {what} (log: {log})", flush=True)
    with open(log, "a" if append else "w") as out:
        done = subprocess.run(command, stdout=out,
                              stderr=None if stdout_only else subprocess.STDOUT,
                              env={**os.environ, **(env or {})})
    if done.returncode != 0:
        sys.exit(f"{label} {what} failed (exit {done.returncode}); see {log}")


def checkpoint_field(inspect_txt, key):
    """A JSON field of `ssr-agent inspect`'s output: `key: {...}` on one line, or the pretty
    config block after `config:`."""
    text = inspect_txt.read_text()
    if key == "config":
        return json.loads(text.split("\nconfig: ", 1)[1])
    for line in text.splitlines():
        if line.startswith(f"{key}: "):
            return json.loads(line[len(key) + 2:])
    raise KeyError(f"{inspect_txt} has no '{key}'")


def runs_under(out):
    """Every <variant>/seed-<k> folder under `out` whose stages have all finished."""
    for variant in VARIANTS:
        for run in sorted((out / variant).glob("seed-*")):
            if (run / "done").is_file():
                yield run


def time_variants(args, runs):
    """Times every variant with a finished run, all in one sitting: `--bench-rounds` rounds,
    each benching every variant in turn (its network with fresh weights: timing does not depend
    on them). Skipped when timing.json already covers exactly these variants."""
    models = {}
    for run in runs:
        models.setdefault(run.parent.name, run / "model.json")
    path = args.out / "timing.json"
    if path.is_file() and sorted(json.loads(path.read_text())) == sorted(models):
        return
    rounds = {variant: [] for variant in models}
    scratch = args.out / "timing.partial"
    for k in range(args.bench_rounds):
        for variant, model in models.items():
            reports = {}
            for batch, extra in ((1, []), (8, ["--train", "--train-batch", "8"])):
                step(f"[timing round {k + 1} of {args.bench_rounds}]",
                     f"{variant} batch {batch}", scratch,
                     [str(args.bin / "ssr-agent"), "bench", "--config", str(model),
                      "--batch", str(batch), "--iterations", str(args.bench_iterations),
                      "--json", *extra], stdout_only=True)
                for line in scratch.read_text().splitlines():
                    if line.startswith("{"):
                        report = json.loads(line)
                        reports.setdefault(report["batch"], {}).update(report["results"])
            rounds[variant].append({
                "params": int(reports[1]["params"]),
                "ms_batch_1": reports[1]["forward_ms"],
                "ms_batch_8": reports[8]["forward_ms"],
                "train_step_ms_batch_8": reports[8]["train_step_ms"],
            })
    scratch.unlink()
    path.write_text(json.dumps(rounds, indent=1) + "\n")


def read_timing(out):
    """Variant -> params and the median over rounds of each timing ({} without timing.json)."""
    path = out / "timing.json"
    if not path.is_file():
        return {}
    return {
        variant: {key: statistics.median(r[key] for r in rounds) for key in rounds[0]}
        for variant, rounds in json.loads(path.read_text()).items()
    }


def collect(run, timing):
    """One run's figures: open loop, closed loop per route set, and its variant's timing and
    size (None until timed)."""
    validation = checkpoint_field(run / "inspect.txt", "training").get("validation") or {}
    l2 = validation.get("l2_m")  # nulls where the data had no validation routes
    row = {
        "variant": run.parent.name,
        "seed": int(run.name.removeprefix("seed-")),
        "timing": timing,
        "l2_m": l2 if l2 and None not in l2 else None,
    }
    for routes in ROUTE_SETS:
        row[routes] = closed_loop(json.loads((run / f"eval-{routes}.json").read_text()))
    return row


def closed_loop(results):
    """DS, RC and IS (means over runs) and infractions per km driven from a results JSON."""
    records = results["_checkpoint"]["records"]
    mean = lambda key: statistics.mean(r["scores"][key] for r in records)
    km = sum(r["meta"]["route_length"] * r["scores"]["score_route"] / 100 for r in records) / 1000
    counts = {}
    for r in records:
        for kind, events in r["infractions"].items():
            counts[kind] = counts.get(kind, 0) + len(events)
    return {
        "runs": len(records),
        "ds": mean("score_composed"),
        "rc": mean("score_route"),
        "is": mean("score_penalty"),
        "km": km,
        "per_km": {kind: n / km for kind, n in counts.items()} if km > 0 else None,
        "ds_by_run": [[r["route_id"], r["meta"]["repetition"], r["scores"]["score_composed"]]
                      for r in records],
    }


def spread(values):
    """'mean' for one value, 'mean ± sd' (over seeds) for more."""
    if len(values) == 1:
        return f"{values[0]:.2f}"
    return f"{statistics.mean(values):.2f} ± {statistics.stdev(values):.2f}"


def infraction_rates(loops):
    """Collisions, red lights and off-lane events per km, means over seeds ('-' if no run
    drove a metre)."""
    driven = [l["per_km"] for l in loops if l["per_km"] is not None]
    if not driven:
        return "-"
    rate = lambda kinds: statistics.mean(sum(p.get(k, 0.0) for k in kinds) for p in driven)
    collisions = rate(["collisions_vehicle", "collisions_pedestrian", "collisions_layout"])
    return f"{collisions:.2f} / {rate(['red_light']):.2f} / {rate(['outside_route_lanes']):.2f}"


def paired_difference(runs, baseline, routes, resamples=2000):
    """DS of `runs` minus DS of `baseline` drive by drive: the same route and repetition, hence
    the same traffic at the start, each side averaged over its training seeds (so a variant
    trained once meets every seed of full SSR). The 95 % interval comes from resampling whole
    routes (a route's drives are alike, so they are not independent draws): it is the spread of
    the drives for these trained networks, while the table's ± is the spread of training seeds.
    None when they share no drive."""
    ours, base = mean_by_drive(runs, routes), mean_by_drive(baseline, routes)
    by_route = {}
    for (route, rep), ds in ours.items():
        if (route, rep) in base:
            by_route.setdefault(route, []).append(ds - base[(route, rep)])
    if not by_route:
        return None
    names = sorted(by_route)
    rng = random.Random(0)  # the same interval on every rebuild of the table
    means = []
    for _ in range(resamples):
        drawn = [d for name in (rng.choice(names) for _ in names) for d in by_route[name]]
        means.append(statistics.mean(drawn))
    means.sort()
    return {
        "drives": sum(len(d) for d in by_route.values()),
        "mean": statistics.mean(d for name in names for d in by_route[name]),
        "low": means[int(0.025 * resamples)],
        "high": means[int(0.975 * resamples) - 1],
    }


def mean_by_drive(runs, routes):
    """(route, repetition) -> DS, the mean over `runs` (one a training seed) that drove it."""
    drives = {}
    for run in runs:
        for route, rep, ds in run[routes]["ds_by_run"]:
            drives.setdefault((route, rep), []).append(ds)
    return {drive: statistics.mean(values) for drive, values in drives.items()}


def write_table(out, rows):
    by_variant = {}
    for row in rows:
        by_variant.setdefault(row["variant"], []).append(row)
    table = results_table(by_variant)
    differences = {}
    if "full" in by_variant:
        differences = {variant: {routes: paired_difference(runs, by_variant["full"], routes)
                                 for routes in ROUTE_SETS}
                       for variant, runs in by_variant.items() if variant != "full"}
        table += "\nAgainst full SSR, drive by drive:\n\n" + against_full_table(differences)
    (out / "ablation.md").write_text(table)
    (out / "ablation.json").write_text(
        json.dumps({"runs": rows, "against_full": differences}, indent=1) + "\n")
    print(table, end="")
    print(f"written to {out / 'ablation.md'} and {out / 'ablation.json'}")


def results_table(by_variant):
    """One row a variant: size, timing, open loop, and closed loop per route set."""
    header = ["variant", "seeds", "params", "ms b1", "ms b8", "train step ms b8",
              "L2 1/2/3 s (m)"]
    for routes in ROUTE_SETS:
        header += [f"{set_name(routes)} {column}" for column in
                   ["DS", "RC", "IS", "collisions / red / off-lane per km"]]
    rows = []
    for variant, runs in by_variant.items():
        l2 = [r["l2_m"] for r in runs if r["l2_m"]]
        cells = [variant, ",".join(str(r["seed"]) for r in runs)]
        timing = runs[0]["timing"]
        if timing:
            cells += [f"{timing['params']:,}", f"{timing['ms_batch_1']:.2f}",
                      f"{timing['ms_batch_8']:.2f}", f"{timing['train_step_ms_batch_8']:.0f}"]
        else:
            cells += ["-"] * 4
        cells.append(" / ".join(f"{statistics.mean(v[h] for v in l2):.2f}" for h in range(3))
                     if l2 else "-")
        for routes in ROUTE_SETS:
            loops = [r[routes] for r in runs]
            cells += [spread([l["ds"] for l in loops]), spread([l["rc"] for l in loops]),
                      spread([l["is"] for l in loops]), infraction_rates(loops)]
        rows.append(cells)
    return markdown(header, rows)


def against_full_table(differences):
    """One row a variant: its paired DS difference to full SSR per route set."""
    header = ["variant"] + [f"{set_name(routes)} DS − full (95 % interval, drives)"
                            for routes in ROUTE_SETS]
    rows = [[variant] + [f"{d['mean']:+.2f} ({d['low']:+.2f} to {d['high']:+.2f}, {d['drives']})"
                         if d else "-" for d in per_set.values()]
            for variant, per_set in differences.items()]
    return markdown(header, rows)


def set_name(routes):
    """'long' for town05-long-style."""
    return routes.removeprefix("town05-").removesuffix("-style")


def markdown(header, rows):
    lines = [header, ["---"] * len(header), *rows]
    return "".join("| " + " | ".join(cells) + " |\n" for cells in lines)


if __name__ == "__main__":
    main()
