//! A campaign split over processes: `eval --shard K/N` parts merged by `results merge` equal
//! the single-process results file run for run, and the merge refuses what the leaderboard's
//! merge refuses (runs twice, other campaigns, missing runs unless allowed).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn sim_bridge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sim-bridge"))
        .args(args)
        .output()
        .expect("runs")
}

fn ok(run: Output) -> Output {
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    run
}

fn fails_saying(run: Output, says: &str) {
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "it should fail: {stderr}");
    assert!(stderr.contains(says), "{stderr}");
}

/// The expert on six short routes twice, into `out`, with `extra` flags (`--shard K/N`, ...).
fn eval(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "eval",
        "--routes",
        "train-small",
        "--limit",
        "6",
        "--repetitions",
        "2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    sim_bridge(&args)
}

/// The file without its wall-clock durations (the one thing that differs between processes).
fn without_wall_time(path: &Path) -> Value {
    fn strip(v: Value) -> Value {
        match v {
            Value::Object(map) => map
                .into_iter()
                .filter(|(k, _)| k != "duration_system")
                .map(|(k, v)| (k, strip(v)))
                .collect(),
            Value::Array(items) => items.into_iter().map(strip).collect(),
            other => other,
        }
    }
    strip(serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap())
}

fn merge(parts: &[PathBuf], out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["results", "merge"];
    args.extend(parts.iter().map(|p| p.to_str().unwrap()));
    args.extend(["--out", out.to_str().unwrap()]);
    args.extend(extra);
    sim_bridge(&args)
}

#[test]
fn four_shards_merge_into_the_single_process_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let single = dir.join("single.json");
    ok(eval(&single, &[]));
    let parts: Vec<PathBuf> = (0..4).map(|k| dir.join(format!("part{k}.json"))).collect();
    for (k, part) in parts.iter().enumerate() {
        ok(eval(part, &["--shard", &format!("{k}/4")]));
        let json = without_wall_time(part);
        assert_eq!(json["plan"]["shard"], format!("{k}/4"));
        assert_eq!(json["_checkpoint"]["progress"], serde_json::json!([3, 3]));
    }
    let merged = dir.join("merged.json");
    let run = ok(merge(&parts, &merged, &[]));
    assert!(String::from_utf8_lossy(&run.stdout).contains("all 12 runs"));
    assert_eq!(without_wall_time(&merged), without_wall_time(&single));

    // A run in two parts.
    let twice = [parts[0].clone(), parts[1].clone(), parts[0].clone()];
    fails_saying(merge(&twice, &dir.join("x.json"), &[]), "is in both");
    // The plan names the traffic mode (CARLA's by default).
    assert_eq!(without_wall_time(&parts[0])["plan"]["traffic"], "carla");
    // A part of another campaign: another seed, another route timeout, other traffic.
    for (flags, says) in [
        (&["--seed", "7"][..], "from seed 7"),
        (&["--timeout", "30"][..], "route timeout"),
        (
            &["--traffic", "courteous"][..],
            "traffic `carla` against `courteous`",
        ),
    ] {
        let other = dir.join("other.json");
        ok(eval(&other, &[&["--shard", "3/4"][..], flags].concat()));
        let mixed = [parts[0].clone(), parts[1].clone(), parts[2].clone(), other];
        let run = merge(&mixed, &dir.join("x.json"), &[]);
        fails_saying(run, "come from different campaigns");
        fails_saying(merge(&mixed, &dir.join("x.json"), &[]), says);
    }
    // A share missing: refused, or written as a partial file that says what is missing.
    let three = &parts[..3];
    fails_saying(
        merge(three, &dir.join("x.json"), &[]),
        "3 of 12 runs are missing",
    );
    let partial = dir.join("partial.json");
    ok(merge(three, &partial, &["--allow-missing"]));
    let json = without_wall_time(&partial);
    assert_eq!(json["entry_status"], "Finished with missing data");
    assert_eq!(json["eligible"], false);
    let exceptions = json["_checkpoint"]["global_record"]["meta"]["exceptions"]
        .as_array()
        .unwrap();
    assert_eq!(exceptions.len(), 3, "{exceptions:?}");
    // A file without a plan (the leaderboard's own) says why it cannot be merged.
    let mut bare = without_wall_time(&parts[0]);
    bare.as_object_mut().unwrap().remove("plan");
    let bare_path = dir.join("bare.json");
    std::fs::write(&bare_path, bare.to_string()).unwrap();
    fails_saying(
        merge(&[bare_path], &dir.join("x.json"), &[]),
        "no `plan` in this results file",
    );
    // Resuming a share into another share's file is refused.
    fails_saying(
        eval(&parts[0], &["--shard", "1/4", "--resume"]),
        "it holds share 0/4",
    );
    // Resuming with another agent is refused.
    fails_saying(
        eval(
            &parts[0],
            &["--shard", "0/4", "--resume", "--agent", "oracle-plan"],
        ),
        "were driven by expert",
    );
    // A malformed share.
    fails_saying(
        eval(&dir.join("x.json"), &["--shard", "4/4"]),
        "shares count from 0 to 3",
    );
}
