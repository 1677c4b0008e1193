//! A run's resume state (`<out>/resume/`): the network's weights with their parameter ids
//! (`model.bpk`), the AdamW state (`optimizer.bpk`) and where the run stands
//! (`progress.json`: the step and the run's config).
//!
//! Resume states written before the hazard head joined the network (when it was a
//! training-only probe) keep its weights apart in `hazard.bpk`; they are read into the
//! network's head with their parameter ids, so such a run goes on exactly where it was. The
//! next resume state is written in today's layout.

use std::path::Path;

use burn::module::Module;
use burn::store::{BurnpackStore, ModuleSnapshot};
use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::config::TrainConfig;
use super::error::TrainError;
use crate::model::SsrModel;
use crate::model::config::SsrConfig;

/// The file of a resume state from before the hazard head joined the network.
const LEGACY_HAZARD_FILE: &str = "hazard.bpk";

/// Where the run stands, saved with the resume state.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct Progress {
    /// Optimiser steps done.
    pub step: u64,
    /// The run's config.
    pub config: TrainConfig,
}

/// Reads and checks `<out>/resume/progress.json`.
pub(super) fn read_progress(out: &Path) -> Result<Progress, TrainError> {
    let dir = out.join("resume");
    let path = dir.join("progress.json");
    let resume = |problem: String| TrainError::Resume {
        path: path.clone(),
        problem,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| resume(e.to_string()))?;
    let mut progress: Progress = serde_json::from_str(&text).map_err(|e| resume(e.to_string()))?;
    let model = &mut progress.config.model;
    if !model.hazard_head && dir.join(LEGACY_HAZARD_FILE).exists() {
        model.hazard_head = true;
    }
    progress.config.validate().map_err(resume)?;
    Ok(progress)
}

/// The network of the resume state in `dir`, built from `config` (as [`read_progress`] gave
/// it), with the weights and parameter ids it was saved with.
pub(super) fn load_model(
    dir: &Path,
    config: &SsrConfig,
    device: &Device,
) -> Result<SsrModel, String> {
    if !dir.join(LEGACY_HAZARD_FILE).exists() {
        let mut model = config.init(device);
        load_weights(&mut model, dir, "model.bpk")?;
        return Ok(model);
    }
    let apart = SsrConfig {
        hazard_head: false,
        ..config.clone()
    };
    let mut model = apart.init(device);
    load_weights(&mut model, dir, "model.bpk")?;
    let mut head = config
        .init_hazard_head(device)
        .ok_or("a hazard head's weights in a run without one")?;
    load_weights(&mut head, dir, LEGACY_HAZARD_FILE)?;
    model.hazard = Some(head);
    Ok(model)
}

/// Loads a module's weights, with their parameter ids, from `file` in the resume folder `dir`.
fn load_weights<M: Module>(module: &mut M, dir: &Path, file: &str) -> Result<(), String> {
    let mut store = BurnpackStore::from_file(dir.join(file))
        .validate(true)
        .allow_partial(false);
    module
        .load_from(&mut store)
        .map(|_| ())
        .map_err(|e| format!("{file}: {e}"))
}

/// Saves a module's weights, with their parameter ids, as `file` in the folder `dir`.
pub(super) fn save_weights<M: Module>(module: &M, dir: &Path, file: &str) -> Result<(), String> {
    let mut store = BurnpackStore::from_file(dir.join(file)).overwrite(true);
    module.save_into(&mut store).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{float_tensor, float_values};

    #[test]
    fn a_resume_state_with_the_hazard_head_apart_loads_into_the_network() {
        let device = Device::flex();
        let config = SsrConfig::cpu_default();
        let dir = std::env::temp_dir().join(format!("ssr-legacy-resume-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Written the old way: the network without the head, the head in its own file.
        let trained = config.init(&device);
        let mut apart = trained.clone();
        let head = apart.hazard.take().unwrap();
        save_weights(&apart, &dir, "model.bpk").unwrap();
        save_weights(&head, &dir, LEGACY_HAZARD_FILE).unwrap();

        let loaded = load_model(&dir, &config, &device).unwrap();
        let tokens = float_tensor(
            vec![0.1; 2 * config.channels],
            [1, 2, config.channels],
            &device,
        );
        let logits =
            |model: &SsrModel| float_values(model.hazard.as_ref().unwrap().forward(tokens.clone()));
        assert_eq!(logits(&loaded), logits(&trained));
        // (Weights load lazily: the files stay until they were read.)
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
