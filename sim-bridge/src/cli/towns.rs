//! `sim-bridge towns`: list the bundled towns or regenerate their files.

use std::path::PathBuf;

use clap::Subcommand;
use sim_bridge::map::MapOptions;
use sim_bridge::towngen::{self, TownStyle};

#[derive(Debug, Subcommand)]
pub enum TownsCommand {
    /// List the bundled towns with their size and traffic control.
    List,
    /// Write every bundled town's OpenDRIVE file (byte-identical to the committed ones).
    Generate {
        /// Folder to write into.
        #[arg(long, default_value = "sim-bridge/towns")]
        out_dir: PathBuf,
    },
}

pub fn run(cmd: TownsCommand) -> anyhow::Result<()> {
    match cmd {
        TownsCommand::List => {
            println!(
                "{:<20} {:>9} {:>9} {:>6} {:>6}  description",
                "town", "size x m", "size y m", "junc", "lights"
            );
            for style in TownStyle::ALL {
                let map = super::load_map(style.name(), MapOptions::default())?;
                let size = map.bounds.1 - map.bounds.0;
                let role = if style.is_test_town() {
                    "[test] "
                } else {
                    "[train] "
                };
                println!(
                    "{:<20} {:>9.0} {:>9.0} {:>6} {:>6}  {role}{}",
                    style.name(),
                    size.x,
                    size.y,
                    map.junctions.len(),
                    map.lights.len(),
                    style.description()
                );
            }
            Ok(())
        }
        TownsCommand::Generate { out_dir } => {
            towngen::write_bundled(&out_dir)?;
            println!(
                "wrote {} towns to {}",
                TownStyle::ALL.len(),
                out_dir.display()
            );
            Ok(())
        }
    }
}
