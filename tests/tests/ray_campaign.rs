//! The Ray campaign driver (`sim-bridge/campaign/ray_campaign.py`) on a Ray instance it starts
//! on this machine: a campaign fanned out as one task per share merges into the file a single
//! `sim-bridge eval` writes, with the expert and with the bundled agent, even when a Ray worker
//! is killed in the middle of a share (Ray retries the task, which resumes from the part file).
//! Needs the `ray` package (`pip install -r tests/requirements.txt`, part of the README's test
//! command); SSRDRIVE_SKIP_PYTHON=1 skips it on a machine without Python.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;
use ssrdrive_tests::{binary, python_skipped};

fn driver() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim-bridge/campaign/ray_campaign.py")
}

fn sim_bridge(args: &[&str]) -> Output {
    let run = Command::new(binary("sim-bridge"))
        .args(args)
        .output()
        .expect("sim-bridge runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    run
}

/// `sim-bridge eval ARGS --out OUT`.
fn eval(args: &[&str], out: &Path) {
    let mut args = [&["eval"], args].concat();
    args.extend(["--out", out.to_str().unwrap()]);
    sim_bridge(&args);
}

/// The driver on `shares` shares of `eval_args`, parts and results in `out`.
fn campaign(out: &Path, shares: usize, eval_args: &[&str]) -> Child {
    Command::new("python3")
        .arg(driver())
        .args([
            "--out",
            out.to_str().unwrap(),
            "--shards",
            &shares.to_string(),
            "--",
        ])
        .args(eval_args)
        .env("SIM_BRIDGE", binary("sim-bridge"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs")
}

fn finished(child: Child) -> String {
    let run = child.wait_with_output().expect("the driver ends");
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "the campaign failed:\n{log}");
    log
}

/// A results file without its wall-clock durations (the one thing processes differ in).
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
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    strip(serde_json::from_str(&text).unwrap())
}

/// The pid of a running process whose command line holds every one of `parts`.
fn process_with(parts: &[&str]) -> Option<u32> {
    std::fs::read_dir("/proc")
        .ok()?
        .flatten()
        .find_map(|entry| {
            let pid: u32 = entry.file_name().to_str()?.parse().ok()?;
            let cmdline = std::fs::read(entry.path().join("cmdline")).ok()?;
            let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
            parts.iter().all(|p| cmdline.contains(p)).then_some(pid)
        })
}

fn parent_of(pid: u32) -> u32 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).expect("the process lives");
    // "pid (comm) state ppid ...": the fields after the command name's closing parenthesis.
    let after = &stat[stat.rfind(')').expect("stat has a comm") + 2..];
    after.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn a_ray_campaign_merges_into_the_single_process_file_even_when_a_worker_dies() {
    if python_skipped("the Ray campaign test") {
        return;
    }
    let probe = Command::new("python3")
        .args(["-c", "import ray"])
        .output()
        .expect("python3 runs (set SSRDRIVE_SKIP_PYTHON=1 on a machine without it)");
    assert!(
        probe.status.success(),
        "ray is missing: pip install -r tests/requirements.txt (or set SSRDRIVE_SKIP_PYTHON=1)"
    );
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();

    // The expert, four shares.
    let expert = [
        "--routes",
        "train-small",
        "--limit",
        "6",
        "--repetitions",
        "2",
        "--quiet",
    ];
    let single = dir.join("expert.json");
    eval(&expert, &single);
    let out = dir.join("expert-campaign");
    let log = finished(campaign(&out, 4, &expert));
    assert!(log.contains("[4/4]"), "{log}");
    assert_eq!(
        without_wall_time(&out.join("results.json")),
        without_wall_time(&single)
    );

    // The bundled agent, three shares; the Ray worker driving share 1 is killed once its
    // evaluation has started.
    let agent = [
        "--routes",
        "town05-short-style",
        "--limit",
        "3",
        "--repetitions",
        "2",
        "--timeout",
        "15",
        "--agent",
        "local",
        "--quiet",
    ];
    let single = dir.join("agent.json");
    eval(&agent, &single);
    let out = dir.join("agent-campaign");
    let child = campaign(&out, 3, &agent);
    let out_arg = out.to_str().unwrap().to_string();
    let started = Instant::now();
    let eval = loop {
        if let Some(pid) = process_with(&["1/3", &out_arg, "eval"]) {
            break pid;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "share 1 never started"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    // Let it score nothing or something; either way its worker dies mid-share.
    std::thread::sleep(Duration::from_secs(2));
    let worker = parent_of(eval);
    let kill = Command::new("kill")
        .args(["-9", &worker.to_string()])
        .status()
        .unwrap();
    assert!(kill.success(), "killing the Ray worker {worker}");
    let log = finished(child);
    assert!(log.contains("[3/3]"), "{log}");
    assert!(
        log.contains("share 1: 2 runs") && log.contains("started 2 times by Ray"),
        "Ray retried share 1 once:\n{log}"
    );
    assert_eq!(
        without_wall_time(&out.join("results.json")),
        without_wall_time(&single)
    );
}
