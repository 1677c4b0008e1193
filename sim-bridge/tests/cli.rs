//! The `sim-bridge` binary, run as a user would.

use std::process::Command;

fn sim_bridge(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sim-bridge"))
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn eval_writes_leaderboard_results_and_a_summary() {
    let dir = std::env::temp_dir().join(format!("sim-bridge-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("results.json");
    let pictures = dir.join("pictures");
    let run = sim_bridge(&[
        "eval",
        "--routes",
        "town05-short-style",
        "--limit",
        "2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
        "--pictures",
        pictures.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let table = String::from_utf8_lossy(&run.stdout);
    assert!(table.contains("mean of 2"), "{table}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(json["_checkpoint"]["progress"], serde_json::json!([2, 2]));
    assert_eq!(json["_checkpoint"]["records"].as_array().unwrap().len(), 2);
    assert!(json["_checkpoint"]["global_record"]["scores"]["score_composed"].is_number());
    assert_eq!(std::fs::read_dir(&pictures).unwrap().count(), 2);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_arguments_fail_with_a_clear_message() {
    let run = sim_bridge(&["eval", "--routes", "no-such-set"]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("no bundled set") && err.contains("town05-long-style"),
        "{err}"
    );
    let run = sim_bridge(&[
        "eval",
        "--agent",
        "nobody",
        "--routes",
        "town05-short-style",
    ]);
    assert!(String::from_utf8_lossy(&run.stderr).contains("unknown agent"));
}

#[test]
fn listings_and_help_explain() {
    let help = sim_bridge(&["--help"]);
    assert!(String::from_utf8_lossy(&help.stdout).contains("leaderboard"));
    let list = sim_bridge(&["routes", "list"]);
    assert!(String::from_utf8_lossy(&list.stdout).contains("town05-long-style"));
    let towns = sim_bridge(&["towns", "list"]);
    assert!(String::from_utf8_lossy(&towns.stdout).contains("ssr_town05"));
}
