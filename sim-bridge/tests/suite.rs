//! The held-out protocol through the `sim-bridge` binary: named suites driven into one folder,
//! collection refused on evaluation towns, procedural training towns written on request.

use std::path::Path;
use std::process::{Command, Output};

fn sim_bridge(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sim-bridge"))
        .args(args)
        .output()
        .expect("runs")
}

fn stderr(run: &Output) -> String {
    String::from_utf8_lossy(&run.stderr).into_owned()
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The CARLA maps folder beside the checkout, if present (CI has it).
fn carla_maps() -> Option<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/carla");
    if dir.join("Town02.xodr").is_file() {
        return Some(dir);
    }
    assert!(
        std::env::var_os("SSRDRIVE_REQUIRE_CARLA").is_none(),
        "SSRDRIVE_REQUIRE_CARLA is set but {} has no Town02.xodr",
        dir.display()
    );
    eprintln!("SKIP: no CARLA maps at {}", dir.display());
    None
}

#[test]
fn a_suite_drives_each_route_file_into_one_folder_repetition_by_repetition_and_sums_them_up() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("home");
    let home = |extra: &[&str]| {
        let mut args = vec![
            "eval",
            "--suite",
            "home",
            "--repetitions",
            "2",
            "--timeout",
            "2",
        ];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--quiet", "--out", out.to_str().unwrap()]);
        sim_bridge(&args)
    };
    let run = home(&["--jobs", "2"]);
    assert!(run.status.success(), "{}", stderr(&run));
    let log = stderr(&run);
    assert!(log.contains("not the suite's protocol"), "{log}");
    // Repetition 0 of both parts before repetition 1 of either.
    let at = |line: &str| log.find(line).unwrap_or_else(|| panic!("{line}: {log}"));
    let passes = [
        at("suite home: town05-long-style, repetition 1 of 2"),
        at("suite home: town05-short-style, repetition 1 of 2"),
        at("suite home: town05-long-style, repetition 2 of 2"),
        at("suite home: town05-short-style, repetition 2 of 2"),
    ];
    assert!(passes.is_sorted(), "{log}");
    let summary = read_json(&out.join("suite.json"));
    assert_eq!(summary["suite"], "home");
    let parts = summary["parts"].as_array().unwrap();
    let names: Vec<&str> = parts.iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["town05-long-style", "town05-short-style"]);
    let mut runs = 0;
    for part in parts {
        let results = read_json(&out.join(part["results"].as_str().unwrap()));
        // --timeout cuts each run: said so, and not an agent error.
        assert_eq!(results["entry_status"], "Finished");
        let records = results["_checkpoint"]["records"].as_array().unwrap();
        for (index, record) in records.iter().enumerate() {
            assert_eq!(record["status"], "Stopped - --timeout reached", "{record}");
            assert_eq!(record["meta"]["stopped_at_s"], 2.0);
            // Leaderboard order in the file: every route of repetition 0, then of 1.
            let repetition = (index >= records.len() / 2) as u64;
            assert_eq!(record["meta"]["repetition"], repetition, "{record}");
        }
        assert_eq!(part["runs"].as_u64().unwrap() as usize, records.len());
        assert_eq!(part["town"], "ssr_town05");
        runs += records.len();
    }
    assert_eq!(runs, 60);
    assert_eq!(summary["all"]["runs"].as_u64().unwrap(), 60);
    // 2 simulated seconds of each route: some metres driven, nothing completed.
    let km = summary["all"]["km_driven"].as_f64().unwrap();
    assert!(km > 0.0 && km < 60.0 * 0.05, "{km}");
    assert_eq!(summary["all"]["completed"].as_u64().unwrap(), 0);
    let table = String::from_utf8_lossy(&run.stdout);
    assert!(
        table.contains("all (home)") && table.contains("veh/km"),
        "{table}"
    );

    // --resume keeps every run: nothing is driven again, the summary is the same.
    let again = home(&["--resume"]);
    assert!(again.status.success(), "{}", stderr(&again));
    assert!(
        stderr(&again).contains("20 of 20 runs already scored"),
        "{}",
        stderr(&again)
    );
    assert_eq!(read_json(&out.join("suite.json")), summary);
}

#[test]
fn the_held_out_suite_needs_the_carla_maps_and_drives_both_towns() {
    let tmp = tempfile::tempdir().unwrap();
    let empty = tmp.path().join("no-maps");
    std::fs::create_dir(&empty).unwrap();
    let out = tmp.path().join("unseen");
    let run = sim_bridge(&[
        "eval",
        "--suite",
        "unseen",
        "--maps",
        empty.to_str().unwrap(),
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!run.status.success());
    assert!(
        stderr(&run).contains("no Town02.xodr") && stderr(&run).contains("heldout-town02"),
        "{}",
        stderr(&run)
    );
    let Some(maps) = carla_maps() else { return };
    let run = sim_bridge(&[
        "eval",
        "--suite",
        "unseen",
        "--maps",
        maps.to_str().unwrap(),
        "--repetitions",
        "1",
        "--timeout",
        "2",
        "--jobs",
        "2",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let summary = read_json(&out.join("suite.json"));
    let towns: Vec<&str> = summary["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["town"].as_str().unwrap())
        .collect();
    assert_eq!(towns, ["Town02", "ssr_heldout_radial"]);
    assert_eq!(summary["all"]["runs"].as_u64().unwrap(), 60);
}

#[test]
fn suite_mistakes_are_named() {
    let run = sim_bridge(&["eval", "--suite", "nowhere"]);
    assert!(!run.status.success());
    assert!(
        stderr(&run).contains("no such suite") && stderr(&run).contains("unseen, home"),
        "{}",
        stderr(&run)
    );
    let run = sim_bridge(&["eval", "--suite", "home", "--routes", "town05-short-style"]);
    assert!(!run.status.success());
    assert!(
        stderr(&run).contains("cannot be used with"),
        "{}",
        stderr(&run)
    );
}

#[test]
fn collection_is_refused_on_every_evaluation_town() {
    let tmp = tempfile::tempdir().unwrap();
    for routes in ["heldout-radial", "town05-short-style"] {
        let out = tmp.path().join(routes);
        let run = sim_bridge(&[
            "collect",
            "--routes",
            routes,
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(!run.status.success(), "{routes} was collected");
        assert!(
            stderr(&run).contains("evaluation suite"),
            "{}",
            stderr(&run)
        );
        let episodes = out.join("episodes");
        assert!(!episodes.exists() || std::fs::read_dir(&episodes).unwrap().next().is_none());
    }
    let run = sim_bridge(&["routes", "list"]);
    let list = String::from_utf8_lossy(&run.stdout);
    assert!(
        list.contains("heldout-radial") && list.contains("heldout-town02"),
        "{list}"
    );
    let run = sim_bridge(&["towns", "list"]);
    let list = String::from_utf8_lossy(&run.stdout);
    assert!(
        list.contains("[held out]") && list.contains("ssr_heldout_radial"),
        "{list}"
    );
}

#[test]
fn procedural_towns_are_written_per_seed_and_drive() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("towns");
    let run = sim_bridge(&[
        "towns",
        "procedural",
        "--seeds",
        "3-4",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let town = dir.join("ssr_proc_003.xodr");
    let first = std::fs::read(&town).unwrap();
    assert!(dir.join("ssr_proc_004.xodr").is_file());
    let again = sim_bridge(&[
        "towns",
        "procedural",
        "--seeds",
        "3",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(again.status.success());
    assert_eq!(
        std::fs::read(&town).unwrap(),
        first,
        "the same seed, the same bytes"
    );
    let routes = dir.join("routes.xml");
    let run = sim_bridge(&[
        "routes",
        "random",
        "--map",
        town.to_str().unwrap(),
        "--count",
        "3",
        "--length",
        "100,300",
        "--out",
        routes.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let results = tmp.path().join("results.json");
    let run = sim_bridge(&[
        "eval",
        "--routes",
        routes.to_str().unwrap(),
        "--maps",
        dir.to_str().unwrap(),
        "--quiet",
        "--out",
        results.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", stderr(&run));
    let records = read_json(&results)["_checkpoint"]["records"].clone();
    assert_eq!(records.as_array().unwrap().len(), 3);
    for bad in ["4-3", "x", "1-2000"] {
        let run = sim_bridge(&[
            "towns",
            "procedural",
            "--seeds",
            bad,
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert!(!run.status.success(), "--seeds {bad} accepted");
        assert!(stderr(&run).contains(bad), "{}", stderr(&run));
    }
}
