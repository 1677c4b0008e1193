//! Floors under the driving itself, so that a change that makes the bundled agent or the
//! expert drive worse turns CI red: each drives a few bundled routes through `sim-bridge eval`
//! (the agent served by a real `ssr-agent serve` on a loopback port), with a fixed seed, and
//! its driving score must stay a little under what it scores today.
//!
//! Today (seed 0): the bundled agent scores DS 100 / RC 100 on each of the four short routes
//! below; the expert 100 on them, and 99.0 on the held-out radial town's 20 routes (one stop
//! sign rolled through). The floors leave room for a route going a little differently, not for
//! an agent that stopped driving.

use std::path::Path;

use ssrdrive_tests::binary;

/// DS and RC means, the runs' statuses, from a results file.
fn figures(results: &Path) -> (f64, f64, Vec<String>) {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(results).unwrap()).unwrap();
    let records = json["_checkpoint"]["records"].as_array().unwrap().clone();
    let mean = |key: &str| {
        records
            .iter()
            .map(|r| r["scores"][key].as_f64().unwrap())
            .sum::<f64>()
            / records.len() as f64
    };
    let statuses = records
        .iter()
        .map(|r| r["status"].as_str().unwrap().to_string())
        .collect();
    (mean("score_composed"), mean("score_route"), statuses)
}

fn eval(agent: &str, args: &[&str], out: &Path) -> (f64, f64, Vec<String>) {
    let run = std::process::Command::new(binary("sim-bridge"))
        .args([
            "eval", "--agent", agent, "--jobs", "2", "--seed", "0", "--quiet", "--out",
        ])
        .arg(out)
        .args(args)
        .output()
        .expect("sim-bridge runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    figures(out)
}

const SHORT_ROUTES: [&str; 4] = ["--routes", "town05-short-style", "--route-ids", "0,3,7,10"];

#[test]
fn the_bundled_agent_drives_short_routes_above_its_floor() {
    let tmp = tempfile::tempdir().unwrap();
    let (ds, rc, statuses) = eval("local", &SHORT_ROUTES, &tmp.path().join("agent.json"));
    assert_eq!(statuses.len(), 4);
    assert!(
        statuses.iter().all(|s| !s.contains("Agent crashed")),
        "{statuses:?}"
    );
    assert!(
        ds >= 85.0 && rc >= 95.0,
        "DS {ds:.2}, RC {rc:.2}: {statuses:?}"
    );
}

#[test]
fn the_expert_drives_home_and_held_out_routes_above_its_floor() {
    let tmp = tempfile::tempdir().unwrap();
    let (ds, rc, _) = eval("expert", &SHORT_ROUTES, &tmp.path().join("home.json"));
    assert!(ds >= 95.0 && rc >= 99.0, "home: DS {ds:.2}, RC {rc:.2}");
    let (ds, rc, statuses) = eval(
        "expert",
        &["--routes", "heldout-radial"],
        &tmp.path().join("radial.json"),
    );
    assert_eq!(statuses.len(), 20);
    assert!(ds >= 95.0 && rc >= 99.0, "radial: DS {ds:.2}, RC {rc:.2}");
}
