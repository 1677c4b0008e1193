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
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.safetensors");
    std::fs::write(&path, [1u8, 0, 0]).unwrap();
    let (ok, _, stderr) = ssr_agent(&["inspect", path.to_str().unwrap()]);
    assert!(!ok && stderr.contains("not a safetensors file"), "{stderr}");
}

#[test]
fn control_prints_and_changes_only_the_named_settings() {
    use ssr_agent::control::{ControlConfig, TurnLead};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.safetensors");
    let config = common::tiny_config();
    let model = config.init(&burn::tensor::Device::flex());
    ssr_agent::checkpoint::save(&model, &config, &[], &path).unwrap();
    let path = path.to_str().unwrap();
    let out = dir.path().join("changed.safetensors");
    let out = out.to_str().unwrap();
    let printed = |checkpoint: &str| {
        let (ok, stdout, stderr) = ssr_agent(&["control", checkpoint]);
        assert!(ok, "{stderr}");
        serde_json::from_str::<ControlConfig>(&stdout).unwrap()
    };
    assert_eq!(printed(path), ControlConfig::default());
    // The history mode is not a controller setting, but what it is is said beside them: a
    // checkpoint that names none is served on the recursion it was validated on.
    let (_, _, stderr) = ssr_agent(&["control", path]);
    assert!(
        stderr.contains("served with its history as: recursive"),
        "{stderr}"
    );

    let patch = r#"{"safety": {"enabled": true}, "vehicle": {"max_wheel_angle": 70},
        "turn_lead": "plan"}"#;
    let (ok, _, stderr) = ssr_agent(&["control", path, "--set", patch, "--out", out]);
    assert!(ok, "{stderr}");
    let mut expected = ControlConfig::default();
    expected.safety.enabled = true;
    expected.vehicle.max_wheel_angle = 70.0;
    expected.turn_lead = TurnLead::Plan;
    assert_eq!(printed(out), expected);
    // From a file, over the changed copy: the earlier changes stay.
    let file = dir.path().join("patch.json");
    std::fs::write(&file, r#"{"unstick": {"after_s": 30}}"#).unwrap();
    let file = file.to_str().unwrap();
    let (ok, _, stderr) = ssr_agent(&["control", out, "--set", file, "--out", out]);
    assert!(ok, "{stderr}");
    expected.unstick.after_s = 30.0;
    assert_eq!(printed(out), expected);

    // Refusals name the problem and write nothing.
    let refused = |set: &str, needle: &str| {
        let (ok, _, stderr) = ssr_agent(&["control", out, "--set", set, "--out", path]);
        assert!(!ok && stderr.contains(needle), "{set}: {stderr}");
        assert_eq!(printed(path), ControlConfig::default(), "{set}");
    };
    refused(
        r#"{"safety": {"enabeld": true}}"#,
        "unknown controller setting 'safety.enabeld'",
    );
    refused(r#"{"vehicle": 3}"#, "'vehicle' is a group of settings");
    refused(r#"{"alpha": 2}"#, "alpha = 2");
    refused(r#"{"alpha": "high"}"#, "changed controller settings");
    refused(r#"{"turn_lead": "sideways"}"#, "unknown variant `sideways`");
    refused(r#"{"alpha": 0.5"#, "--set is not JSON");
    refused("/no/such/patch.json", "/no/such/patch.json");
    refused("not json", "neither a JSON object nor a readable file");
    let (ok, _, stderr) = ssr_agent(&["control", path, "--set", "{}"]);
    assert!(!ok && stderr.contains("--out"), "{stderr}");
}

#[test]
fn blend_writes_a_checkpoint_and_names_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let config = common::tiny_config();
    let device = burn::tensor::Device::flex();
    let [a, b, out] = ["a", "b", "mixed"].map(|name| {
        dir.path()
            .join(format!("{name}.safetensors"))
            .to_str()
            .unwrap()
            .to_string()
    });
    for path in [&a, &b] {
        ssr_agent::checkpoint::save(&config.init(&device), &config, &[], path.as_ref()).unwrap();
    }
    let (ok, _, stderr) = ssr_agent(&["blend", &a, &b, "--weight", "0.5", "--out", &out]);
    assert!(ok && stderr.contains("0.5 x"), "{stderr}");
    let (ok, stdout, stderr) = ssr_agent(&["inspect", &out]);
    assert!(
        ok && stdout.contains("blend: {\"from\""),
        "{stdout}{stderr}"
    );
    let (ok, _, stderr) = ssr_agent(&["blend", &a, &b, "--weight", "2", "--out", &out]);
    assert!(
        !ok && stderr.contains("must be in 0..=1, not 2"),
        "{stderr}"
    );
    let (ok, _, stderr) = ssr_agent(&["blend", &a, &b, "--out", &out]);
    assert!(!ok && stderr.contains("--weight"), "{stderr}");
}

#[test]
fn bench_runs_a_small_config_and_prints_json() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny.json");
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
    // Milliseconds, not seconds or microseconds: a tiny network's forward pass is well under a
    // second, and a training step (forward and backward at batch 2) takes longer than it.
    let ms = |line: usize, key: &str| lines[line]["results"][key].as_f64().unwrap();
    let forward = ms(0, "forward_ms");
    assert!(forward > 0.0 && forward < 1000.0, "{forward}");
    let step = ms(0, "policy_step_900x256_ms");
    assert!(step > 0.0 && step < 10_000.0, "{step}");
    let train = ms(1, "train_step_ms");
    assert!(train > forward && train < 60_000.0, "{train} vs {forward}");
    let (ok, _, stderr) = ssr_agent(&["bench", "--config", "/no/such/file.json"]);
    assert!(!ok && stderr.contains("--config"), "{stderr}");

    // Another rig: a step takes a frame from each camera, and its rows say it is not TCP's.
    let rig = dir.path().join("front-right.json");
    let camera = |id: &str, yaw: f32| {
        serde_json::json!({"id": id, "x": -1.5, "y": 0.0, "z": 2.0, "roll": 0.0, "pitch": 0.0,
            "yaw": yaw, "width": 64, "height": 32, "fov": 100.0})
    };
    std::fs::write(
        &rig,
        serde_json::json!([camera("front", 0.0), camera("right", 90.0)]).to_string(),
    )
    .unwrap();
    let (ok, stdout, stderr) = ssr_agent(&[
        "bench",
        "--config",
        path.to_str().unwrap(),
        "--rig",
        rig.to_str().unwrap(),
        "--iterations",
        "1",
        "--warmup",
        "0",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let line: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let step = line["results"]["policy_step_rig_link_ms"].as_f64().unwrap();
    assert!(step > 0.0 && step < 10_000.0, "{step}");
    assert!(line["results"].get("policy_step_900x256_ms").is_none());
    let (ok, _, stderr) = ssr_agent(&["bench", "--rig", "/no/such/rig.json"]);
    assert!(!ok && stderr.contains("--rig"), "{stderr}");
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
        assert_ne!(
            out.status.code(),
            Some(101),
            "a refused setting is not a panic"
        );
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("serve.toml");
    std::fs::write(&file, "max_batch = 0\n").unwrap();
    let file = file.to_str().unwrap();

    // The file's bad value is caught and named...
    let stderr = serve(&[], &["--config", file]);
    assert!(
        stderr.contains("max_batch = 0: must be in 1..=256"),
        "{stderr}"
    );
    // ...unless the environment overrides it (then the next problem is the missing model)...
    let missing = ("SSR_AGENT_CHECKPOINT", "/no/such/model.safetensors");
    let stderr = serve(
        &[("SSR_AGENT_MAX_BATCH", "3"), missing],
        &["--config", file],
    );
    assert!(stderr.contains("/no/such/model.safetensors"), "{stderr}");
    // ...and a flag beats the environment.
    let stderr = serve(&[("SSR_AGENT_MAX_BATCH", "3")], &["--max-batch", "0"]);
    assert!(stderr.contains("max_batch = 0"), "{stderr}");
    let stderr = serve(&[], &["--idle-timeout-s", "1e308"]);
    assert!(
        stderr.contains("idle_timeout_s = 1e308: must be in"),
        "{stderr}"
    );
    let stderr = serve(&[("SSR_AGENT_DRAIN_TIMEOUT_S", "1e308")], &[]);
    assert!(stderr.contains("drain_timeout_s = 1e308"), "{stderr}");
    let stderr = serve(&[], &["--config", "/no/such/file.toml"]);
    assert!(stderr.contains("/no/such/file.toml"), "{stderr}");
    let stderr = serve(&[("SSR_AGENT_METRICS_LISTEN", "nowhere")], &[]);
    assert!(
        stderr.contains("expected IP:PORT or HOST:PORT") && stderr.contains("`off`"),
        "{stderr}"
    );
    // A host name is an address (the README's examples say `localhost`): the next problem is
    // the missing model, not the address.
    let stderr = serve(
        &[("SSR_AGENT_CHECKPOINT", "/no/such/model.safetensors")],
        &["--metrics-listen", "localhost:0"],
    );
    assert!(stderr.contains("/no/such/model.safetensors"), "{stderr}");
    let stderr = serve(&[], &["--metrics-listen", "localhost"]);
    assert!(stderr.contains("expected IP:PORT or HOST:PORT"), "{stderr}");
    // The motion rule needs a network with the motion head; the bundled one has none.
    let stderr = serve(&[], &["--safety-motion", "true"]);
    assert!(
        stderr.contains("motion head") && stderr.contains("--safety-motion false"),
        "{stderr}"
    );
    let stderr = serve(&[("SSR_AGENT_BACKEND", "tpu")], &[]);
    assert!(stderr.contains("[possible values: cpu, wgpu]"), "{stderr}");
    if cfg!(not(feature = "wgpu")) {
        let stderr = serve(&[], &["--backend", "wgpu"]);
        assert!(
            stderr.contains("rebuild with `--features wgpu`"),
            "{stderr}"
        );
    }
}

#[test]
fn train_runs_ablations_from_flags_and_names_bad_data() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    common::fixture::write_fixture_dataset(&data);
    let model = dir.join("tiny.json");
    std::fs::write(
        &model,
        serde_json::to_string(&common::tiny_config()).unwrap(),
    )
    .unwrap();
    let out = dir.join("run");
    let (data, model, out_arg) = (
        data.to_str().unwrap(),
        model.to_str().unwrap(),
        out.to_str().unwrap(),
    );
    let train = |extra: &[&str]| {
        let mut args = vec![
            "train", "--data", data, "--out", out_arg, "--model", model, "--quiet",
        ];
        args.extend_from_slice(extra);
        ssr_agent(&args)
    };
    let (ok, stdout, stderr) =
        train(&["--steps", "3", "--batch-size", "4", "--no-stl", "--no-ffp"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("3 steps done (3 in this run"), "{stdout}");
    assert!(stdout.contains("validation at step 3"), "{stdout}");
    let info = ssr_agent::checkpoint::inspect(&out.join("final.safetensors")).unwrap();
    assert_eq!(info.config.name, "tiny-no-stl-no-ffp");
    assert!(info.config.tokens.dense_bev);
    assert!(info.metadata["training"].contains("\"future_bev\":false"));

    // Resuming a finished run trains nothing more and says so.
    let (ok, stdout, stderr) = train(&["--resume"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("3 steps done (0 in this run"), "{stdout}");

    // The command-only gate, in a run of its own from the first run's perception.
    let gated = dir.join("gated");
    let first = out.join("final.safetensors");
    let (ok, _, stderr) = ssr_agent(&[
        "train",
        "--data",
        data,
        "--out",
        gated.to_str().unwrap(),
        "--model",
        model,
        "--quiet",
        "--steps",
        "1",
        "--batch-size",
        "2",
        "--gate-command-only",
        "--init-perception",
        first.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let info = ssr_agent::checkpoint::inspect(&gated.join("final.safetensors")).unwrap();
    assert_eq!(info.config.name, "tiny-gate-command");
    assert!(!info.config.tokens.gate_target_point);

    let training = &info.metadata["training"];
    assert!(training.contains("\"init_perception\""), "{training}");

    // A deeper backbone grown from the first run's checkpoint, named after the growth.
    let deep = dir.join("deep");
    // One step from the first run's checkpoint into `out`, with `extra` flags.
    let from_first = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec![
            "train",
            "--data",
            data,
            "--out",
            out.to_str().unwrap(),
            "--quiet",
            "--steps",
            "1",
            "--batch-size",
            "2",
            "--init",
            first.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        ssr_agent(&args)
    };
    let deepen = |blocks: &str| from_first(&deep, &["--deepen-backbone", blocks]);
    let (ok, _, stderr) = deepen("2,1,2,1");
    assert!(ok, "{stderr}");
    let info = ssr_agent::checkpoint::inspect(&deep.join("final.safetensors")).unwrap();
    assert_eq!(info.config.name, "tiny-no-stl-no-ffp-blocks-2-1-2-1");
    assert_eq!(info.config.backbone.blocks, [2, 1, 2, 1]);
    let (ok, _, stderr) = deepen("1,1");
    assert!(
        !ok && stderr.contains("--deepen-backbone") && stderr.contains("[1, 1, 1, 1] blocks"),
        "{stderr}"
    );
    let (ok, _, stderr) = train(&["--deepen-backbone", "2,2,2,2"]);
    assert!(!ok && stderr.contains("--init"), "{stderr}");

    // The first run's network at another input size, named after it; the data must hold it.
    let resized = dir.join("resized");
    let resize = |size: &str| from_first(&resized, &["--input-size", size]);
    let (ok, _, stderr) = resize("48x32");
    assert!(ok, "{stderr}");
    let info = ssr_agent::checkpoint::inspect(&resized.join("final.safetensors")).unwrap();
    assert_eq!(info.config.name, "tiny-no-stl-no-ffp-input-48x32");
    assert_eq!(
        (info.config.image_width, info.config.image_height),
        (48, 32)
    );
    let (ok, _, stderr) = resize("96x32");
    assert!(
        !ok && stderr.contains("smaller than the network's 96x32 input"),
        "{stderr}"
    );
    let (ok, _, stderr) = resize("48");
    assert!(
        !ok && stderr.contains("'48' is not WIDTHxHEIGHT"),
        "{stderr}"
    );

    let (ok, _, stderr) = train(&["--stop-at", "0"]);
    assert!(!ok && stderr.contains("--stop-at"), "{stderr}");
    let (ok, _, stderr) = ssr_agent(&[
        "train",
        "--data",
        data,
        "--init",
        "a.safetensors",
        "--init-perception",
        "b.safetensors",
    ]);
    assert!(
        !ok && stderr.contains("--init-perception") && stderr.contains("cannot be used with"),
        "{stderr}"
    );
    let (ok, _, stderr) = train(&["--tokens", "0"]);
    assert!(!ok && stderr.contains("num_tokens"), "{stderr}");
    let (ok, _, stderr) = ssr_agent(&["train", "--data", "/no/such/dataset", "--out", out_arg]);
    assert!(
        !ok && stderr.contains("/no/such/dataset/manifest.json"),
        "{stderr}"
    );
}

#[test]
fn logs_into_a_file_or_pipe_carry_no_colour_codes() {
    use std::io::{BufRead, BufReader};
    let mut child = Command::new(env!("CARGO_BIN_EXE_ssr-agent"))
        .args([
            "serve",
            "--untrained-config",
            "cpu-default",
            "--listen",
            "127.0.0.1:0",
        ])
        .args(["--metrics-listen", "off"])
        .env("RUST_LOG", "info")
        .env_remove("SSR_AGENT_CHECKPOINT")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("runs");
    let stderr = child.stderr.take().unwrap();
    let line = BufReader::new(stderr)
        .lines()
        .map_while(Result::ok)
        .find(|l| l.contains("INFO"));
    child.kill().unwrap();
    child.wait().unwrap();
    let line = line.expect("an INFO line before the server stopped");
    assert!(!line.contains('\u{1b}'), "{line:?}");
}
