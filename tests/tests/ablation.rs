//! The ablation harness (`agent/ablation/ablate.py`) end to end on a tiny budget: it collects
//! nothing itself, so a small expert dataset comes first; then two variants are trained for two
//! steps, driven on one route of each Town05-style set for a second, timed in one sitting, and
//! the table is written. Run again, every finished stage is skipped; an unfinished run stays
//! out of the table.

use std::path::Path;
use std::process::{Command, Output};

use ssrdrive_tests::binary;

fn ablate(args: &[&str], bin: &Path) -> Output {
    Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../agent/ablation/ablate.py"))
        .arg("--bin")
        .arg(bin)
        .args(args)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("python3 runs")
}

/// Runs the harness, which must succeed, and returns its standard output.
fn ablate_ok(args: &[&str], bin: &Path) -> String {
    let run = ablate(args, bin);
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    stdout
}

#[test]
fn ablations_train_drive_time_and_tabulate_each_variant_and_resume() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, out, kept) = (
        tmp.path().join("data"),
        tmp.path().join("out"),
        tmp.path().join("kept"),
    );
    let collect = Command::new(binary("sim-bridge"))
        .args([
            "collect",
            "--routes",
            "train-small",
            "--limit",
            "40",
            "--vehicles",
            "0",
        ])
        .args(["--quiet", "--out"])
        .arg(&data)
        .output()
        .unwrap();
    assert!(
        collect.status.success(),
        "{}",
        String::from_utf8_lossy(&collect.stderr)
    );
    let bin = binary("sim-bridge").parent().unwrap().to_path_buf();
    let (data, out_arg, kept_arg) = (
        data.to_str().unwrap(),
        out.to_str().unwrap(),
        kept.to_str().unwrap(),
    );
    let args = [
        "--data",
        data,
        "--out",
        out_arg,
        "--variants",
        "full,tokens-4",
        "--steps",
        "2",
        "--repetitions",
        "1",
        "--limit",
        "1",
        "--timeout",
        "1",
        "--bench-iterations",
        "1",
        "--bench-rounds",
        "1",
        "--jobs",
        "1",
        "--keep",
        kept_arg,
    ];
    let stdout = ablate_ok(&args, &bin);
    assert!(stdout.contains("[tokens-4 seed 0] train"), "{stdout}");
    assert!(
        stdout.contains("[timing round 1 of 1] tokens-4 batch 8"),
        "{stdout}"
    );

    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    let rows = table["runs"].as_array().unwrap();
    let variants: Vec<&str> = rows
        .iter()
        .map(|r| r["variant"].as_str().unwrap())
        .collect();
    assert_eq!(variants, ["full", "tokens-4"]);
    // Fewer tokens, fewer TokenLearner outputs; both ran through training, eval and timing.
    assert!(
        rows[1]["timing"]["params"].as_f64().unwrap()
            < rows[0]["timing"]["params"].as_f64().unwrap(),
        "{rows:?}"
    );
    for row in rows {
        assert_eq!(row["l2_m"].as_array().unwrap().len(), 3, "{row}");
        for timed in ["ms_batch_1", "ms_batch_8", "train_step_ms_batch_8"] {
            assert!(row["timing"][timed].as_f64().unwrap() > 0.0, "{row}");
        }
        for routes in ["town05-long-style", "town05-short-style"] {
            assert_eq!(row[routes]["runs"], 1, "{row}");
        }
    }
    // tokens-4 against full over the drives both made: one route of each set, its interval
    // around its difference.
    for routes in ["town05-long-style", "town05-short-style"] {
        let paired = &table["against_full"]["tokens-4"][routes];
        assert_eq!(paired["drives"], 1, "{paired}");
        let (low, mean, high) = (
            paired["low"].as_f64().unwrap(),
            paired["mean"].as_f64().unwrap(),
            paired["high"].as_f64().unwrap(),
        );
        assert!(low <= mean && mean <= high, "{paired}");
    }
    let markdown = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(markdown.contains("| tokens-4 | 0 |"), "{markdown}");
    assert!(markdown.contains("Against full SSR"), "{markdown}");

    // Again: nothing is trained or driven twice, and the table is the same.
    let stdout = ablate_ok(&args, &bin);
    assert!(!stdout.contains("(log"), "{stdout}");
    assert_eq!(
        std::fs::read_to_string(out.join("ablation.md")).unwrap(),
        markdown
    );
    // The kept figures, without the checkpoints, rebuild the same table.
    ablate_ok(&["--out", kept_arg, "--table-only"], &bin);
    assert_eq!(
        std::fs::read_to_string(kept.join("ablation.md")).unwrap(),
        markdown
    );
    assert!(kept.join("timing.json").is_file());
    assert!(!kept.join("full/seed-0/agent.safetensors").exists());
    assert!(!kept.join("full/seed-0/train").exists());
    // A run whose evaluations did not all finish stays out of the table.
    std::fs::remove_file(out.join("tokens-4/seed-0/done")).unwrap();
    let stdout = ablate_ok(&["--out", out_arg, "--table-only"], &bin);
    assert!(
        stdout.contains("| full | 0 |") && !stdout.contains("tokens-4"),
        "{stdout}"
    );

    // Unknown variants and missing binaries are named.
    let bad = ablate(&["--data", data, "--variants", "full,huge"], &bin);
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && stderr.contains("unknown variant huge"),
        "{stderr}"
    );
    let missing = ablate(&["--data", data], Path::new("/no/such/bin"));
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(
        !missing.status.success() && stderr.contains("/no/such/bin/ssr-agent is missing"),
        "{stderr}"
    );
}

/// One finished run's figures as the harness keeps them, every drive scoring `ds`.
fn write_run(kept: &Path, variant: &str, seed: u32, ds: f64) {
    let run = kept.join(variant).join(format!("seed-{seed}"));
    std::fs::create_dir_all(&run).unwrap();
    std::fs::write(
        run.join("inspect.txt"),
        "training: {\"validation\": {\"l2_m\": [0.5, 1.0, 1.5]}}\n",
    )
    .unwrap();
    for routes in ["town05-long-style", "town05-short-style"] {
        let record = serde_json::json!({
            "route_id": "7",
            "meta": {"repetition": 0, "route_length": 1000.0},
            "scores": {"score_composed": ds, "score_route": 100.0, "score_penalty": ds / 100.0},
            "infractions": {"collisions_vehicle": []},
        });
        let results = serde_json::json!({"_checkpoint": {"records": [record]}});
        std::fs::write(run.join(format!("eval-{routes}.json")), results.to_string()).unwrap();
    }
    std::fs::write(run.join("done"), "").unwrap();
}

#[test]
fn a_variant_trained_once_is_set_against_every_seed_of_full_ssr() {
    let tmp = tempfile::tempdir().unwrap();
    write_run(tmp.path(), "full", 0, 60.0);
    write_run(tmp.path(), "full", 1, 80.0);
    write_run(tmp.path(), "tokens-4", 0, 90.0);
    let bin = binary("sim-bridge").parent().unwrap().to_path_buf();
    let stdout = ablate_ok(
        &["--out", tmp.path().to_str().unwrap(), "--table-only"],
        &bin,
    );
    // Full SSR's row is the mean ± standard deviation of its two seeds.
    assert!(stdout.contains("| full | 0,1 |"), "{stdout}");
    assert!(stdout.contains("| 70.00 ± 14.14 |"), "{stdout}");
    // The difference is taken from the mean of both seeds' drive (70), not seed 0's alone (60).
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("ablation.json")).unwrap())
            .unwrap();
    for routes in ["town05-long-style", "town05-short-style"] {
        let paired = &table["against_full"]["tokens-4"][routes];
        assert_eq!(paired["drives"], 1, "{paired}");
        assert_eq!(paired["mean"].as_f64().unwrap(), 20.0, "{paired}");
    }
}
