//! Checkpoints: save then load gives identical outputs; bad files are clear errors.

mod common;

use burn::module::Module;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;

use common::{max_abs_diff, model_input, tiny_config};
use ssr_agent::checkpoint::{CheckpointError, inspect, load, save};
use ssr_agent::model::float_values;

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
    let input = model_input(&config, 2, 1, true, &device);
    let a = model.valid().forward(&input);
    let b = loaded.valid().forward(&input);
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
