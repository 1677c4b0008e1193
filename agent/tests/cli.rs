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

#[test]
fn serve_layers_file_env_and_flags_and_refuses_bad_settings() {
    let serve = |env: &[(&str, &str)], args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_ssr-agent"))
            .arg("serve")
            .args(["--listen", "127.0.0.1:0"])
            .args(args)
            .env_remove("SSR_AGENT_CHECKPOINT")
            .env_remove("SSR_AGENT_UNTRAINED_CONFIG")
            .envs(env.iter().copied())
            .output()
            .expect("runs");
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let file = std::env::temp_dir().join(format!("ssr-cli-serve-{}.toml", std::process::id()));
    std::fs::write(&file, "max_batch = 0\n").unwrap();
    let file = file.to_str().unwrap();

    // The file's bad value is caught and named...
    let stderr = serve(&[], &["--config", file]);
    assert!(
        stderr.contains("max_batch = 0: must be in 1..=256"),
        "{stderr}"
    );
    // ...unless the environment overrides it (then the next problem is the missing model)...
    let stderr = serve(&[("SSR_AGENT_MAX_BATCH", "3")], &["--config", file]);
    assert!(stderr.contains("no model: pass --checkpoint"), "{stderr}");
    // ...and a flag beats the environment.
    let stderr = serve(&[("SSR_AGENT_MAX_BATCH", "3")], &["--max-batch", "0"]);
    assert!(stderr.contains("max_batch = 0"), "{stderr}");
    let stderr = serve(&[], &["--config", "/no/such/file.toml"]);
    assert!(stderr.contains("/no/such/file.toml"), "{stderr}");
    let stderr = serve(&[("SSR_AGENT_METRICS_LISTEN", "nowhere")], &[]);
    assert!(stderr.contains("expected HOST:PORT or `off`"), "{stderr}");
}
