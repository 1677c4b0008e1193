//! End to end: sim-bridge's commands against a real `ssr-agent serve` process (random
//! cpu-default weights) on an ephemeral loopback port, or the one `--agent local` starts: eval,
//! render, a server lost mid-route and the resume, load and replay.

use std::process::Command;
use std::time::Duration;

use ssrdrive_tests::{Server, binary};

fn read_results(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The stdout of a run that must have succeeded (its stderr in the failure message).
fn succeeded(run: std::process::Output) -> String {
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    String::from_utf8_lossy(&run.stdout).into_owned()
}

/// `sim-bridge eval` of the bundled short routes without traffic, quiet, results to `out`;
/// `flags` add to or narrow it (`--limit`, `--timeout`, ...).
fn eval_command(agent: &str, flags: &[&str], out: &std::path::Path) -> Command {
    let mut command = Command::new(binary("sim-bridge"));
    command
        .args(["eval", "--agent", agent, "--routes", "town05-short-style"])
        .args(["--vehicles", "0", "--quiet"])
        .args(flags)
        .arg("--out")
        .arg(out);
    command
}

#[test]
fn eval_scores_a_route_through_the_server() {
    let server = Server::start(&[]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = dir.join("results.json");
    let agent = format!("grpc://{}", server.address);
    let run = eval_command(&agent, &["--limit", "1", "--timeout", "2"], &out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("agent: ssr (cpu-default)"), "{stderr}");
    let results = read_results(&out);
    let records = results["_checkpoint"]["records"].as_array().unwrap();
    assert_eq!(records.len(), 1);
    assert!((records[0]["meta"]["duration_game"].as_f64().unwrap() - 2.0).abs() < 0.1);
    // One step per 20 Hz tick went through the server, and the episode was ended.
    let steps = server.metric(r#"ssr_requests_total{method="Step",code="OK"}"#);
    assert!((40.0..=42.0).contains(&steps), "{steps} steps");
    assert_eq!(server.metric("ssr_active_episodes"), 0.0);
}

#[test]
fn local_agent_starts_its_own_server() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = dir.join("results.json");
    let run = eval_command("local", &["--limit", "1", "--timeout", "1"], &out)
        .env("SSR_AGENT_BIN", binary("ssr-agent"))
        .env("SSR_AGENT_UNTRAINED_CONFIG", "cpu-default")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(
        stderr.contains("agent: ssr (cpu-default) at grpc://127.0.0.1:"),
        "{stderr}"
    );
    assert_eq!(
        read_results(&out)["_checkpoint"]["records"]
            .as_array()
            .unwrap()
            .len(),
        1
    );

    // A local server that cannot load its checkpoint refuses to start, and eval says why.
    let run = eval_command("local", &["--limit", "1"], &out)
        .env("SSR_AGENT_BIN", binary("ssr-agent"))
        .env_remove("SSR_AGENT_UNTRAINED_CONFIG")
        .env("SSR_AGENT_CHECKPOINT", "/no/such/model.safetensors")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("/no/such/model.safetensors"), "{stderr}");
    assert!(stderr.contains("did not report its port"), "{stderr}");
}

/// A local server ends with the `sim-bridge` that started it, even one killed with SIGKILL
/// (which runs no clean-up): it watches the standard input its parent holds open.
#[cfg(target_os = "linux")]
#[test]
fn a_killed_sim_bridge_leaves_no_local_server_running() {
    let tmp = tempfile::tempdir().unwrap();
    let mut eval = eval_command("local", &["--limit", "1"], &tmp.path().join("results.json"))
        .env("SSR_AGENT_BIN", binary("ssr-agent"))
        .env("SSR_AGENT_UNTRAINED_CONFIG", "cpu-default")
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // The server is eval's child process (Linux lists children in /proc).
    let children = format!("/proc/{0}/task/{0}/children", eval.id());
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let server: u32 = loop {
        let listed = std::fs::read_to_string(&children).unwrap_or_default();
        if let Some(pid) = listed.split_whitespace().next() {
            break pid.parse().unwrap();
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no server within 60 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let server_alive = || {
        std::fs::read_to_string(format!("/proc/{server}/stat"))
            // A zombie (state Z) has exited and waits for its parent; init reaps it.
            .is_ok_and(|stat| {
                stat.rsplit(')')
                    .next()
                    .is_some_and(|rest| !rest.trim_start().starts_with('Z'))
            })
    };
    assert!(server_alive());
    eval.kill().unwrap();
    eval.wait().unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while server_alive() {
        assert!(
            std::time::Instant::now() < deadline,
            "the local server {server} still runs 30 s after its sim-bridge was killed"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_local_agent_drives_runs_at_once_as_one_at_a_time() {
    // The bundled network, two routes for 3 s each: with two runs at once, each run's controls
    // are the ones it gets alone, bit for bit (batched kernels round differently).
    let tmp = tempfile::tempdir().unwrap();
    let controls = |jobs: &str| {
        let dir = tmp.path().join(format!("jobs-{jobs}"));
        let record = dir.to_str().unwrap();
        let flags = [
            "--limit",
            "2",
            "--timeout",
            "3",
            "--jobs",
            jobs,
            "--record",
            record,
        ];
        succeeded(
            eval_command("local", &flags, &dir.join("results.json"))
                .env("SSR_AGENT_BIN", binary("ssr-agent"))
                .env_remove("SSR_AGENT_UNTRAINED_CONFIG")
                .env_remove("SSR_AGENT_CHECKPOINT")
                .env_remove("SSR_AGENT_MAX_BATCH")
                .output()
                .unwrap(),
        );
        let mut logs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|entry| entry.unwrap().path())
            .filter(|path| path.extension().is_some_and(|e| e == "ssrlog"))
            .collect();
        logs.sort();
        assert_eq!(logs.len(), 2, "{logs:?}");
        logs.iter()
            .map(|path| {
                let log = sim_bridge::replay::log::read_log(path).unwrap();
                log.ticks
                    .iter()
                    .map(|tick| {
                        let c = tick.control.unwrap();
                        [c.steer, c.throttle, c.brake].map(f64::to_bits)
                    })
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    let alone = controls("1");
    assert!(alone.iter().all(|run| run.len() >= 59), "3 s at 20 Hz");
    assert_eq!(controls("2"), alone);
}

#[test]
fn render_puts_a_served_agents_token_attention_and_occupancy_beside_the_views() {
    let server = Server::start(&[]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    let render = |agent: &str| {
        Command::new(binary("sim-bridge"))
            .args(["render", "--agent", agent, "--routes", "town05-short-style"])
            .args(["--limit", "1", "--vehicles", "0", "--timeout", "1"])
            .args(["--every", "10", "--topdown", "192", "--out"])
            .arg(out)
            .output()
            .unwrap()
    };
    let stdout = succeeded(render(&format!("grpc://{}", server.address)));
    assert!(stdout.contains("route 0: 3 frames"), "{stdout}");
    let route = out.join("route_0");
    // The camera (the server's 320x96 rig, enlarged twice to the panels' 192 px), the top-down
    // view, the 16 token maps and the occupancy, for each rendered tick, beside the raw camera
    // frames.
    for tick in ["000000", "000010", "000020"] {
        assert!(route.join(format!("{tick}_rgb_front.png")).is_file());
        let view = std::fs::read(route.join(format!("{tick}_view.png"))).unwrap();
        let size = |at: usize| u32::from_be_bytes(view[at..at + 4].try_into().unwrap());
        assert_eq!((size(16), size(20)), (640 + 3 * 192, 192), "tick {tick}");
    }
    assert!(route.join("run.png").is_file());

    let refused = render("nowhere");
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("--agent nowhere: unknown agent"),
        "{stderr}"
    );
}

#[test]
fn a_server_lost_mid_route_crashes_the_route_and_resume_finishes_the_run() {
    let server = Server::start(&[]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = dir.join("results.json");
    let agent = format!("grpc://{}", server.address);
    let flags = ["--limit", "2", "--timeout", "600", "--call-timeout", "2"];
    let eval = eval_command(&agent, &flags, &out)
        .args(["--ready-timeout", "1"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Lost once the first route is under way: its first steps were answered, and it is too
    // early for it to have ended by itself (a fixed wait let it deviate and end first).
    let steps = r#"ssr_requests_total{method="Step",code="OK"}"#;
    let answered = server.wait_for_metric(steps, |n| n >= 3.0, Duration::from_secs(60));
    assert!(answered >= 3.0, "the route never started: {answered} steps");
    drop(server);
    let run = eval.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "{stderr}");
    assert!(stderr.contains("the agent crashed"), "{stderr}");
    let results = read_results(&out);
    let records = results["_checkpoint"]["records"].as_array().unwrap();
    assert_eq!(records.len(), 2, "both runs are recorded");
    for record in records {
        assert_eq!(record["status"], "Failed - Agent crashed");
    }

    // With a server back, --resume drives the crashed runs again (short: --timeout is not part
    // of the plan a resume checks).
    let server = Server::start(&[]);
    let agent = format!("grpc://{}", server.address);
    let resumed = ["--limit", "2", "--timeout", "3", "--resume"];
    succeeded(eval_command(&agent, &resumed, &out).output().unwrap());
    let results = read_results(&out);
    let records = results["_checkpoint"]["records"].as_array().unwrap();
    assert_eq!(records.len(), 2);
    for record in records {
        assert_ne!(record["status"], "Failed - Agent crashed", "{record}");
    }
}

#[test]
fn load_reports_every_step_and_the_server_memory() {
    let server = Server::start(&[]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = dir.join("load.json");
    let run = Command::new(binary("sim-bridge"))
        .args(["load", "--agent", &format!("grpc://{}", server.address)])
        .args(["--metrics", &format!("http://{}/metrics", server.metrics)])
        .args([
            "--episodes",
            "2",
            "--rate",
            "5",
            "--duration",
            "2",
            "--frames",
            "4",
        ])
        .args([
            "--routes",
            "town05-short-style",
            "--vehicles",
            "0",
            "--quiet",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = succeeded(run);
    // 2 episodes x 5 Hz x 2 s = 20 steps due: each one answered OK, or (on a machine too busy
    // to keep up) reported as behind schedule, never lost.
    let report = read_results(&out);
    let count = report["report"]["count"].as_u64().unwrap();
    let behind = report["report"]["behind_schedule"].as_u64().unwrap();
    assert_eq!(count + behind, 20, "{stdout}");
    assert!(
        stdout.contains(&format!("status codes: Ok {count}\n")),
        "{stdout}"
    );
    assert!(report["report"]["latency_ms"]["p99"].as_f64().unwrap() > 0.0);
    let memory = report["server_rss_bytes"].as_array().unwrap();
    assert!(memory.len() >= 2, "{memory:?}");
    assert!(memory.last().unwrap()["bytes"].as_u64().unwrap() > 10 << 20);
    let steps = server.metric(r#"ssr_requests_total{method="Step",code="OK"}"#);
    assert_eq!(steps, count as f64);
}

#[test]
fn a_recorded_run_replays_without_drift() {
    let server = Server::start(&[]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let logs = dir.join("logs");
    let agent = format!("grpc://{}", server.address);
    let flags = [
        "--limit",
        "1",
        "--timeout",
        "1.5",
        "--record",
        logs.to_str().unwrap(),
    ];
    let run = eval_command(&agent, &flags, &dir.join("results.json"))
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let out = dir.join("replay.json");
    let ticks = dir.join("ticks.jsonl");
    let run = Command::new(binary("sim-bridge"))
        .args([
            "replay",
            "--agent",
            &format!("grpc://{}", server.address),
            "--out",
        ])
        .arg(&out)
        .arg("--ticks")
        .arg(&ticks)
        .arg(&logs)
        .output()
        .unwrap();
    let stdout = succeeded(run);
    assert!(stdout.contains("open loop at 1 s: L2"), "{stdout}");
    let reports = read_results(&out);
    let report = &reports[0];
    assert_eq!(report["ticks"], 31);
    assert_eq!(report["codes"]["Ok"], 31);
    // The same server and weights answer the same frames the same way.
    for field in [
        "steer_diff",
        "throttle_diff",
        "brake_diff",
        "trajectory_drift_m",
    ] {
        assert_eq!(report[field]["max"], 0.0, "{field}: {report}");
    }
    assert!(report["open_loop"][0]["samples"].as_u64().unwrap() > 0);
    // Per tick, what the network believed: cpu-default has a hazard head and no light head.
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(&ticks)
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect();
    assert_eq!(lines.len(), 31);
    for (i, line) in lines.iter().enumerate() {
        assert_eq!(line["frame"], i as u64, "{line}");
        assert_eq!(line["control"], line["recorded"], "{line}");
        assert!(line["log"].as_str().unwrap().ends_with(".ssrlog"), "{line}");
        let hazard: Vec<f64> = serde_json::from_value(line["hazard"].clone()).unwrap();
        assert_eq!(hazard.len(), 5);
        assert!((hazard.iter().sum::<f64>() - 1.0).abs() < 1e-3, "{line}");
        assert!(line["light"].is_null(), "{line}");
        assert!(line["lights"].is_array(), "{line}");
        // The fusion mixes the two sources' steers: the served one lies between them.
        let steer = |field: &str| line[field][0].as_f64().unwrap();
        let (plan, branch) = (steer("trajectory_control"), steer("branch_control"));
        let fused = steer("control");
        assert!(
            plan.min(branch) - 1e-6 <= fused && fused <= plan.max(branch) + 1e-6,
            "{line}"
        );
    }
}
