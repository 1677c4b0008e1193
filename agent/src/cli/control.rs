//! `ssr-agent control`: show the controller settings a checkpoint carries, or write a copy of
//! the checkpoint with some of them changed (another vehicle's geometry, the safety stop on).
//!
//! A change is a JSON object merged over the current settings: only the keys it names change,
//! and a key the settings do not have is refused with its path, so a typo never passes
//! silently.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use serde_json::Value;
use ssr_agent::checkpoint;
use ssr_agent::control::ControlConfig;
use ssr_agent::device::Backend;
use ssrdrive_support::files::read_capped_text;

/// The largest settings file `--set` reads.
const MAX_PATCH_BYTES: u64 = 1 << 20;

#[derive(Args)]
pub struct ControlArgs {
    /// The checkpoint (from `ssr-agent train`).
    checkpoint: PathBuf,
    /// Settings to change: a JSON object, or a file holding one, merged over the checkpoint's
    /// (only the keys it names change), e.g. '{"safety": {"enabled": true}}' or
    /// '{"vehicle": {"wheelbase": 2.87, "max_wheel_angle": 70}}'. Needs --out.
    #[arg(long, requires = "out", value_name = "JSON|FILE")]
    set: Option<String>,
    /// Where to write the changed copy (may be the checkpoint itself).
    #[arg(long, requires = "set")]
    out: Option<PathBuf>,
}

pub fn run(args: &ControlArgs) -> anyhow::Result<()> {
    let info = checkpoint::inspect(&args.checkpoint)?;
    let current = checkpoint::control_config(&info)
        .map_err(|e| anyhow::anyhow!("checkpoint {}: {e}", args.checkpoint.display()))?;
    let (Some(set), Some(out)) = (&args.set, &args.out) else {
        println!(
            "{}",
            serde_json::to_string_pretty(&current).expect("configs serialise")
        );
        let history = checkpoint::history(&info)
            .map_err(|e| anyhow::anyhow!("checkpoint {}: {e}", args.checkpoint.display()))?;
        eprintln!(
            "served with its history as: {history} (not a controller setting; \
             `ssr-agent serve --history` overrides it)"
        );
        return Ok(());
    };
    let patch = read_patch(set)?;
    let mut merged = serde_json::to_value(&current).expect("configs serialise");
    merge(&mut merged, &patch, "").map_err(anyhow::Error::msg)?;
    let control: ControlConfig =
        serde_json::from_value(merged).context("the changed controller settings")?;
    checkpoint::with_control(&args.checkpoint, out, &control, &Backend::Cpu.device()?)?;
    eprintln!(
        "wrote {} with controller settings:\n{}",
        out.display(),
        serde_json::to_string_pretty(&control).expect("configs serialise")
    );
    Ok(())
}

/// `set` as JSON when it starts with `{`, else the JSON in the file it names.
fn read_patch(set: &str) -> anyhow::Result<Value> {
    let (text, source) = if set.trim_start().starts_with('{') {
        (set.to_string(), "--set".to_string())
    } else {
        let text = read_capped_text(Path::new(set), MAX_PATCH_BYTES)
            .with_context(|| format!("--set {set} is neither a JSON object nor a readable file"))?;
        (text, set.to_string())
    };
    let patch: Value =
        serde_json::from_str(&text).with_context(|| format!("{source} is not JSON"))?;
    anyhow::ensure!(
        patch.is_object(),
        "{source} must be a JSON object of settings"
    );
    Ok(patch)
}

/// Merges `patch` into `base` key by key (`path` names where, for errors): objects merge,
/// values replace, and a key `base` lacks is an error.
fn merge(base: &mut Value, patch: &Value, path: &str) -> Result<(), String> {
    let (Value::Object(base), Value::Object(patch)) = (&mut *base, patch) else {
        if base.is_object() {
            return Err(format!("'{path}' is a group of settings, not a value"));
        }
        *base = patch.clone();
        return Ok(());
    };
    for (key, value) in patch {
        let at = if path.is_empty() {
            key.clone()
        } else {
            format!("{path}.{key}")
        };
        let slot = base
            .get_mut(key)
            .ok_or_else(|| format!("unknown controller setting '{at}'"))?;
        merge(slot, value, &at)?;
    }
    Ok(())
}
