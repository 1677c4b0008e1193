//! The `sim-bridge` binary, run as a user would.

use std::process::Command;

use sim_bridge::towngen::TownStyle;

fn sim_bridge(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_sim-bridge"))
        .args(args)
        .output()
        .expect("runs")
}

/// Fails the test with the command's standard error unless it exited successfully.
fn assert_succeeded(run: &std::process::Output) {
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

#[test]
fn eval_writes_leaderboard_results_and_a_summary() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
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
    assert_succeeded(&run);
    let table = String::from_utf8_lossy(&run.stdout);
    assert!(table.contains("mean of 2"), "{table}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(json["_checkpoint"]["progress"], serde_json::json!([2, 2]));
    assert_eq!(json["_checkpoint"]["records"].as_array().unwrap().len(), 2);
    // The global DS is the mean of the runs' DS.
    let records = json["_checkpoint"]["records"].as_array().unwrap();
    let mean = records
        .iter()
        .map(|r| r["scores"]["score_composed"].as_f64().unwrap())
        .sum::<f64>()
        / records.len() as f64;
    let global = json["_checkpoint"]["global_record"]["scores"]["score_composed"]
        .as_f64()
        .unwrap();
    assert!((global - mean).abs() < 1e-9, "{global} vs {mean}");
    assert_eq!(std::fs::read_dir(&pictures).unwrap().count(), 2);
}

#[test]
fn eval_jobs_run_routes_at_once_with_the_same_results() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let records = |jobs: &str| {
        let out = dir.join(format!("jobs{jobs}.json"));
        let run = sim_bridge(&[
            "eval",
            "--routes",
            "town05-short-style",
            "--limit",
            "3",
            "--repetitions",
            "2",
            "--timeout",
            "20",
            "--jobs",
            jobs,
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_succeeded(&run);
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let mut records = json["_checkpoint"]["records"].as_array().unwrap().clone();
        for record in &mut records {
            record["meta"]["duration_system"] = serde_json::Value::Null;
        }
        records
    };
    let (one, three) = (records("1"), records("3"));
    assert_eq!(one.len(), 6);
    assert_eq!(one, three, "the same runs, in leaderboard order");
    let repetitions: Vec<_> = one
        .iter()
        .map(|r| r["meta"]["repetition"].as_u64())
        .collect();
    assert_eq!(repetitions, [0, 0, 0, 1, 1, 1].map(Some));
}

#[test]
fn eval_resume_keeps_scored_runs_and_refuses_another_plan() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = dir.join("results.json");
    let eval = |repetitions: &str, seed: &str, resume: bool| {
        let mut args = vec![
            "eval",
            "--routes",
            "town05-short-style",
            "--limit",
            "2",
            "--timeout",
            "10",
            "--repetitions",
            repetitions,
            "--seed",
            seed,
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ];
        if resume {
            args.push("--resume");
        }
        sim_bridge(&args)
    };
    let records = || -> Vec<serde_json::Value> {
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        json["_checkpoint"]["records"].as_array().unwrap().clone()
    };
    // Nothing to resume from yet: a fresh run.
    let first = eval("1", "0", true);
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let scored = records();
    assert_eq!(scored.len(), 2);

    // The second repetition is added; the first one's records are kept as they were.
    let second = eval("2", "0", true);
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(second.status.success(), "{stderr}");
    assert!(
        stderr.contains("resuming: 2 of 4 runs already scored"),
        "{stderr}"
    );
    assert_eq!(stderr.matches(" rep 1:").count(), 2, "{stderr}");
    assert_eq!(stderr.matches(" rep 0:").count(), 0, "{stderr}");
    let all = records();
    assert_eq!(all.len(), 4);
    assert_eq!(all[..2], scored[..]);

    let refused = |run: std::process::Output, needles: [&str; 2]| {
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{stderr}");
        assert!(needles.iter().all(|n| stderr.contains(n)), "{stderr}");
    };
    // Another seed is another plan: refused, and the file is left alone.
    refused(eval("2", "7", true), ["cannot resume from", "seed 7"]);
    assert_eq!(records(), all);
    // A broken file is named.
    std::fs::write(&out, "{ not json").unwrap();
    refused(eval("2", "0", true), ["resuming from", "malformed"]);
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
    for flag in ["--jobs", "--repetitions"] {
        let run = sim_bridge(&["eval", flag, "0"]);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success() && err.contains("at least 1"), "{err}");
    }
    // Each command checks its numbers before it loads or connects to anything.
    let empty = tempfile::tempdir().unwrap();
    let empty = empty.path().to_str().unwrap();
    let cases: &[(&[&str], &str)] = &[
        (
            &["collect", "--noise-rate=-1", "--out", empty],
            "--noise-rate must be",
        ),
        (
            &["collect", "--noise-longitudinal", "2", "--out", empty],
            "--noise-longitudinal must be",
        ),
        (
            &["collect", "--rate", "3", "--out", empty],
            "--rate 3: must be 20 Hz divided",
        ),
        (
            &["collect", "--noise-steer", "0.5,0.1", "--out", empty],
            "MIN 0.5 is above MAX 0.1",
        ),
        (
            &["load", "--episodes", "0"],
            "--episodes and --frames must be at least 1",
        ),
        (
            &["load", "--frames", "0"],
            "--episodes and --frames must be at least 1",
        ),
        (
            &["eval", "--timeout", "0"],
            "expected a positive number, got '0'",
        ),
        (
            &["eval", "--timeout", "NaN"],
            "expected a positive number, got 'NaN'",
        ),
        (
            &["replay", "--call-timeout", "1e300", empty],
            "longer than any run can take",
        ),
        (
            &["render", "--topdown-radius=-5", "--out", empty],
            "--topdown-radius must be a positive",
        ),
        (&["replay", empty], "no .ssrlog files"),
        (&["eval", "--jobs", "-1"], "at least 1, got '-1'"),
        (
            &["render", "--every", "0", "--out", empty],
            "at least 1, got '0'",
        ),
        (
            &[
                "eval",
                "--map",
                "ssr_town5",
                "--routes",
                "town05-short-style",
            ],
            "bundled towns: ssr_town05, ssr_train_small",
        ),
        (
            &[
                "eval",
                "--routes",
                "town05-short-style",
                "--map",
                "ssr_train_small",
            ],
            "route 0 is on town ssr_town05, but the map is ssr_train_small",
        ),
        (
            &[
                "eval",
                "--routes",
                "town05-short-style",
                "--route-ids",
                "3,abc,99",
            ],
            "abc, 99 not in town05-short-style, whose route ids are 0-19",
        ),
        (
            &[
                "collect",
                "--routes",
                "train-small,train-dense",
                "--route-ids",
                "7,300",
                "--out",
                empty,
            ],
            "300 not in train-small,train-dense",
        ),
    ];
    for (args, expected) in cases {
        let run = sim_bridge(args);
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{args:?} succeeded");
        assert!(err.contains(expected), "{args:?}: {err}");
    }
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

#[test]
fn render_writes_camera_frames_and_an_animation() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let run = sim_bridge(&[
        "render",
        "--routes",
        "town05-short-style",
        "--limit",
        "1",
        "--rig",
        "tcp-small",
        "--max-frames",
        "5",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_succeeded(&run);
    let route = std::fs::read_dir(dir)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let mut names: Vec<String> = std::fs::read_dir(&route)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names.len(), 6, "{names:?}");
    assert_eq!(names[0], "000000_rgb_front.png");
    let frame = std::fs::read(route.join(&names[1])).unwrap();
    let image = ssrdrive_proto::image::decode_png(&frame).unwrap();
    assert_eq!((image.width, image.height), (320, 96));
    let animation = std::fs::read(route.join("run.png")).unwrap();
    assert!(
        animation.windows(4).any(|w| w == b"acTL"),
        "run.png is not an animated PNG"
    );
}

#[test]
fn malformed_rigs_are_refused_with_the_problem_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let cases = [
        (
            r#"[{"id":"front","x":0,"y":0,"z":2,"roll":0,"pitch":0,"yaw":0,"width":320,"height":96,"fov":200}]"#,
            "fov",
        ),
        (
            r#"[{"id":"front/../x","x":0,"y":0,"z":2,"roll":0,"pitch":0,"yaw":0,"width":320,"height":96,"fov":90}]"#,
            "letters, digits",
        ),
        (
            r#"[{"id":"front","x":0,"y":0,"z":2,"roll":0,"pitch":1e9,"yaw":0,"width":320,"height":96,"fov":90}]"#,
            "pitch = 1000000000 degrees is outside -360..360",
        ),
        (r#"{"cameras": []}"#, "at least one camera"),
        (r#"[{"id":"front"}]"#, "missing field"),
    ];
    for (k, (json, expected)) in cases.iter().enumerate() {
        let path = dir.join(format!("rig{k}.json"));
        std::fs::write(&path, json).unwrap();
        let run = sim_bridge(&[
            "bench",
            "render",
            "--frames",
            "1",
            "--rig",
            path.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success());
        assert!(
            stderr.contains(expected) && stderr.contains("rig"),
            "{stderr}"
        );
    }
    let run = sim_bridge(&["bench", "render", "--rig", "no-such-rig"]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("tcp-small"), "presets are listed: {stderr}");
}

/// Every file of every episode folder under `root`, with its bytes.
fn dataset_files(root: &std::path::Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![root.join("episodes")];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let rel = path
                    .strip_prefix(root)
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    out
}

#[test]
fn a_killed_collection_resumes_without_losing_or_duplicating_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (killed, clean) = (dir.join("killed"), dir.join("clean"));
    let args = |out: &std::path::Path| {
        vec![
            "collect".to_string(),
            "--routes".into(),
            "train-dense".into(),
            "--limit".into(),
            "6".into(),
            "--rig".into(),
            "tcp".into(),
            "--jobs".into(),
            "1".into(),
            "--quiet".into(),
            "--out".into(),
            out.to_string_lossy().into_owned(),
        ]
    };
    // Complete episodes: renamed from their hidden `.NAME.partial` folder, where the episode
    // file is written just before the rename (counting those raced the resume's own count).
    let complete = |out: &std::path::Path| {
        std::fs::read_dir(out.join("episodes")).map_or(0, |entries| {
            entries
                .map(|e| e.unwrap().path())
                .filter(|p| !p.file_name().unwrap().to_string_lossy().starts_with('.'))
                .filter(|p| p.join("episode.json").exists())
                .count()
        })
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_sim-bridge"))
        .args(args(&killed))
        .spawn()
        .unwrap();
    while complete(&killed) < 2 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "finished before it could be killed"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let before = complete(&killed);
    assert!(
        (2..6).contains(&before),
        "{before} episodes complete at the kill"
    );

    let resumed = sim_bridge(&args(&killed).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let said = String::from_utf8_lossy(&resumed.stdout);
    assert!(
        said.contains(&format!("skipped {before} already complete")),
        "{said}"
    );
    let whole = sim_bridge(&args(&clean).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(whole.status.success());

    let (a, b) = (dataset_files(&killed), dataset_files(&clean));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        if !name.ends_with("episode.json") {
            assert!(bytes == &b[name], "{name} differs after the resume");
        }
    }
    let manifest = |root: &std::path::Path| {
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(root.join("manifest.json")).unwrap()).unwrap();
        (m["episodes"].clone(), m["frames"].clone())
    };
    assert_eq!(manifest(&killed), manifest(&clean));
}

/// `--maps DIR` takes the map a route file's town names, and a route that cannot be planned
/// is a failed run with zero scores in the results (as the leaderboard counts it), not a
/// route left out; `eval` then exits non-zero after writing them.
#[test]
fn eval_finds_maps_by_town_and_scores_unplannable_routes_as_failures() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let maps = dir.join("maps");
    std::fs::create_dir_all(&maps).unwrap();
    std::fs::write(
        maps.join("LineTown.xodr"),
        include_str!("maps/degenerate_road.xodr"),
    )
    .unwrap();
    // One 60 m one-way lane along +x (CARLA's y is the map's -y): route 0 drives it, route 1
    // asks for the opposite way.
    let routes = dir.join("routes.xml");
    std::fs::write(
        &routes,
        r#"<routes>
  <route id="0" town="LineTown">
    <waypoint x="2.0" y="1.75" z="0.0" yaw="0.0"/>
    <waypoint x="55.0" y="1.75" z="0.0" yaw="0.0"/>
  </route>
  <route id="1" town="LineTown">
    <waypoint x="55.0" y="1.75" z="0.0" yaw="180.0"/>
    <waypoint x="2.0" y="1.75" z="0.0" yaw="180.0"/>
  </route>
</routes>"#,
    )
    .unwrap();
    let out = dir.join("results.json");
    let eval = || {
        sim_bridge(&[
            "eval",
            "--routes",
            routes.to_str().unwrap(),
            "--maps",
            maps.to_str().unwrap(),
            "--vehicles",
            "0",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let run = eval();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "an unplannable route fails the run");
    assert!(
        stderr.contains("1 of 2 routes could not be planned"),
        "{stderr}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let records = json["_checkpoint"]["records"].as_array().unwrap();
    assert_eq!(records.len(), 2);
    assert_eq!(records[0]["status"], "Completed");
    let failed = records[1]["status"].as_str().unwrap();
    assert!(
        failed.starts_with("Failed - Route could not be planned: ") && failed.contains("no path"),
        "{failed}"
    );
    assert_eq!(records[1]["scores"]["score_composed"], 0.0);
    let global = json["_checkpoint"]["global_record"]["scores"]["score_composed"]
        .as_f64()
        .unwrap();
    assert!(
        (global - 50.0).abs() < 1.0,
        "the failure counts in the mean: {global}"
    );

    // A town with no map in the folder is named.
    std::fs::remove_file(maps.join("LineTown.xodr")).unwrap();
    let run = eval();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && stderr.contains("LineTown.xodr"),
        "{stderr}"
    );
}

#[test]
fn a_road_of_unusable_length_is_named_in_a_warning() {
    let tmp = tempfile::tempdir().unwrap();
    let xml = include_str!("maps/lane_drop.xodr").replace(
        r#"<road name="r3" length="100.0""#,
        r#"<road name="r3" length="NaN""#,
    );
    let map = tmp.path().join("bad-length.xodr");
    std::fs::write(&map, xml).unwrap();
    let routes = tmp.path().join("routes.xml");
    std::fs::write(
        &routes,
        r#"<routes><route id="0" town="bad-length">
            <waypoint x="20.0" y="1.75" z="0.0"/><waypoint x="250.0" y="1.75" z="0.0"/>
        </route></routes>"#,
    )
    .unwrap();
    let run = sim_bridge(&[
        "routes",
        "show",
        routes.to_str().unwrap(),
        "--map",
        map.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(
        stderr.contains(r#"road "3" skipped: no finite length above zero; it is left out"#),
        "{stderr}"
    );
}

/// `routes random` writes a route file that `routes show` and `eval --maps` read back (the town
/// named after the map file), `routes scenarios` a scenario file `eval --scenarios` reads for
/// them, and both refuse bad options and maps with the problem named.
#[test]
fn random_routes_and_scenario_files_on_any_map_are_written_and_driven() {
    let tmp = tempfile::tempdir().unwrap();
    let maps = tmp.path().join("maps");
    std::fs::create_dir(&maps).unwrap();
    let map = maps.join("mytown.xodr");
    std::fs::write(
        &map,
        sim_bridge::towngen::bundled(TownStyle::SmallTJunctions),
    )
    .unwrap();
    let out = tmp.path().join("random.xml");
    let random = |extra: &[&str]| {
        let mut args = vec!["routes", "random", "--map", map.to_str().unwrap()];
        args.extend_from_slice(extra);
        sim_bridge(&args)
    };
    let run = random(&[
        "--count",
        "3",
        "--length",
        "150,250",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert_succeeded(&run);
    assert!(
        stdout.contains("wrote 3 routes") && stdout.contains("on mytown"),
        "{stdout}"
    );
    let text = std::fs::read_to_string(&out).unwrap();
    assert_eq!(text.matches(r#"town="mytown""#).count(), 3, "{text}");

    // The expert drives the file's routes, found by town in --maps, with `extra` options.
    let drive = |extra: &[&str], results: &str| {
        let results = tmp.path().join(results);
        let mut args = vec![
            "eval",
            "--agent",
            "expert",
            "--routes",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(&["--maps", maps.to_str().unwrap(), "--quiet", "--out"]);
        args.push(results.to_str().unwrap());
        args.extend_from_slice(extra);
        let eval = sim_bridge(&args);
        assert!(
            eval.status.success(),
            "{}",
            String::from_utf8_lossy(&eval.stderr)
        );
    };
    drive(&[], "results.json");
    let results: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("results.json")).unwrap()).unwrap();
    let records = &results["_checkpoint"]["records"];
    assert_eq!(records.as_array().map(Vec::len), Some(3), "{results}");

    let scenarios = tmp.path().join("scenarios.json");
    let placed = sim_bridge(&[
        "routes",
        "scenarios",
        "--map",
        map.to_str().unwrap(),
        "--out",
        scenarios.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&placed.stdout);
    assert!(
        placed.status.success() && stdout.contains("triggers on mytown"),
        "{stdout} {}",
        String::from_utf8_lossy(&placed.stderr)
    );
    drive(
        &["--scenarios", scenarios.to_str().unwrap()],
        "with-scenarios.json",
    );
    let close = sim_bridge(&[
        "routes",
        "scenarios",
        "--map",
        map.to_str().unwrap(),
        "--spacing",
        "3",
        "--out",
        scenarios.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&close.stderr);
    assert!(
        !close.status.success() && stderr.contains("--spacing 3: give 10 to 10000 m"),
        "{stderr}"
    );

    for (args, expected) in [
        (vec!["--count", "0"], "--count 0"),
        (vec!["--length", "5,10"], "--length 5,10"),
        (vec!["--length", "300,100"], "MIN 300 is above MAX 100"),
        (vec!["--turn-bias", "1.5"], "--turn-bias 1.5"),
    ] {
        let mut all = args.clone();
        all.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let run = random(&all);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(
            !run.status.success() && stderr.contains(expected),
            "{args:?}: {stderr}"
        );
    }
    let broken = tmp.path().join("broken.xodr");
    std::fs::write(&broken, "<OpenDRIVE><road").unwrap();
    for (command, out) in [("random", "none.xml"), ("scenarios", "none.json")] {
        let out = tmp.path().join(out);
        let run = sim_bridge(&[
            "routes",
            command,
            "--map",
            broken.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(
            !run.status.success() && stderr.contains("map broken is not valid OpenDRIVE"),
            "{command}: {stderr}"
        );
        assert!(!out.exists(), "{command}");
    }
}

/// Every file of a dataset's episodes, by path relative to `root`, with its bytes; the
/// wall-clock time in `episode.json` left out (it differs between runs by nature).
fn episode_files(root: &std::path::Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut files = std::collections::BTreeMap::new();
    for episode in std::fs::read_dir(root.join("episodes")).unwrap() {
        let episode = episode.unwrap().path();
        let mut stack = vec![episode];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                    continue;
                }
                let mut bytes = std::fs::read(&path).unwrap();
                if path.ends_with("episode.json") {
                    let mut info: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
                    info["wall_seconds"] = serde_json::Value::Null;
                    bytes = info.to_string().into_bytes();
                }
                let relative = path.strip_prefix(root).unwrap();
                files.insert(relative.display().to_string(), bytes);
            }
        }
    }
    files
}

#[test]
fn a_collection_killed_mid_episode_resumes_to_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let collect = |out: &std::path::Path| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_sim-bridge"));
        command
            .args(["collect", "--routes", "train-dense", "--limit", "3"])
            .args(["--jobs", "1", "--vehicles", "10", "--quiet", "--out"])
            .arg(out);
        command
    };
    let whole = tmp.path().join("whole");
    assert!(collect(&whole).output().unwrap().status.success());

    // Killed (SIGKILL: no chance to tidy up) once the first episode is complete, so with the
    // second one in flight.
    let killed = tmp.path().join("killed");
    let mut child = collect(&killed).spawn().unwrap();
    let episodes = killed.join("episodes");
    let started = std::time::Instant::now();
    loop {
        let complete = std::fs::read_dir(&episodes)
            .map(|dir| {
                dir.flatten()
                    .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
                    .count()
            })
            .unwrap_or(0);
        assert!(
            started.elapsed().as_secs() < 120,
            "no episode complete in 120 s"
        );
        if complete >= 1 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    // Still running, so the kill lands mid-collection (`kill` succeeds on an ended child too).
    assert!(
        child.try_wait().unwrap().is_none(),
        "finished before it could be killed"
    );
    child.kill().unwrap();
    child.wait().unwrap();
    let run = collect(&killed).output().unwrap();
    assert_succeeded(&run);
    let (want, got) = (episode_files(&whole), episode_files(&killed));
    assert_eq!(
        want.keys().collect::<Vec<_>>(),
        got.keys().collect::<Vec<_>>()
    );
    for (path, bytes) in &want {
        assert!(&got[path] == bytes, "{path} differs after the resume");
    }
}

/// A full disk, as a file-size limit on the process: `eval` stops with an error that names the
/// results file, the file still holds the runs written before (valid JSON, no temporary file
/// left), and `--resume` finishes the evaluation once there is room.
#[test]
fn a_full_disk_stops_eval_with_the_results_so_far_intact() {
    use std::os::unix::process::CommandExt;
    let tmp = tempfile::tempdir().unwrap();
    let eval = |out: &std::path::Path, limit: &str| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_sim-bridge"));
        command
            .args([
                "eval",
                "--agent",
                "expert",
                "--routes",
                "town05-short-style",
            ])
            .args(["--vehicles", "0", "--quiet", "--limit", limit, "--out"])
            .arg(out);
        command
    };
    // The size of the results of one run, to set the limit between one run and two.
    let one = tmp.path().join("one.json");
    assert!(eval(&one, "1").output().unwrap().status.success());
    let limit = std::fs::metadata(&one).unwrap().len() + 300;

    let out = tmp.path().join("results.json");
    let mut command = eval(&out, "3");
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        command.pre_exec(move || {
            let rlimit = libc::rlimit {
                rlim_cur: limit,
                rlim_max: limit,
            };
            // A write past the limit then fails with EFBIG instead of killing the process.
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            if libc::setrlimit(libc::RLIMIT_FSIZE, &rlimit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let run = command.output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "{stderr}");
    assert!(
        stderr.contains("writing") && stderr.contains("results.json"),
        "{stderr}"
    );
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        results["_checkpoint"]["records"].as_array().unwrap().len(),
        1
    );
    assert!(
        !tmp.path().join("results.tmp").exists(),
        "the temporary file is removed"
    );

    let mut resume = eval(&out, "3");
    assert!(resume.arg("--resume").output().unwrap().status.success());
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(
        results["_checkpoint"]["records"].as_array().unwrap().len(),
        3
    );
}

#[test]
fn collect_selects_route_ids_across_every_route_set() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("data");
    // A second route set on the same town whose one route has an id train-small lacks.
    let file = tmp.path().join("extra.xml");
    let drawn = sim_bridge(&[
        "routes",
        "random",
        "--map",
        "ssr_train_small",
        "--count",
        "1",
        "--length",
        "60,120",
        "--out",
        file.to_str().unwrap(),
    ]);
    assert!(
        drawn.status.success(),
        "{}",
        String::from_utf8_lossy(&drawn.stderr)
    );
    let text = std::fs::read_to_string(&file).unwrap();
    std::fs::write(&file, text.replace(r#"id="0""#, r#"id="only-here""#)).unwrap();
    let routes = format!("train-small,{}", file.display());
    let collect = |ids: &str| {
        sim_bridge(&[
            "collect",
            "--routes",
            &routes,
            "--map",
            "ssr_train_small",
            "--route-ids",
            ids,
            "--vehicles",
            "0",
            "--no-scenarios",
            "--quiet",
            "--out",
            out.to_str().unwrap(),
        ])
    };
    // The id is only in the file: train-small holding none of the ids is no error.
    let run = collect("only-here");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let episodes: Vec<String> = std::fs::read_dir(out.join("episodes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(episodes.len(), 1, "{episodes:?}");
    assert!(episodes[0].contains("extra"), "{episodes:?}");
    // An id in no set is.
    let run = collect("no-such-id");
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("no-such-id not in train-small"), "{stderr}");
}

#[test]
fn a_step_log_keeps_the_lights_around_the_ego_as_ground_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let logs = tmp.path().join("logs");
    let run = sim_bridge(&[
        "eval",
        "--routes",
        "town05-short-style",
        "--route-ids",
        "0",
        "--timeout",
        "5",
        "--quiet",
        "--out",
        tmp.path().join("results.json").to_str().unwrap(),
        "--record",
        logs.to_str().unwrap(),
    ]);
    assert_succeeded(&run);
    let log = std::fs::read_dir(&logs).unwrap().next().unwrap().unwrap();
    let log = sim_bridge::replay::log::read_log(&log.path()).unwrap();
    let mut seen = 0;
    for tick in &log.ticks {
        let ego = tick.ego.unwrap();
        for light in &tick.lights {
            let distance = (light.head_x - ego.x).hypot(light.head_y - ego.y);
            assert!(distance <= 60.0, "{light:?} is {distance:.1} m away");
            assert!(["green", "yellow", "red"].contains(&light.state.as_str()));
            seen += 1;
        }
    }
    assert!(
        seen > 0,
        "the route starts among the town's signalised junctions"
    );
}

/// The expert's 5-second runs of Town05-style short routes `ids` (e.g. "0,1"), written to `out`.
fn expert_results(out: &std::path::Path, ids: &str) -> std::path::PathBuf {
    let run = sim_bridge(&[
        "eval",
        "--routes",
        "town05-short-style",
        "--route-ids",
        ids,
        "--timeout",
        "5",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_succeeded(&run);
    out.to_path_buf()
}

#[test]
fn results_compare_pairs_two_agents_runs_and_says_when_they_share_none() {
    let tmp = tempfile::tempdir().unwrap();
    let eval = |name: &str, ids: &str| expert_results(&tmp.path().join(name), ids);
    let (first, second, other) = (
        eval("a.json", "0,1"),
        eval("b.json", "1,0"),
        eval("c.json", "2"),
    );
    let json = tmp.path().join("comparison.json");
    let run = sim_bridge(&[
        "results",
        "compare",
        first.to_str().unwrap(),
        second.to_str().unwrap(),
        "--out",
        json.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success() && stdout.contains("2 runs paired"),
        "{stdout}"
    );
    // A reader that stops early (`| head`) ends the printing, not the command with a panic.
    let mut closed = Command::new(env!("CARGO_BIN_EXE_sim-bridge"))
        .args(["results", "compare"])
        .args([&first, &second])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(closed.stdout.take());
    let run = closed.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success() && stderr.is_empty(), "{stderr}");
    let comparison: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // The same expert on the same runs: no difference, and one that cannot be told apart.
    assert_eq!(comparison["ds"]["difference"], 0.0);
    assert_eq!(comparison["same"], 2);
    let run = sim_bridge(&[
        "results",
        "compare",
        first.to_str().unwrap(),
        other.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && stderr.contains("share no run"),
        "{stderr}"
    );
}

#[test]
fn results_summary_tabulates_files_side_by_side_and_names_a_bad_one() {
    let tmp = tempfile::tempdir().unwrap();
    let eval = |name: &str, ids: &str| expert_results(&tmp.path().join(name), ids);
    let (one, two) = (eval("one.json", "0"), eval("two.json", "1,2"));
    let run = sim_bridge(&[
        "results",
        "summary",
        one.to_str().unwrap(),
        two.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{stdout}");
    let runs_of = |name: &str| {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(name))
            .unwrap_or_else(|| panic!("{stdout}"));
        line[name.len()..]
            .split_whitespace()
            .next()
            .unwrap()
            .to_string()
    };
    assert_eq!(runs_of(one.to_str().unwrap()), "1");
    assert_eq!(runs_of(two.to_str().unwrap()), "2");
    assert_eq!(runs_of("all (2 files)"), "3");

    let broken = tmp.path().join("broken.json");
    std::fs::write(&broken, "{\"not\": \"results\"}").unwrap();
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    for (path, says) in [(&broken, "broken.json"), (&empty, "holds no results files")] {
        let run = sim_bridge(&[
            "results",
            "summary",
            one.to_str().unwrap(),
            path.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success() && stderr.contains(says), "{stderr}");
    }
}
