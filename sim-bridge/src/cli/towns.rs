//! `sim-bridge towns`: list the bundled towns, regenerate their files, or write procedural
//! training towns.

use std::path::PathBuf;

use clap::Subcommand;
use sim_bridge::map::MapOptions;
use sim_bridge::towngen::procedural::{Bends, Family, LightPlacement};
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
    /// Write procedural training towns (`ssr_proc_NNN.xodr` or, with `--bends tight`,
    /// `ssr_tight_NNN.xodr`, one per seed, `_kerb_` in the name with `--lights kerb`, `_kerbback_`
    /// with `--lights kerb-set-back`: grids of
    /// varied spacing, angles, lanes, widths, bends, gaps and control; see
    /// `towngen::procedural`). Draw routes on them with `routes random` and collect with
    /// `collect --maps DIR`.
    Procedural {
        /// Seeds, as FIRST-LAST (inclusive) or a comma-separated list.
        #[arg(long, value_parser = parse_seeds)]
        seeds: SeedList,
        /// The family: `gentle` (loop corners of 18-40 m, some streets gently bent) or `tight`
        /// (corners a few metres beyond the kerb, some streets detouring through four of them,
        /// as small towns bend).
        #[arg(long, value_enum, default_value_t = BendsArg::Gentle)]
        bends: BendsArg,
        /// Where the lights stand: `across` (across the junction, US-style, as CARLA's
        /// Town03-07; some towns leave them to the simulator, which places them likewise) or
        /// `kerb` (every light at the kerb just before its stop line, as CARLA's Town01 and
        /// Town02 post them) or `kerb-set-back` (at the kerb 2-7 m before the line, varied by
        /// light: beside or behind a car waiting at the line, out of a forward camera's view).
        #[arg(long, value_enum, default_value_t = LightsArg::Across)]
        lights: LightsArg,
        /// Folder to write into.
        #[arg(long)]
        out: PathBuf,
    },
}

/// `towns procedural --bends`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum BendsArg {
    Gentle,
    Tight,
}

impl From<BendsArg> for Bends {
    fn from(arg: BendsArg) -> Self {
        match arg {
            BendsArg::Gentle => Bends::Gentle,
            BendsArg::Tight => Bends::Tight,
        }
    }
}

/// `towns procedural --lights`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum LightsArg {
    Across,
    Kerb,
    KerbSetBack,
}

impl From<LightsArg> for LightPlacement {
    fn from(arg: LightsArg) -> Self {
        match arg {
            LightsArg::Across => LightPlacement::Across,
            LightsArg::Kerb => LightPlacement::Kerb,
            LightsArg::KerbSetBack => LightPlacement::KerbSetBack,
        }
    }
}

/// The seeds of `towns procedural --seeds`.
#[derive(Debug, Clone)]
pub struct SeedList(Vec<u64>);

/// FIRST-LAST or A,B,C (a clap value parser); at most 1,000 seeds.
fn parse_seeds(text: &str) -> Result<SeedList, String> {
    let bad = || format!("'{text}' is not FIRST-LAST or a comma-separated list of seeds");
    let seeds: Vec<u64> = match text.split_once('-') {
        Some((a, b)) => {
            let (a, b): (u64, u64) = (
                a.trim().parse().map_err(|_| bad())?,
                b.trim().parse().map_err(|_| bad())?,
            );
            if a > b {
                return Err(format!("{text}: FIRST is after LAST"));
            }
            (a..=b).collect()
        }
        None => text
            .split(',')
            .map(|s| s.trim().parse().map_err(|_| bad()))
            .collect::<Result<_, _>>()?,
    };
    if seeds.is_empty() || seeds.len() > 1000 {
        return Err(format!("{text}: give 1 to 1000 seeds"));
    }
    Ok(SeedList(seeds))
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
                    "[home test] "
                } else if style.is_held_out() {
                    "[held out] "
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
        TownsCommand::Procedural {
            seeds,
            bends,
            lights,
            out,
        } => {
            let family = Family {
                bends: bends.into(),
                lights: lights.into(),
            };
            for path in towngen::write_procedural(&out, seeds.0, family)? {
                let map = super::load_map(&path.to_string_lossy(), MapOptions::default())?;
                let size = map.bounds.1 - map.bounds.0;
                println!(
                    "{}: {:.0} x {:.0} m, {} junctions, {} lights",
                    path.display(),
                    size.x,
                    size.y,
                    map.junctions.len(),
                    map.lights.len()
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
