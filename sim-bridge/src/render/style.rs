//! How camera frames look: the palette of every material, the sun, the sky and the sensor
//! noise. [`Appearance::default`] is the canonical look; [`Appearance::randomised`] draws a
//! varied one from a seed (colours, light, road tint, noise) for training robustness. Both are
//! pure data, so the same appearance always renders the same bytes.

use glam::Vec3;
use rand::{RngExt as _, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::map::surface::{Material, Paint};
use crate::world::WorldConfig;

/// An RGB colour with components in 0..=1.
pub type Rgb = Vec3;

/// Everything that decides the look of a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Appearance {
    /// Colour of [`Material::Driving`] surfaces.
    pub driving: Rgb,
    /// Colour of [`Material::Parking`] surfaces.
    pub parking: Rgb,
    /// Colour of [`Material::Sidewalk`] surfaces.
    pub sidewalk: Rgb,
    /// Colour of [`Material::Shoulder`] surfaces.
    pub shoulder: Rgb,
    /// Colour of [`Material::Grass`] surfaces.
    pub grass: Rgb,
    /// Colour of [`Paint::White`] road marks.
    pub white_paint: Rgb,
    /// Colour of [`Paint::Yellow`] road marks.
    pub yellow_paint: Rgb,
    /// Sky at the zenith.
    pub sky_top: Rgb,
    /// Sky at the horizon.
    pub sky_horizon: Rgb,
    /// Terrain near the camera.
    pub terrain_near: Rgb,
    /// Terrain in the distance (haze).
    pub terrain_far: Rgb,
    /// Unit vector towards the sun, world frame.
    pub sun: Vec3,
    /// Light reaching faces turned away from the sun, 0..1.
    pub ambient: f32,
    /// Overall brightness multiplier.
    pub exposure: f32,
    /// Car body colours, picked by actor id.
    pub car_colours: Vec<Rgb>,
    /// Standard deviation of the per-pixel sensor noise, in 0..255 units (0 = none).
    pub noise: f32,
    /// Seed of the sensor noise (mixed with the frame index).
    pub noise_seed: u64,
}

impl Default for Appearance {
    fn default() -> Self {
        let rgb = |r: u8, g: u8, b: u8| Vec3::new(r as f32, g as f32, b as f32) / 255.0;
        Self {
            driving: rgb(72, 72, 76),
            parking: rgb(92, 90, 88),
            sidewalk: rgb(160, 156, 148),
            shoulder: rgb(110, 106, 100),
            grass: rgb(84, 120, 60),
            white_paint: rgb(235, 235, 230),
            yellow_paint: rgb(230, 190, 40),
            sky_top: rgb(70, 120, 200),
            sky_horizon: rgb(190, 210, 230),
            terrain_near: rgb(96, 122, 70),
            terrain_far: rgb(150, 165, 150),
            sun: Vec3::new(0.4, 0.3, 0.87).normalize(),
            ambient: 0.55,
            exposure: 1.0,
            car_colours: vec![
                rgb(180, 30, 30),
                rgb(30, 60, 160),
                rgb(220, 220, 220),
                rgb(30, 30, 30),
                rgb(120, 120, 125),
                rgb(40, 120, 60),
                rgb(200, 160, 40),
                rgb(90, 50, 30),
            ],
            noise: 0.0,
            noise_seed: 0,
        }
    }
}

impl Appearance {
    /// The look camera frames of a world are drawn in: randomised from its seed when it asks
    /// for that, else the canonical one.
    pub fn of_world(config: &WorldConfig) -> Self {
        if config.randomise_appearance {
            Self::randomised(config.seed)
        } else {
            Self::default()
        }
    }

    /// A varied look drawn from `seed`: material colours and the road tint jittered, the sun
    /// anywhere above 20 degrees, exposure 0.75..1.2, sensor noise 0..6.
    pub fn randomised(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_a99e_a7a2_ce00);
        let base = Self::default();
        let mut jitter = |c: Rgb, amount: f32| -> Rgb {
            let scale = 1.0 + rng.random_range(-amount..amount);
            let tint = Vec3::new(
                rng.random_range(-0.04..0.04),
                rng.random_range(-0.04..0.04),
                rng.random_range(-0.04..0.04),
            );
            (c * scale + tint).clamp(Vec3::ZERO, Vec3::ONE)
        };
        let driving = jitter(base.driving, 0.25);
        let parking = jitter(base.parking, 0.2);
        let sidewalk = jitter(base.sidewalk, 0.15);
        let shoulder = jitter(base.shoulder, 0.2);
        let grass = jitter(base.grass, 0.25);
        let white_paint = jitter(base.white_paint, 0.1);
        let yellow_paint = jitter(base.yellow_paint, 0.1);
        let sky_top = jitter(base.sky_top, 0.2);
        let sky_horizon = jitter(base.sky_horizon, 0.1);
        let terrain_near = jitter(base.terrain_near, 0.25);
        let terrain_far = jitter(base.terrain_far, 0.15);
        let car_colours = base.car_colours.iter().map(|&c| jitter(c, 0.2)).collect();
        let azimuth = rng.random_range(0.0..std::f32::consts::TAU);
        let elevation = rng.random_range(20f32..75.0).to_radians();
        Self {
            driving,
            parking,
            sidewalk,
            shoulder,
            grass,
            white_paint,
            yellow_paint,
            sky_top,
            sky_horizon,
            terrain_near,
            terrain_far,
            sun: Vec3::new(
                elevation.cos() * azimuth.cos(),
                elevation.cos() * azimuth.sin(),
                elevation.sin(),
            ),
            ambient: rng.random_range(0.4..0.7),
            exposure: rng.random_range(0.75..1.2),
            car_colours,
            noise: rng.random_range(0.0..6.0),
            noise_seed: seed,
        }
    }

    /// Base colour of a surface material.
    pub fn material(&self, material: Material) -> Rgb {
        match material {
            Material::Driving => self.driving,
            Material::Parking => self.parking,
            Material::Sidewalk => self.sidewalk,
            Material::Shoulder => self.shoulder,
            Material::Grass => self.grass,
        }
    }

    /// Colour of road paint.
    pub fn paint(&self, paint: Paint) -> Rgb {
        match paint {
            Paint::White => self.white_paint,
            Paint::Yellow => self.yellow_paint,
        }
    }

    /// Body colour of the vehicle with this id (grey with an empty palette).
    pub fn car(&self, id: u32) -> Rgb {
        let k = (id as usize).wrapping_mul(2_654_435_761) >> 7;
        match self.car_colours.len() {
            0 => Vec3::splat(0.5),
            n => self.car_colours[k % n],
        }
    }

    /// A colour lit by the sun on a face with unit normal `normal`, packed as 0x00RRGGBB.
    pub fn shade(&self, colour: Rgb, normal: Vec3) -> u32 {
        let light = self.ambient + (1.0 - self.ambient) * normal.dot(self.sun).max(0.0);
        pack(colour * light * self.exposure)
    }

    /// A colour that emits its own light (lamps), packed.
    pub fn emissive(&self, colour: Rgb) -> u32 {
        pack(colour)
    }
}

/// Pack 0..1 RGB into 0x00RRGGBB, saturating.
pub fn pack(c: Rgb) -> u32 {
    let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u32;
    (q(c.x) << 16) | (q(c.y) << 8) | q(c.z)
}
