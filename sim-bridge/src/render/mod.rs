//! Pictures: camera frames through a rig (a CPU rasterizer: [`cameras`] over [`scene`],
//! [`actors`], [`shapes`], [`raster`] and [`style`]), top-down PNGs of route runs for
//! people ([`topdown`] on [`canvas`]), and a served agent's BEV maps: token attention and
//! occupancy ([`bev_maps`]).

pub mod actors;
pub mod bev_maps;
pub mod cameras;
pub mod canvas;
pub mod raster;
pub mod scene;
pub mod shapes;
pub mod style;
pub mod topdown;

pub use cameras::{CameraRenderer, SceneState};
pub use style::Appearance;
