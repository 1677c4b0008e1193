//! Checkpoints: the weights in one safetensors file whose metadata holds the model config (and
//! free-form training notes), so a checkpoint always rebuilds the network it was saved from.
//!
//! Guarantees: [`load`] never panics on a bad file. It reports a missing or unreadable file, a
//! file that is not safetensors, a truncated file (with the bytes expected and found), a missing
//! or invalid config, and weights that do not fit the config (names and shapes), each as its
//! own [`CheckpointError`]. Headers are capped at [`MAX_HEADER_BYTES`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;
use ssrdrive_proto::camera::Rig;

use crate::control::ControlConfig;
use crate::history::History;
use crate::model::SsrModel;
use crate::model::config::SsrConfig;

/// Metadata key of the config JSON.
pub const CONFIG_KEY: &str = "ssr_config";
/// Metadata key of the controller settings JSON (the vehicle the network was trained to drive,
/// look-ahead, PID gains, fusion); a checkpoint without it gets [`ControlConfig::default`].
pub const CONTROL_KEY: &str = "control";
/// Metadata key of how the network was trained to get its history BEV (a JSON string:
/// `"chain"`, `"link"` or `"recursive"`); see [`history`] for checkpoints without it.
pub const HISTORY_KEY: &str = "history";
/// Metadata key of the rig the network was trained with (JSON); a checkpoint without it gets
/// the config's default rig.
pub const RIG_KEY: &str = "rig";
/// Metadata key of the training notes (JSON: config, step, data, validation).
pub const TRAINING_KEY: &str = "training";
/// Metadata key of a blend's notes (JSON: the two checkpoints and the weight; see [`blend`]).
pub const BLEND_KEY: &str = "blend";
/// Largest safetensors header accepted.
pub const MAX_HEADER_BYTES: u64 = 16 << 20;

/// Why a checkpoint cannot be saved, read or loaded; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// The file could not be opened, read or written.
    #[error("checkpoint {path}: {source}")]
    Io {
        /// The checkpoint file (or the label of one in memory).
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not safetensors: no header, a header over the cap, or one that is not JSON.
    #[error("checkpoint {path} is not a safetensors file: {reason}")]
    NotSafetensors {
        /// The checkpoint file (or the label of one in memory).
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The file is shorter than its header says.
    #[error(
        "checkpoint {path} is truncated: its header promises {expected} bytes, the file has {actual}"
    )]
    Truncated {
        /// The checkpoint file (or the label of one in memory).
        path: PathBuf,
        /// Bytes the header promises (length prefix, header and tensor data).
        expected: u64,
        /// Bytes the file has.
        actual: u64,
    },
    /// The metadata holds no model config under [`CONFIG_KEY`].
    #[error("checkpoint {path} has no '{CONFIG_KEY}' in its metadata (not saved by ssr-agent?)")]
    MissingConfig {
        /// The checkpoint file (or the label of one in memory).
        path: PathBuf,
    },
    /// The model config in the metadata does not parse or does not validate.
    #[error("checkpoint {path} holds an invalid model config: {reason}")]
    BadConfig {
        /// The checkpoint file (or the label of one in memory).
        path: PathBuf,
        /// Why the config was refused.
        reason: String,
    },
    /// Controller settings that do not validate.
    #[error("controller settings for {path}: {reason}")]
    BadControl {
        /// The checkpoint file they were meant for.
        path: PathBuf,
        /// Which setting is out of range.
        reason: String,
    },
    /// Two checkpoints that cannot be blended: different configs, history modes or rigs.
    #[error("checkpoints {from} and {to} cannot be blended: {reason}")]
    Incompatible {
        /// The checkpoint weighing `1 - weight`.
        from: PathBuf,
        /// The checkpoint weighing `weight`.
        to: PathBuf,
        /// What differs.
        reason: String,
    },
    /// The weights do not fit the network the config describes (names or shapes).
    #[error("checkpoint {path} does not match its config '{config}': {details}")]
    Mismatch {
        /// The checkpoint file (or the label of one in memory).
        path: PathBuf,
        /// The config's name.
        config: String,
        /// Which tensors are missing, extra or of the wrong shape.
        details: String,
    },
}

/// What a checkpoint's header says, read without loading the weights.
#[derive(Debug, Clone)]
pub struct CheckpointInfo {
    /// The model config the weights were saved with (validated).
    pub config: SsrConfig,
    /// Every metadata entry except the config.
    pub metadata: BTreeMap<String, String>,
    /// Tensors in the file.
    pub tensors: usize,
    /// Size of the file, bytes.
    pub bytes: u64,
}

/// Saves `model` with `config` and extra metadata entries (for example training notes).
pub fn save(
    model: &SsrModel,
    config: &SsrConfig,
    metadata: &[(&str, String)],
    path: &Path,
) -> Result<(), CheckpointError> {
    let io = |source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    };
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(io)?;
    }
    let config_json = serde_json::to_string(config).expect("configs serialise");
    let mut store = SafetensorsStore::from_file(path)
        .metadata(CONFIG_KEY, config_json)
        .overwrite(true);
    for (key, value) in metadata {
        store = store.metadata(*key, value.clone());
    }
    model
        .save_into(&mut store)
        .map_err(|e| CheckpointError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::other(e.to_string()),
        })
}

/// Writes a copy of the checkpoint at `from` to `to` with `control` (checked first) as its
/// controller settings; the weights and every other metadata entry are kept. The copy is
/// written beside `to` and renamed over it, so `to` may be `from` and is never left half
/// written.
pub fn with_control(
    from: &Path,
    to: &Path,
    control: &ControlConfig,
    device: &Device,
) -> Result<(), CheckpointError> {
    control
        .validate()
        .map_err(|reason| CheckpointError::BadControl {
            path: to.to_path_buf(),
            reason,
        })?;
    let (model, info) = load(from, device)?;
    // Checkpoints written before the history had a key of its own kept it in the controller
    // settings, which are replaced here: the copy names it under its own key.
    let history = history(&info).map_err(|reason| CheckpointError::BadControl {
        path: from.to_path_buf(),
        reason,
    })?;
    let control_json = serde_json::to_string(control).expect("configs serialise");
    let history_json = serde_json::to_string(&history).expect("modes serialise");
    let metadata = replaced(
        &info.metadata,
        vec![(CONTROL_KEY, control_json), (HISTORY_KEY, history_json)],
    );
    save_over(&model, &info.config, &metadata, from, to)
}

/// Writes to `out` the blend of the checkpoints `from` and `to`, `(1 - weight) * from + weight *
/// to` tensor by tensor ([`crate::model::blend::blend`]), with `to`'s controller settings,
/// history mode, rig and training notes, and a [`BLEND_KEY`] entry naming both files and the
/// weight. The two must share their model config, history mode and rig: a blend of networks
/// trained for different inputs would drive as neither. `out` may be either of them and is
/// never left half written.
pub fn blend(
    from: &Path,
    to: &Path,
    weight: f64,
    out: &Path,
    device: &Device,
) -> Result<(), CheckpointError> {
    let (from_model, from_info) = load(from, device)?;
    let (to_model, to_info) = load(to, device)?;
    let incompatible = |reason: String| CheckpointError::Incompatible {
        from: from.to_path_buf(),
        to: to.to_path_buf(),
        reason,
    };
    // A history mode is read as the controller settings that once carried it (as in
    // `with_control`); a rig is part of what the network takes in.
    let unreadable = |path: &Path, reason: String| CheckpointError::BadControl {
        path: path.to_path_buf(),
        reason,
    };
    let bad_rig = |path: &Path, reason: String| CheckpointError::BadConfig {
        path: path.to_path_buf(),
        reason,
    };
    if from_info.config != to_info.config {
        return Err(incompatible(format!(
            "their model configs differ ('{}' and '{}')",
            from_info.config.name, to_info.config.name
        )));
    }
    let from_history = history(&from_info).map_err(|e| unreadable(from, e))?;
    let to_history = history(&to_info).map_err(|e| unreadable(to, e))?;
    if from_history != to_history {
        return Err(incompatible(format!(
            "they were trained for different history modes ({from_history} and {to_history})"
        )));
    }
    if rig(&from_info).map_err(|e| bad_rig(from, e))?
        != rig(&to_info).map_err(|e| bad_rig(to, e))?
    {
        return Err(incompatible("they were trained on different rigs".into()));
    }
    let model = crate::model::blend::blend(&from_model, to_model, weight).map_err(incompatible)?;
    let note = serde_json::json!({
        "from": from.display().to_string(),
        "to": to.display().to_string(),
        "weight": weight,
    });
    let history_json = serde_json::to_string(&to_history).expect("modes serialise");
    let metadata = replaced(
        &to_info.metadata,
        vec![(HISTORY_KEY, history_json), (BLEND_KEY, note.to_string())],
    );
    save_over(&model, &to_info.config, &metadata, to, out)
}

/// `metadata` with `entries` in place of whatever it held under their keys.
fn replaced<'a>(
    metadata: &'a BTreeMap<String, String>,
    entries: Vec<(&'a str, String)>,
) -> Vec<(&'a str, String)> {
    let mut kept: Vec<(&str, String)> = metadata
        .iter()
        .filter(|(key, _)| entries.iter().all(|(replacing, _)| replacing != key))
        .map(|(key, value)| (key.as_str(), value.clone()))
        .collect();
    kept.extend(entries);
    kept
}

/// Saves beside `out` and renames over it, so `out` is never left half written; the file keeps
/// the mode of the one it replaces, else of `like`.
fn save_over(
    model: &SsrModel,
    config: &SsrConfig,
    metadata: &[(&str, String)],
    like: &Path,
    out: &Path,
) -> Result<(), CheckpointError> {
    let mut partial = out.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    save(model, config, metadata, &partial)?;
    let io = |source| CheckpointError::Io {
        path: out.to_path_buf(),
        source,
    };
    let mode = std::fs::metadata(out)
        .or_else(|_| std::fs::metadata(like))
        .map_err(io)?
        .permissions();
    std::fs::set_permissions(&partial, mode).map_err(io)?;
    std::fs::rename(&partial, out).map_err(io)
}

/// The controller settings a checkpoint carries (checked), or the defaults when it has none.
pub fn control_config(info: &CheckpointInfo) -> Result<ControlConfig, String> {
    let Some(json) = info.metadata.get(CONTROL_KEY) else {
        return Ok(ControlConfig::default());
    };
    let config: ControlConfig = serde_json::from_str(json)
        .map_err(|e| format!("its '{CONTROL_KEY}' metadata is not a controller config: {e}"))?;
    config
        .validate()
        .map_err(|e| format!("its '{CONTROL_KEY}' metadata: {e}"))?;
    Ok(config)
}

/// How a checkpoint's network gets its history BEV: its [`HISTORY_KEY`]; else the `history`
/// its controller settings carried before the mode had a key of its own; else
/// [`History::Recursive`], the mode checkpoints were validated on before there was a choice.
pub fn history(info: &CheckpointInfo) -> Result<History, String> {
    if let Some(json) = info.metadata.get(HISTORY_KEY) {
        return serde_json::from_str(json)
            .map_err(|e| format!("its '{HISTORY_KEY}' metadata is not a history mode: {e}"));
    }
    let Some(control) = info.metadata.get(CONTROL_KEY) else {
        return Ok(History::Recursive);
    };
    #[derive(serde::Deserialize)]
    struct Before {
        history: Option<History>,
    }
    let before: Before = serde_json::from_str(control)
        .map_err(|e| format!("its '{CONTROL_KEY}' metadata names no history mode: {e}"))?;
    Ok(before.history.unwrap_or(History::Recursive))
}

/// The rig a checkpoint carries (checked), if any.
pub fn rig(info: &CheckpointInfo) -> Result<Option<Rig>, String> {
    info.metadata
        .get(RIG_KEY)
        .map(|json| Rig::from_json(json).map_err(|e| format!("its '{RIG_KEY}' metadata: {e}")))
        .transpose()
}

/// Reads and checks a checkpoint's header: config, metadata, and that the file is complete.
pub fn inspect(path: &Path) -> Result<CheckpointInfo, CheckpointError> {
    let io = |source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let metadata = file.metadata().map_err(io)?;
    if metadata.is_dir() {
        return Err(CheckpointError::NotSafetensors {
            path: path.to_path_buf(),
            reason: "is a directory, not a checkpoint file".into(),
        });
    }
    read_header(file, metadata.len(), path)
}

/// [`inspect`] for a checkpoint in memory; `label` names it in errors.
pub fn inspect_bytes(bytes: &[u8], label: &Path) -> Result<CheckpointInfo, CheckpointError> {
    read_header(bytes, bytes.len() as u64, label)
}

fn read_header(
    mut reader: impl std::io::Read,
    actual: u64,
    path: &Path,
) -> Result<CheckpointInfo, CheckpointError> {
    let io = |source| CheckpointError::Io {
        path: path.to_path_buf(),
        source,
    };
    let not_st = |reason: String| CheckpointError::NotSafetensors {
        path: path.to_path_buf(),
        reason,
    };
    let mut length = [0u8; 8];
    reader
        .read_exact(&mut length)
        .map_err(|_| not_st(format!("only {actual} bytes, no header")))?;
    let header_len = u64::from_le_bytes(length);
    if header_len > MAX_HEADER_BYTES {
        return Err(not_st(format!(
            "header of {header_len} bytes exceeds the {MAX_HEADER_BYTES}-byte cap"
        )));
    }
    if 8 + header_len > actual {
        return Err(CheckpointError::Truncated {
            path: path.to_path_buf(),
            expected: 8 + header_len,
            actual,
        });
    }
    let mut header = vec![0u8; header_len as usize];
    reader.read_exact(&mut header).map_err(io)?;
    let header: serde_json::Map<String, serde_json::Value> = serde_json::from_slice(&header)
        .map_err(|e| not_st(format!("header is not a JSON object: {e}")))?;

    let mut data_end = 0u64;
    let mut tensors = 0;
    let mut metadata = BTreeMap::new();
    for (name, entry) in &header {
        if name == "__metadata__" {
            for (key, value) in entry.as_object().into_iter().flatten() {
                metadata.insert(key.clone(), value.as_str().unwrap_or_default().to_string());
            }
            continue;
        }
        let end = entry
            .get("data_offsets")
            .and_then(|o| o.get(1))
            .and_then(|v| v.as_u64())
            .ok_or_else(|| not_st(format!("tensor '{name}' has no data_offsets")))?;
        data_end = data_end.max(end);
        tensors += 1;
    }
    // data_end is the file's own claim: a huge one saturates, and so reads as truncated.
    let expected = (8 + header_len).saturating_add(data_end);
    if expected > actual {
        return Err(CheckpointError::Truncated {
            path: path.to_path_buf(),
            expected,
            actual,
        });
    }
    let config_json =
        metadata
            .remove(CONFIG_KEY)
            .ok_or_else(|| CheckpointError::MissingConfig {
                path: path.to_path_buf(),
            })?;
    let config: SsrConfig =
        serde_json::from_str(&config_json).map_err(|e| CheckpointError::BadConfig {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
    config.validate().map_err(|e| CheckpointError::BadConfig {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(CheckpointInfo {
        config,
        metadata,
        tensors,
        bytes: actual,
    })
}

/// Loads a checkpoint onto `device`: the network its config describes, with its weights.
pub fn load(path: &Path, device: &Device) -> Result<(SsrModel, CheckpointInfo), CheckpointError> {
    let info = inspect(path)?;
    apply(SafetensorsStore::from_file(path), info, path, device)
}

/// [`load`] for a checkpoint in memory; `label` names it in errors.
pub fn load_bytes(
    bytes: &[u8],
    label: &Path,
    device: &Device,
) -> Result<(SsrModel, CheckpointInfo), CheckpointError> {
    let info = inspect_bytes(bytes, label)?;
    apply(
        SafetensorsStore::from_bytes(Some(bytes.to_vec())),
        info,
        label,
        device,
    )
}

fn apply(
    store: SafetensorsStore,
    info: CheckpointInfo,
    path: &Path,
    device: &Device,
) -> Result<(SsrModel, CheckpointInfo), CheckpointError> {
    let mismatch = |details: String| CheckpointError::Mismatch {
        path: path.to_path_buf(),
        config: info.config.name.clone(),
        details,
    };
    let mut model = info.config.init(device);
    let mut store = store.validate(true).allow_partial(false);
    let result = model
        .load_from(&mut store)
        .map_err(|e| mismatch(e.to_string()))?;
    if !result.unused.is_empty() {
        return Err(mismatch(format!(
            "tensors the config has no place for: {}",
            result.unused.join(", ")
        )));
    }
    Ok((model, info))
}

/// The checkpoint bundled into the binary (`agent/models/`, see its model card): the CPU
/// default trained by `ssr-agent train` on the bundled training towns.
pub mod bundled {
    use super::*;

    /// How logs and errors name it.
    pub const NAME: &str = "bundled:ssr-cpu-default";
    /// The safetensors bytes.
    pub const BYTES: &[u8] = include_bytes!("../models/ssr-cpu-default.safetensors");

    /// Loads it onto `device`.
    pub fn load(device: &Device) -> Result<(SsrModel, CheckpointInfo), CheckpointError> {
        load_bytes(BYTES, Path::new(NAME), device)
    }
}
