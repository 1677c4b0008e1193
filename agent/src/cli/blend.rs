//! `ssr-agent blend`: a checkpoint whose weights interpolate two checkpoints of one config
//! (WiSE-FT), typically a fine-tuned network and the one its fine-tuning started from.

use std::path::PathBuf;

use clap::Args;
use ssr_agent::checkpoint;
use ssr_agent::device::Backend;

#[derive(Args)]
pub struct BlendArgs {
    /// The checkpoint that weighs 1 - WEIGHT (typically the one fine-tuning started from).
    from: PathBuf,
    /// The checkpoint that weighs WEIGHT (typically the fine-tuned one); the blend carries its
    /// controller settings, history mode and training notes.
    to: PathBuf,
    /// How much of TO the blend takes, 0 to 1 (0 gives FROM's weights, 1 TO's).
    #[arg(long, value_name = "WEIGHT")]
    weight: f64,
    /// Where to write the blend (may be FROM or TO).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: &BlendArgs) -> anyhow::Result<()> {
    checkpoint::blend(
        &args.from,
        &args.to,
        args.weight,
        &args.out,
        &Backend::Cpu.device()?,
    )?;
    eprintln!(
        "wrote {}: {} x {} + {} x {}",
        args.out.display(),
        1.0 - args.weight,
        args.from.display(),
        args.weight,
        args.to.display()
    );
    Ok(())
}
