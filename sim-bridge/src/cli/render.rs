//! `sim-bridge render`: drive routes with the expert or a served agent and write what the
//! cameras saw: one PNG per camera every few ticks, and an animated PNG of the whole run with the
//! camera view beside a top-down view of the ego's surroundings. A served agent's scene-token
//! attention maps and occupancy (its debug block, asked for on the rendered ticks) go beside
//! them, and each rendered tick's composite is also written as a still.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use sim_bridge::client::grpc::{GrpcAgent, GrpcOptions};
use sim_bridge::client::local::LocalRole;
use sim_bridge::driver::{Agent, AgentError, CameraFrame, Observation, RouteContext};
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::render::bev_maps::{occupancy_panel, token_panel};
use sim_bridge::render::canvas::label;
use sim_bridge::render::topdown::{Intent, local_view};
use sim_bridge::route::DenseRoute;
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::world::{DT, World};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::safe_name;
use ssrdrive_proto::image::{RgbImage, encode_png, write_apng};
use ssrdrive_proto::v1;

use super::args::{PlannedRoute, RouteArgs, WorldArgs, server_target};

#[derive(Debug, Args)]
pub struct RenderArgs {
    #[command(flatten)]
    route: RouteArgs,
    #[command(flatten)]
    world: WorldArgs,
    /// Who drives: `expert` (in process), `local` (starts `ssr-agent serve`; SSR_AGENT_*
    /// variables such as SSR_AGENT_CHECKPOINT configure it) or `grpc://HOST:PORT`. A served
    /// agent's scene-token attention maps go beside the views.
    #[arg(long, default_value = "expert")]
    agent: String,
    /// Camera rig: a preset (`tcp`: TCP's 900x256 front camera; `tcp-small`: the same at
    /// 320x96) or a JSON rig file (a list of CARLA-style camera descriptions) [default: `tcp`
    /// for the expert, the rig a served agent expects].
    #[arg(long)]
    rig: Option<String>,
    /// Ticks (20 Hz) between two rendered frames: 10 gives 2 Hz.
    #[arg(long, default_value_t = 10, allow_negative_numbers = true, value_parser = super::args::parse_count)]
    every: usize,
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
    /// End every route after this many simulated seconds instead of the leaderboard's
    /// length-based timeout (a short look at a long route).
    #[arg(long, value_parser = super::args::parse_positive)]
    timeout: Option<f64>,
    /// How long to wait for a served agent to report SERVING (a local one loads and warms up
    /// first), e.g. `120`, `2m`.
    #[arg(long, default_value = "120", value_parser = super::args::parse_seconds)]
    ready_timeout: std::time::Duration,
    /// Output folder: one subfolder per route.
    #[arg(long, default_value = "renders")]
    out: PathBuf,
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    if !(args.topdown_radius.is_finite() && args.topdown_radius > 0.0) {
        bail!("--topdown-radius must be a positive number of metres");
    }
    let rig = args
        .rig
        .as_deref()
        .map(Rig::from_name_or_file)
        .transpose()?;
    let (map, planned) = args.route.load()?;
    let (mut driver, _local_server) = match args.agent.as_str() {
        "expert" => (
            Driver::Expert(Expert::new(), rig.unwrap_or(Rig::tcp())),
            None,
        ),
        agent => {
            let (target, server) = server_target(agent, LocalRole::Driving { runs: 1 })?;
            let options = GrpcOptions {
                rig,
                ready_timeout: args.ready_timeout,
                client: "sim-bridge render".into(),
                ..GrpcOptions::default()
            };
            (
                Driver::Served(GrpcAgent::connect(&target, options)?),
                server,
            )
        }
    };
    for PlannedRoute { spec, dense } in &planned {
        let dir = args.out.join(safe_name(&format!("route_{}", spec.id)));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let mut film = Film {
            driver: &mut driver,
            args: &args,
            dir: dir.clone(),
            route: None,
            frames: Vec::new(),
            written: 0,
            error: None,
        };
        let world = args.world.config(&map, args.world.seed)?;
        let run = run_route(
            &map,
            spec,
            dense,
            &mut film,
            world,
            ScoringConfig {
                timeout: args.timeout,
                ..ScoringConfig::default()
            },
            0,
            0,
            |_| {},
        );
        if let Some(e) = film.error {
            return Err(e);
        }
        let mut summary = format!(
            "route {}: {} frames in {} ({})",
            spec.id,
            film.written,
            dir.display(),
            run.record.status
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

/// Who drives: the expert in process (with the rig to render), or an agent server.
#[expect(clippy::large_enum_variant, reason = "one driver per render run")]
enum Driver {
    Expert(Expert, Rig),
    Served(GrpcAgent),
}

impl Driver {
    fn agent(&self) -> &dyn Agent {
        match self {
            Driver::Expert(expert, _) => expert,
            Driver::Served(agent) => agent,
        }
    }

    fn agent_mut(&mut self) -> &mut dyn Agent {
        match self {
            Driver::Expert(expert, _) => expert,
            Driver::Served(agent) => agent,
        }
    }
}

/// The driver, with every rendered frame written out and composed for the animation.
struct Film<'a> {
    driver: &'a mut Driver,
    args: &'a RenderArgs,
    dir: PathBuf,
    route: Option<DenseRoute>,
    frames: Vec<RgbImage>,
    written: usize,
    error: Option<anyhow::Error>,
}

impl Film<'_> {
    /// Whether tick `frame` is one to render and write.
    fn renders(&self, frame: u64) -> bool {
        frame.is_multiple_of(self.args.every as u64) && self.written < self.args.max_frames
    }

    fn record(
        &mut self,
        obs: &Observation,
        world: &World<'_>,
        debug: Option<&v1::Debug>,
    ) -> anyhow::Result<()> {
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
        let stack_height: u32 = obs.frames.iter().map(|f| f.height).sum();
        let side = match self.args.topdown {
            0 => stack_height.max(128),
            side => side,
        };
        // Small cameras are enlarged (nearest pixel, whole factors) to the panels' height.
        let zoom = (side / stack_height.max(1)).max(1);
        let cameras: Vec<RgbImage> = obs.frames.iter().map(|f| enlarge(f, zoom)).collect();
        let plan = self.driver.agent().planned_trajectory();
        let intent = Intent {
            target_point: Some(obs.target_point),
            plan: &plan,
        };
        let topdown = local_view(
            world.map,
            route,
            &world.ego_state(),
            &world.visible_actors(),
            intent,
            self.args.topdown_radius,
            side,
        );
        let mut panels = vec![Panel {
            image: RgbImage {
                width: side,
                height: side,
                rgb: topdown.pixels().to_vec(),
            },
            title: "top-down, north up",
            key: "plan cyan, target magenta",
        }];
        let maps = match debug {
            Some(debug) => debug_panels(debug, side).map_err(|e| {
                anyhow::anyhow!("the agent's debug block at tick {}: {e}", obs.frame)
            })?,
            None => Vec::new(),
        };
        let with_maps = !maps.is_empty();
        panels.extend(maps);
        let names: Vec<String> = obs
            .frames
            .iter()
            .map(|f| format!("camera {}", f.camera))
            .collect();
        let RgbImage { width, height, rgb } = compose_view(&cameras, &names, &panels, side);
        if with_maps {
            let path = self.dir.join(format!("{:06}_view.png", obs.frame));
            write_file(&path, &encode_png(width, height, &rgb)?)?;
        }
        self.frames.push(RgbImage { width, height, rgb });
        Ok(())
    }
}

/// One square panel beside the cameras, with its title (top) and key (bottom), short enough
/// for a 288-pixel panel.
struct Panel {
    image: RgbImage,
    title: &'static str,
    key: &'static str,
}

/// The debug block's BEV maps, in the order the agent sent them: token attention, occupancy.
fn debug_panels(debug: &v1::Debug, side: u32) -> Result<Vec<Panel>, String> {
    let mut panels = Vec::new();
    if !debug.token_attention.is_empty() {
        panels.push(Panel {
            image: token_panel(&debug.token_attention, side)?,
            title: "token attention",
            key: "ego frame, ahead up",
        });
    }
    if !debug.occupancy.is_empty() {
        panels.push(Panel {
            image: occupancy_panel(&debug.occupancy, side)?,
            title: "occupancy",
            key: "vehicle orange, walker cyan",
        });
    }
    Ok(panels)
}

/// The cameras stacked on the left (each labelled with its name), then the `side`-pixel
/// panels left to right, each with its title and key.
fn compose_view(cameras: &[RgbImage], names: &[String], panels: &[Panel], side: u32) -> RgbImage {
    let cameras_width = cameras.iter().map(|f| f.width).max().unwrap_or(0);
    let cameras_height: u32 = cameras.iter().map(|f| f.height).sum();
    let (width, height) = (
        cameras_width + panels.len() as u32 * side,
        cameras_height.max(side),
    );
    let stride = width as usize * 3;
    let mut rgb = vec![0u8; stride * height as usize];
    let mut blit = |x0: u32, y0: u32, w: u32, pixels: &[u8]| {
        for (row, line) in pixels.chunks_exact(w as usize * 3).enumerate() {
            let at = (y0 as usize + row) * stride + x0 as usize * 3;
            rgb[at..at + line.len()].copy_from_slice(line);
        }
    };
    let mut y = 0;
    for frame in cameras {
        blit(0, y, frame.width, &frame.rgb);
        y += frame.height;
    }
    for (k, panel) in panels.iter().enumerate() {
        blit(cameras_width + k as u32 * side, 0, side, &panel.image.rgb);
    }
    let mut y = 0;
    for (image, name) in cameras.iter().zip(names) {
        label(&mut rgb, width, 2, y as i64 + 2, name);
        y += image.height;
    }
    for (k, panel) in panels.iter().enumerate() {
        let x = (cameras_width + k as u32 * side) as i64 + 2;
        label(&mut rgb, width, x, 2, panel.title);
        label(&mut rgb, width, x, height as i64 - 16, panel.key);
    }
    RgbImage { width, height, rgb }
}

/// `frame` with each pixel repeated `zoom` times across and down.
fn enlarge(frame: &CameraFrame, zoom: u32) -> RgbImage {
    let (width, height) = (frame.width * zoom, frame.height * zoom);
    let mut rgb = Vec::with_capacity((width * height * 3) as usize);
    for row in frame.rgb.chunks_exact(frame.width as usize * 3) {
        let line: Vec<u8> = row
            .chunks_exact(3)
            .flat_map(|pixel| pixel.repeat(zoom as usize))
            .collect();
        for _ in 0..zoom {
            rgb.extend_from_slice(&line);
        }
    }
    RgbImage { width, height, rgb }
}

fn write_file(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

impl Agent for Film<'_> {
    fn name(&self) -> String {
        self.driver.agent().name()
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.route = Some(ctx.route.clone());
        self.driver.agent_mut().start_route(ctx)
    }

    fn end_route(&mut self) {
        self.driver.agent_mut().end_route();
    }

    fn sensors(&self) -> Option<Rig> {
        match &*self.driver {
            Driver::Expert(_, rig) => Some(rig.clone()),
            Driver::Served(agent) => agent.sensors(),
        }
    }

    fn wants_frames(&self, frame: u64) -> bool {
        // A served agent drives from its cameras on every tick.
        matches!(&*self.driver, Driver::Served(_)) || self.renders(frame)
    }

    fn planned_trajectory(&self) -> Vec<glam::DVec2> {
        self.driver.agent().planned_trajectory()
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        let render = !obs.frames.is_empty() && self.renders(obs.frame);
        let (control, debug) = match &mut *self.driver {
            Driver::Expert(expert, _) => (expert.run_step(obs, world)?, None),
            Driver::Served(agent) => agent.step(obs, render)?,
        };
        if render
            && self.error.is_none()
            && let Err(e) = self.record(obs, world, debug.as_ref())
        {
            self.error = Some(e);
        }
        Ok(control)
    }
}
