//! `sim-bridge render`: drive routes with an agent and write what its cameras saw: one PNG per
//! camera every few ticks, and an animated PNG of the whole run with the camera view beside a
//! top-down view of the ego's surroundings.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use sim_bridge::agent::{Agent, AgentError, Observation, RouteContext};
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::render::topdown::local_view;
use sim_bridge::route::DenseRoute;
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::world::{DT, World};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::safe_name;
use ssrdrive_proto::image::{RgbImage, encode_png, write_apng};

use super::args::{PlannedRoute, RouteArgs, WorldArgs};

#[derive(Debug, Args)]
pub struct RenderArgs {
    #[command(flatten)]
    route: RouteArgs,
    #[command(flatten)]
    world: WorldArgs,
    /// Camera rig: a preset (`tcp`: TCP's 900x256 front camera; `tcp-small`: the same at
    /// 320x96) or a JSON rig file (a list of CARLA-style camera descriptions).
    #[arg(long, default_value = "tcp")]
    rig: String,
    /// Ticks (20 Hz) between two rendered frames: 10 gives 2 Hz.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    every: u64,
    /// Render at most this many frames per route (the run goes on unrendered).
    #[arg(long, default_value_t = 400)]
    max_frames: usize,
    /// Side of the top-down panel in the animation, pixels (0: as tall as the cameras).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=2048))]
    topdown: u32,
    /// Metres from the ego to the edge of the top-down panel.
    #[arg(long, default_value_t = 30.0)]
    topdown_radius: f64,
    /// Write only the per-camera PNGs, no animation.
    #[arg(long)]
    no_animation: bool,
    /// Output folder: one subfolder per route.
    #[arg(long, default_value = "renders")]
    out: PathBuf,
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    if !(args.topdown_radius.is_finite() && args.topdown_radius > 0.0) {
        bail!("--topdown-radius must be a positive number of metres");
    }
    let rig = Rig::from_name_or_file(&args.rig)?;
    let (map, planned) = args.route.load()?;
    for PlannedRoute { spec, dense } in &planned {
        let dir = args.out.join(safe_name(&format!("route_{}", spec.id)));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let mut film = Film {
            driver: Expert::new(),
            rig: rig.clone(),
            args: &args,
            dir: dir.clone(),
            route: None,
            frames: Vec::new(),
            written: 0,
            error: None,
        };
        let world = args.world.config(&map, args.world.seed);
        run_route(
            &map,
            spec,
            dense,
            &mut film,
            world,
            ScoringConfig::default(),
            0,
            0,
            |_| {},
        );
        if let Some(e) = film.error {
            return Err(e);
        }
        let mut summary = format!(
            "route {}: {} frames in {}",
            spec.id,
            film.written,
            dir.display()
        );
        if !args.no_animation && !film.frames.is_empty() {
            let path = dir.join("run.png");
            let delay = (args.every as f64 * DT * 1000.0).round() as u16;
            let file = std::fs::File::create(&path)
                .with_context(|| format!("creating {}", path.display()))?;
            write_apng(std::io::BufWriter::new(file), &film.frames, delay)
                .with_context(|| format!("writing {}", path.display()))?;
            summary += &format!(", animation {}", path.display());
        }
        println!("{summary}");
    }
    Ok(())
}

/// The driver, with every rendered frame written out and composed for the animation.
struct Film<'a> {
    driver: Expert,
    rig: Rig,
    args: &'a RenderArgs,
    dir: PathBuf,
    route: Option<DenseRoute>,
    frames: Vec<RgbImage>,
    written: usize,
    error: Option<anyhow::Error>,
}

impl Film<'_> {
    fn record(&mut self, obs: &Observation, world: &World<'_>) -> anyhow::Result<()> {
        for frame in &obs.frames {
            let path = self
                .dir
                .join(format!("{:06}_{}.png", obs.frame, frame.camera));
            let png = encode_png(frame.width, frame.height, &frame.rgb)?;
            write_file(&path, &png)?;
        }
        self.written += 1;
        if self.args.no_animation {
            return Ok(());
        }
        let Some(route) = &self.route else {
            return Ok(());
        };
        let cameras_width = obs.frames.iter().map(|f| f.width).max().unwrap_or(0);
        let cameras_height: u32 = obs.frames.iter().map(|f| f.height).sum();
        let side = match self.args.topdown {
            0 => cameras_height.max(128),
            side => side,
        };
        let panel = local_view(
            world.map,
            route,
            &world.ego_state(),
            &world.actors(),
            self.args.topdown_radius,
            side,
        );
        let (width, height) = (cameras_width + side, cameras_height.max(side));
        let stride = width as usize * 3;
        let mut rgb = vec![0u8; stride * height as usize];
        let mut blit = |x0: u32, y0: u32, w: u32, pixels: &[u8]| {
            for (row, line) in pixels.chunks_exact(w as usize * 3).enumerate() {
                let at = (y0 as usize + row) * stride + x0 as usize * 3;
                rgb[at..at + line.len()].copy_from_slice(line);
            }
        };
        let mut y = 0;
        for frame in &obs.frames {
            blit(0, y, frame.width, &frame.rgb);
            y += frame.height;
        }
        blit(cameras_width, 0, side, panel.pixels());
        self.frames.push(RgbImage { width, height, rgb });
        Ok(())
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

impl Agent for Film<'_> {
    fn name(&self) -> String {
        self.driver.name()
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.route = Some(ctx.route.clone());
        self.driver.start_route(ctx)
    }

    fn sensors(&self) -> Option<Rig> {
        Some(self.rig.clone())
    }

    fn wants_frames(&self, frame: u64) -> bool {
        frame.is_multiple_of(self.args.every) && self.written < self.args.max_frames
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        if !obs.frames.is_empty()
            && self.error.is_none()
            && let Err(e) = self.record(obs, world)
        {
            self.error = Some(e);
        }
        self.driver.run_step(obs, world)
    }
}
