//! The `ssr-agent` binary: configs, checkpoint inspection errors, and a bench smoke run.

mod common;

use std::process::Command;

fn ssr_agent(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_ssr-agent"))
        .args(args)
        .output()
        .expect("runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn config_prints_presets_that_parse_back() {
    let (ok, stdout, _) = ssr_agent(&["config", "paper"]);
    assert!(ok);
    let config: ssr_agent::model::config::SsrConfig = serde_json::from_str(&stdout).unwrap();
    assert_eq!(config, ssr_agent::model::config::SsrConfig::paper());
    let (ok, _, stderr) = ssr_agent(&["config", "huge"]);
    assert!(!ok && stderr.contains("cpu-default"), "{stderr}");
}

#[test]
fn inspect_reports_bad_files() {
    let path = std::env::temp_dir().join(format!("ssr-cli-{}.safetensors", std::process::id()));
    std::fs::write(&path, [1u8, 0, 0]).unwrap();
    let (ok, _, stderr) = ssr_agent(&["inspect", path.to_str().unwrap()]);
    assert!(!ok && stderr.contains("not a safetensors file"), "{stderr}");
}

#[test]
fn bench_runs_a_small_config_and_prints_json() {
    let path = std::env::temp_dir().join(format!("ssr-cli-tiny-{}.json", std::process::id()));
    std::fs::write(
        &path,
        serde_json::to_string(&common::tiny_config()).unwrap(),
    )
    .unwrap();
    let (ok, stdout, stderr) = ssr_agent(&[
        "bench",
        "--config",
        path.to_str().unwrap(),
        "--iterations",
        "1",
        "--warmup",
        "0",
        "--json",
        "--train",
        "--train-batch",
        "2",
    ]);
    assert!(ok, "{stderr}");
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    assert!(lines[0]["results"]["forward_ms"].as_f64().unwrap() > 0.0);
    assert!(
        lines[0]["results"]["policy_step_900x256_ms"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert!(lines[1]["results"]["train_step_ms"].as_f64().unwrap() > 0.0);
    let (ok, _, stderr) = ssr_agent(&["bench", "--config", "/no/such/file.json"]);
    assert!(!ok && stderr.contains("--config"), "{stderr}");
}
