//! The top-level README's one-minute start, run as written: every `target/release/...` command
//! of its first shell block, in a fresh folder, must succeed and leave what the README says it
//! leaves. (Its Python step is `proto/python/examples/one_step.py`, run by `python.rs`.)

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use ssrdrive_tests::binary;

/// The commands of the first ```sh block under "## One-minute start", comments stripped.
fn one_minute_start() -> Vec<Vec<String>> {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md"))
            .unwrap();
    let section = readme
        .split("## One-minute start")
        .nth(1)
        .expect("the README has a one-minute start");
    let block = section
        .split("```sh")
        .nth(1)
        .and_then(|b| b.split("```").next())
        .expect("a shell block");
    block
        .lines()
        .map(|l| l.split('#').next().unwrap().trim())
        .filter(|l| l.starts_with("target/release/"))
        .map(|l| l.split_whitespace().map(str::to_string).collect())
        .collect()
}

#[test]
fn the_readmes_one_minute_start_runs() {
    let commands = one_minute_start();
    assert!(commands.len() >= 3, "{commands:?}");
    let tmp = tempfile::tempdir().unwrap();
    let started = Instant::now();
    for command in &commands {
        let name = command[0].trim_start_matches("target/release/");
        let run = Command::new(binary(name))
            .args(&command[1..])
            .current_dir(tmp.path())
            .output()
            .expect("runs");
        assert!(
            run.status.success(),
            "{command:?}: {}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
    eprintln!(
        "the one-minute start took {:.0} s",
        started.elapsed().as_secs_f64()
    );
    // What the text after the block promises.
    assert!(tmp.path().join("pictures/route_3_rep0.png").is_file());
    for results in ["expert.json", "agent.json"] {
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(tmp.path().join(results)).unwrap())
                .unwrap();
        assert_eq!(json["_checkpoint"]["records"].as_array().unwrap().len(), 1);
    }
}
