//! The deterministic generator of the bundled towns.
//!
//! Each [`TownStyle`] is a layout (one file each: [`town05`], [`small`],
//! [`highway`], [`dense`], [`radial`]) declared on a [`builder::TownBuilder`]: junction
//! centres and the streets between them. The builder derives every
//! junction's connecting roads from its legs and places the traffic lights
//! and stop signs; [`emit`] writes the result as OpenDRIVE through the small
//! [`xml`] writer. Nothing is random, and numbers are printed with fixed
//! decimals, so [`generate`] gives the same bytes on every call.
//!
//! The generated documents are committed under `sim-bridge/towns/` and
//! compiled in by [`bundled`]; [`write_bundled`] regenerates them.
//! [`procedural`] adds families of training towns drawn from a seed (gentle and tight bends,
//! lights across the junction or at the kerb), written on request ([`write_procedural`])
//! rather than committed.

mod builder;
mod dense;
mod elevation;
mod emit;
mod geometry;
mod highway;
mod junction;
pub mod procedural;
mod profile;
mod radial;
mod signals;
mod small;
mod town;
mod town05;
mod xml;

#[cfg(test)]
mod tests;

use std::path::Path;

/// The bundled towns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TownStyle {
    /// The evaluation town, modelled on CARLA Town05: a grid of two-lane
    /// streets inside a three-lane ring road with an elevated stretch.
    Town05Style,
    /// A small training town of one-lane streets and T-junctions.
    SmallTJunctions,
    /// A training town: a highway loop with ramps to a local grid.
    Highway,
    /// A training town: a rotated grid of three- and two-lane streets.
    DenseMultiLane,
    /// A held-out town of its own layout family: two curved rings joined by spokes.
    HeldOutRadial,
}

impl TownStyle {
    /// Every style, the test town first.
    pub const ALL: [TownStyle; 5] = [
        TownStyle::Town05Style,
        TownStyle::SmallTJunctions,
        TownStyle::Highway,
        TownStyle::DenseMultiLane,
        TownStyle::HeldOutRadial,
    ];

    /// File stem, e.g. "ssr_town05" / "ssr_train_small" / "ssr_heldout_radial".
    pub fn name(self) -> &'static str {
        match self {
            Self::Town05Style => "ssr_town05",
            Self::SmallTJunctions => "ssr_train_small",
            Self::Highway => "ssr_train_highway",
            Self::DenseMultiLane => "ssr_train_dense",
            Self::HeldOutRadial => "ssr_heldout_radial",
        }
    }

    /// The style whose [`TownStyle::name`] is `name`.
    pub fn from_name(name: &str) -> Option<TownStyle> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// One line for `--help`/listings.
    pub fn description(self) -> &'static str {
        match self {
            Self::Town05Style => {
                "evaluation town like CARLA Town05: 470x400 m grid of 2-lane streets, 3-lane ring road with an elevated west side"
            }
            Self::SmallTJunctions => {
                "training town like CARLA Town01/02: 300x250 m of 1-lane streets, mostly T-junctions"
            }
            Self::Highway => {
                "training town like CARLA Town04/06: 600x350 m 3-lane highway loop with on/off ramps to a local grid"
            }
            Self::DenseMultiLane => {
                "training town: 350x300 m grid rotated 20 degrees, 3-lane avenues and 2-lane streets, large signalized junctions"
            }
            Self::HeldOutRadial => {
                "held-out town, in no training set: two curved rings (radius 95 and 230 m) joined by spokes, junctions at 60-120 degrees"
            }
        }
    }

    /// true only for Town05Style (the home evaluation town, a regression check).
    pub fn is_test_town(self) -> bool {
        self == Self::Town05Style
    }

    /// true for the towns of the held-out suite, which no training set may drive.
    pub fn is_held_out(self) -> bool {
        self == Self::HeldOutRadial
    }

    /// true for the towns training data is collected on.
    pub fn is_training_town(self) -> bool {
        !self.is_test_town() && !self.is_held_out()
    }
}

/// The OpenDRIVE document of a town. Deterministic: identical bytes on every call and platform.
pub fn generate(style: TownStyle) -> String {
    let town = match style {
        TownStyle::Town05Style => town05::build(),
        TownStyle::SmallTJunctions => small::build(),
        TownStyle::Highway => highway::build(),
        TownStyle::DenseMultiLane => dense::build(),
        TownStyle::HeldOutRadial => radial::build(),
    };
    emit::write_town(&town)
}

/// The committed copy, via include_str!("../../towns/<name>.xodr").
pub fn bundled(style: TownStyle) -> &'static str {
    match style {
        TownStyle::Town05Style => include_str!("../../towns/ssr_town05.xodr"),
        TownStyle::SmallTJunctions => include_str!("../../towns/ssr_train_small.xodr"),
        TownStyle::Highway => include_str!("../../towns/ssr_train_highway.xodr"),
        TownStyle::DenseMultiLane => include_str!("../../towns/ssr_train_dense.xodr"),
        TownStyle::HeldOutRadial => include_str!("../../towns/ssr_heldout_radial.xodr"),
    }
}

/// Write every town's document to `dir/<name>.xodr`, creating `dir`. This
/// regenerates the committed copies when given `sim-bridge/towns`.
pub fn write_bundled(dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    for style in TownStyle::ALL {
        std::fs::write(dir.join(format!("{}.xodr", style.name())), generate(style))?;
    }
    Ok(())
}

/// The OpenDRIVE document of the procedural training town of `seed` in `family`
/// ([`procedural`]).
pub fn generate_procedural(seed: u64, family: procedural::Family) -> String {
    emit::write_town(&procedural::build(seed, family))
}

/// Write the procedural towns of `seeds` in `family` to `dir/NAME.xodr` (`ssr_proc_NNN`,
/// `ssr_tight_NNN`, `ssr_tight_kerb_NNN`, ...), creating `dir`; returns the paths written.
pub fn write_procedural(
    dir: &Path,
    seeds: impl IntoIterator<Item = u64>,
    family: procedural::Family,
) -> std::io::Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    for seed in seeds {
        let path = dir.join(format!("{}.xodr", procedural::name(seed, family)));
        std::fs::write(&path, generate_procedural(seed, family))?;
        written.push(path);
    }
    Ok(written)
}
