//! Checkpoints: save then load gives identical outputs; new controller settings keep the
//! weights; blends interpolate every tensor; bad files are clear errors.

mod common;

use burn::module::Module;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;

use common::{max_abs_diff, model_input, tiny_config};
use ssr_agent::checkpoint::{
    BLEND_KEY, CONTROL_KEY, CheckpointError, HISTORY_KEY, blend, control_config, history, inspect,
    load, save, with_control,
};
use ssr_agent::control::ControlConfig;
use ssr_agent::history::History;
use ssr_agent::model::config::SsrConfig;
use ssr_agent::model::{SsrModel, float_values};

#[test]
fn save_then_load_gives_identical_outputs() {
    let device = Device::flex();
    let config = tiny_config();
    let model = config.init(&device);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("roundtrip.safetensors");
    save(&model, &config, &[("note", "unit test".into())], &path).unwrap();
    let (loaded, info) = load(&path, &device).unwrap();
    assert_eq!(info.config, config);
    assert_eq!(
        info.metadata.get("note").map(String::as_str),
        Some("unit test")
    );
    assert_same_outputs(&model, &loaded, &config, &device);
}

/// The two networks give bit-identical waypoints and BEV on one input.
fn assert_same_outputs(a: &SsrModel, b: &SsrModel, config: &SsrConfig, device: &Device) {
    let input = model_input(config, 2, 1, true, device);
    let a = a.valid().forward(&input);
    let b = b.valid().forward(&input);
    assert_eq!(
        max_abs_diff(
            float_values(a.head.waypoints),
            float_values(b.head.waypoints)
        ),
        0.0
    );
    assert_eq!(max_abs_diff(float_values(a.bev), float_values(b.bev)), 0.0);
}

#[test]
fn a_checkpoint_names_its_history_mode_or_is_served_as_it_was_validated() {
    let device = Device::flex();
    let config = tiny_config();
    let model = config.init(&device);
    let dir = tempfile::tempdir().unwrap();
    let written = |name: &str, metadata: &[(&str, String)]| {
        let path = dir.path().join(name);
        save(&model, &config, metadata, &path).unwrap();
        path
    };
    let mode = |path: &std::path::Path| history(&inspect(path).unwrap());
    // Its own key.
    let link = written("link.safetensors", &[(HISTORY_KEY, "\"link\"".into())]);
    assert_eq!(mode(&link), Ok(History::Link));
    // Written before the key: the controller settings carried it.
    let older = written(
        "older.safetensors",
        &[(CONTROL_KEY, r#"{"alpha": 0.3, "history": "chain"}"#.into())],
    );
    assert_eq!(mode(&older), Ok(History::Chain));
    // Written before there was a choice: the recursion it was validated on.
    let oldest = written(
        "oldest.safetensors",
        &[(CONTROL_KEY, r#"{"alpha": 0.3}"#.into())],
    );
    assert_eq!(mode(&oldest), Ok(History::Recursive));
    assert_eq!(
        mode(&written("none.safetensors", &[])),
        Ok(History::Recursive)
    );
    let bad = written("bad.safetensors", &[(HISTORY_KEY, "\"sideways\"".into())]);
    let error = mode(&bad).unwrap_err();
    assert!(
        error.contains("'history' metadata") && error.contains("sideways"),
        "{error}"
    );
    // New controller settings for an older checkpoint keep the mode it carried.
    with_control(&older, &older, &ControlConfig::default(), &device).unwrap();
    assert_eq!(mode(&older), Ok(History::Chain));
    assert_eq!("link".parse(), Ok(History::Link));
    assert!(
        "sideways"
            .parse::<History>()
            .unwrap_err()
            .contains("sideways")
    );
}

#[test]
fn new_controller_settings_keep_the_weights_and_the_other_metadata() {
    let device = Device::flex();
    let config = tiny_config();
    let model = config.init(&device);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("model.safetensors");
    save(&model, &config, &[("note", "unit test".into())], &path).unwrap();
    let before = std::fs::read(&path).unwrap();
    assert_eq!(
        control_config(&inspect(&path).unwrap()).unwrap(),
        ControlConfig::default()
    );

    // Out of range: refused, and the file is untouched.
    let bad = ControlConfig {
        alpha: 2.0,
        ..ControlConfig::default()
    };
    let error = with_control(&path, &path, &bad, &device).unwrap_err();
    assert!(
        matches!(error, CheckpointError::BadControl { .. }),
        "{error}"
    );
    assert!(error.to_string().contains("alpha = 2"), "{error}");
    assert_eq!(std::fs::read(&path).unwrap(), before);

    // In place: the weights give the same outputs, the notes stay, the settings are new, and
    // the file keeps its mode.
    #[cfg(unix)]
    use std::os::unix::fs::PermissionsExt;
    #[cfg(unix)]
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
    let mut control = ControlConfig::default();
    control.safety.enabled = true;
    control.vehicle.wheelbase = 2.87;
    with_control(&path, &path, &control, &device).unwrap();
    #[cfg(unix)]
    assert_eq!(
        std::fs::metadata(&path).unwrap().permissions().mode() & 0o777,
        0o644
    );
    let (loaded, info) = load(&path, &device).unwrap();
    assert_eq!(control_config(&info).unwrap(), control);
    assert!(info.metadata.contains_key(CONTROL_KEY));
    assert_eq!(info.metadata["note"], "unit test");
    assert!(!dir.path().join("model.safetensors.partial").exists());
    assert_same_outputs(&model, &loaded, &config, &device);

    // A truncated source is named, and nothing is written.
    let truncated = dir.path().join("truncated.safetensors");
    std::fs::write(&truncated, &before[..before.len() / 2]).unwrap();
    let out = dir.path().join("out.safetensors");
    let error = with_control(&truncated, &out, &control, &device).unwrap_err();
    assert!(
        matches!(error, CheckpointError::Truncated { .. }),
        "{error}"
    );
    assert!(!out.exists());
}

/// Every float of a network, in the order its tensors are visited.
fn floats(model: &SsrModel) -> Vec<f32> {
    model
        .collect(None, None, false)
        .into_iter()
        .flat_map(|tensor| {
            let bytes = tensor.to_bytes().unwrap();
            bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn a_blend_interpolates_every_tensor_and_carries_the_second_checkpoints_settings() {
    let device = Device::flex();
    let config = tiny_config();
    let dir = tempfile::tempdir().unwrap();
    let link = serde_json::to_string(&History::Link).unwrap();
    let (a, b) = (config.init(&device), config.init(&device));
    let (from, to) = (
        dir.path().join("a.safetensors"),
        dir.path().join("b.safetensors"),
    );
    save(&a, &config, &[(HISTORY_KEY, link.clone())], &from).unwrap();
    let mut control = ControlConfig::default();
    control.safety.enabled = true;
    let b_metadata = [
        (HISTORY_KEY, link.clone()),
        (CONTROL_KEY, serde_json::to_string(&control).unwrap()),
        ("note", "fine-tuned".to_string()),
    ];
    save(&b, &config, &b_metadata, &to).unwrap();
    let out = dir.path().join("blend.safetensors");
    let blended = |weight: f64| {
        blend(&from, &to, weight, &out, &device).unwrap();
        load(&out, &device).unwrap()
    };

    // The ends are the two networks themselves.
    assert_same_outputs(&blended(0.0).0, &a, &config, &device);
    assert_same_outputs(&blended(1.0).0, &b, &config, &device);
    // Between, each value of every tensor the file holds lies where the weight puts it.
    let (mid, info) = blended(0.25);
    let (x, y, m) = (floats(&a), floats(&b), floats(&mid));
    assert_eq!((x.len(), y.len()), (m.len(), m.len()));
    let worst = x
        .iter()
        .zip(&y)
        .zip(&m)
        .map(|((x, y), m)| (m - (0.75 * x + 0.25 * y)).abs() / (1.0 + x.abs() + y.abs()))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "{worst}");
    assert!(x.iter().zip(&m).any(|(x, m)| x != m));
    assert_eq!(control_config(&info).unwrap(), control);
    assert_eq!(info.metadata["note"], "fine-tuned");
    let note: serde_json::Value = serde_json::from_str(&info.metadata[BLEND_KEY]).unwrap();
    assert_eq!(note["weight"], 0.25);
    assert!(note["from"].as_str().unwrap().ends_with("a.safetensors"));

    // Refusals name what differs, and write nothing.
    let nothing = dir.path().join("nothing.safetensors");
    let refused = |from: &std::path::Path, weight: f64, needle: &str| {
        let error = blend(from, &to, weight, &nothing, &device).unwrap_err();
        assert!(error.to_string().contains(needle), "{error}");
        assert!(!nothing.exists());
    };
    refused(&from, 1.5, "must be in 0..=1, not 1.5");
    refused(&from, f64::NAN, "must be in 0..=1, not NaN");
    let mut wider = config.clone();
    wider.channels *= 2;
    let other = dir.path().join("wider.safetensors");
    save(&wider.init(&device), &wider, &[(HISTORY_KEY, link)], &other).unwrap();
    refused(&other, 0.5, "their model configs differ");
    let chained = dir.path().join("chain.safetensors");
    let chain = serde_json::to_string(&History::Chain).unwrap();
    save(&a, &config, &[(HISTORY_KEY, chain)], &chained).unwrap();
    refused(&chained, 0.5, "different history modes (chain and link)");
    refused(
        &dir.path().join("missing.safetensors"),
        0.5,
        "missing.safetensors",
    );
}

#[test]
fn bad_checkpoints_are_clear_errors() {
    let device = Device::flex();
    let config = tiny_config();
    let model = config.init(&device);
    let dir = tempfile::tempdir().unwrap();
    let scratch = |name: &str| dir.path().join(name);
    let good = scratch("good.safetensors");
    save(&model, &config, &[], &good).unwrap();
    let bytes = std::fs::read(&good).unwrap();

    let truncated = scratch("truncated.safetensors");
    std::fs::write(&truncated, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let err = load(&truncated, &device).unwrap_err();
    assert!(matches!(err, CheckpointError::Truncated { .. }), "{err}");
    assert!(err.to_string().contains("truncated"));

    let header_cut = scratch("header-cut.safetensors");
    std::fs::write(&header_cut, &bytes[..20]).unwrap();
    assert!(matches!(
        load(&header_cut, &device).unwrap_err(),
        CheckpointError::Truncated { .. }
    ));

    // A header whose tensor claims to end at the last byte a u64 can name.
    let header = format!(
        r#"{{"w":{{"dtype":"F32","shape":[1],"data_offsets":[0,{}]}}}}"#,
        u64::MAX
    );
    let mut huge = (header.len() as u64).to_le_bytes().to_vec();
    huge.extend_from_slice(header.as_bytes());
    let claims_too_much = scratch("claims-too-much.safetensors");
    std::fs::write(&claims_too_much, &huge).unwrap();
    assert!(matches!(
        load(&claims_too_much, &device).unwrap_err(),
        CheckpointError::Truncated { .. }
    ));

    let garbage = scratch("garbage.safetensors");
    std::fs::write(&garbage, b"this is not a checkpoint at all").unwrap();
    assert!(matches!(
        load(&garbage, &device).unwrap_err(),
        CheckpointError::NotSafetensors { .. }
    ));

    let directory = scratch("a-directory.safetensors");
    std::fs::create_dir_all(&directory).unwrap();
    let error = load(&directory, &device).unwrap_err();
    assert!(error.to_string().contains("is a directory"), "{error}");

    let missing = scratch("does-not-exist.safetensors");
    assert!(matches!(
        load(&missing, &device).unwrap_err(),
        CheckpointError::Io { .. }
    ));

    // Weights of one config stored under another config.
    let mut wider = config.clone();
    wider.channels = 32;
    let mismatched = scratch("mismatch.safetensors");
    save(&model, &wider, &[], &mismatched).unwrap();
    let err = load(&mismatched, &device).unwrap_err();
    assert!(matches!(err, CheckpointError::Mismatch { .. }), "{err}");

    // Plain safetensors without our config.
    let foreign = scratch("foreign.safetensors");
    model
        .save_into(&mut SafetensorsStore::from_file(&foreign))
        .unwrap();
    assert!(matches!(
        inspect(&foreign).unwrap_err(),
        CheckpointError::MissingConfig { .. }
    ));
}

/// Not a check: writes the fuzz replay's accepted checkpoint seed, a tiny network with random
/// weights and controller settings (`cargo test --release -p ssr-agent --test checkpoint --
/// --ignored write_the_fuzz_seed`); `tests/fuzz/entries/tests/replay.rs` must accept it.
#[test]
#[ignore = "writes tests/fuzz/seeds/checkpoint/tiny.safetensors"]
fn write_the_fuzz_seed() {
    let device = Device::flex();
    let config = tiny_config();
    let model = config.init(&device);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fuzz/seeds/checkpoint/tiny.safetensors");
    let control = serde_json::to_string(&ControlConfig::default()).unwrap();
    save(&model, &config, &[(CONTROL_KEY, control)], &path).unwrap();
    assert!(load(&path, &device).is_ok());
}
