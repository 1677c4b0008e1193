//! Maps over the agent's BEV grid from its debug block, as pictures that `sim-bridge render` puts
//! beside the camera and top-down views: the scene tokens' attention, one heat map per token in
//! a square grid (SSR's paper shows the same in its Figure 4), and the occupancy head's
//! vehicles and walkers in one map.
//!
//! Maps are in the ego frame as the agent sends them: the far front at the top, the car's left
//! on the left. Each token map is scaled to its own largest weight, on a square-root scale so
//! that weak attention still shows: the picture shows where each token looks, not how strongly
//! one token looks compared with another. Occupancy is a probability and is drawn as one.

use ssrdrive_proto::image::RgbImage;
use ssrdrive_proto::v1::TokenMap;

/// Pixels between two maps and around the grid.
const GAP: u32 = 2;
/// The colour between the maps.
const BACKGROUND: [u8; 3] = [40, 40, 40];
/// The heat scale, from no attention to a map's largest weight (after matplotlib's inferno).
const RAMP: [[f32; 3]; 5] = [
    [0.0, 0.0, 4.0],
    [87.0, 16.0, 110.0],
    [188.0, 55.0, 84.0],
    [249.0, 142.0, 9.0],
    [252.0, 255.0, 164.0],
];

/// `maps` in a grid of ceil(sqrt(n)) columns inside a `side`-pixel square (see the module doc),
/// or why they cannot be drawn: no maps, or a map whose weights do not fill its rows x cols.
pub fn token_panel(maps: &[TokenMap], side: u32) -> Result<RgbImage, String> {
    check("token", maps)?;
    let per_row = (maps.len() as f64).sqrt().ceil() as u32;
    let cell = side.saturating_sub(GAP) / per_row;
    if cell <= GAP {
        return Err(format!(
            "{side} px is too small for {} token maps",
            maps.len()
        ));
    }
    let mut rgb = vec![0u8; (side * side * 3) as usize];
    for pixel in rgb.chunks_exact_mut(3) {
        pixel.copy_from_slice(&BACKGROUND);
    }
    let inner = cell - GAP;
    for (k, map) in maps.iter().enumerate() {
        let (x0, y0) = (
            GAP + (k as u32 % per_row) * cell,
            GAP + (k as u32 / per_row) * cell,
        );
        let top = map.weights.iter().copied().fold(0.0f32, f32::max);
        for y in 0..inner {
            let row = (y * map.rows / inner) as usize;
            for x in 0..inner {
                let col = (x * map.cols / inner) as usize;
                let weight = map.weights[row * map.cols as usize + col];
                let level = if top > 0.0 {
                    (weight / top).sqrt()
                } else {
                    0.0
                };
                let at = (((y0 + y) * side + x0 + x) * 3) as usize;
                rgb[at..at + 3].copy_from_slice(&heat(level));
            }
        }
    }
    Ok(RgbImage {
        width: side,
        height: side,
        rgb,
    })
}

/// Vehicle occupancy's colour at probability 1 (walkers': [`WALKER`]).
const VEHICLE: [f32; 3] = [255.0, 90.0, 40.0];
/// Walker occupancy's colour at probability 1.
const WALKER: [f32; 3] = [60.0, 220.0, 255.0];

/// The occupancy head's `[vehicle, walker]` maps as one `side`-pixel square: each cell blends
/// from the background towards [`VEHICLE`] by the vehicle probability, then towards [`WALKER`]
/// by the walker probability; or why they cannot be drawn (not two maps of one grid).
pub fn occupancy_panel(maps: &[TokenMap], side: u32) -> Result<RgbImage, String> {
    check("occupancy", maps)?;
    let [vehicle, walker] = maps else {
        return Err(format!(
            "{} occupancy maps, not 2 (vehicle, walker)",
            maps.len()
        ));
    };
    if (vehicle.rows, vehicle.cols) != (walker.rows, walker.cols) || side == 0 {
        return Err("the occupancy maps differ in size".into());
    }
    let (rows, cols) = (vehicle.rows, vehicle.cols);
    let mut rgb = Vec::with_capacity((side * side * 3) as usize);
    for y in 0..side {
        let row = y * rows / side;
        for x in 0..side {
            let at = (row * cols + x * cols / side) as usize;
            let (v, w) = (unit(vehicle.weights[at]), unit(walker.weights[at]));
            for c in 0..3 {
                let base = BACKGROUND[c] as f32;
                let with_vehicle = base + v * (VEHICLE[c] - base);
                rgb.push((with_vehicle + w * (WALKER[c] - with_vehicle)).round() as u8);
            }
        }
    }
    Ok(RgbImage {
        width: side,
        height: side,
        rgb,
    })
}

/// The most rows or columns a map may have: the agent's BEV grid is far smaller, and the cap
/// keeps the pixel arithmetic on a server's sizes within `u32`.
const MAX_CELLS_PER_SIDE: u32 = 4096;

/// Every map fills its rows x cols (each 1..=[`MAX_CELLS_PER_SIDE`]) and there is one; else
/// which does not, named by `what`.
fn check(what: &str, maps: &[TokenMap]) -> Result<(), String> {
    if maps.is_empty() {
        return Err(format!("the debug block has no {what} maps"));
    }
    for (k, map) in maps.iter().enumerate() {
        let sides = 1..=MAX_CELLS_PER_SIDE;
        if !sides.contains(&map.rows) || !sides.contains(&map.cols) {
            return Err(format!(
                "{what} map {k} is {} x {} cells, outside 1..{MAX_CELLS_PER_SIDE} a side",
                map.rows, map.cols
            ));
        }
        if map.weights.len() != (map.rows * map.cols) as usize {
            return Err(format!(
                "{what} map {k} has {} weights for {} x {} cells",
                map.weights.len(),
                map.rows,
                map.cols
            ));
        }
    }
    Ok(())
}

/// `value` clamped to [0, 1] (NaN is 0).
fn unit(value: f32) -> f32 {
    if value.is_nan() {
        0.0
    } else {
        value.clamp(0.0, 1.0)
    }
}

/// The ramp's colour at `level` in [0, 1] (clamped; NaN is 0).
fn heat(level: f32) -> [u8; 3] {
    let at = unit(level) * (RAMP.len() - 1) as f32;
    let i = (at as usize).min(RAMP.len() - 2);
    let t = at - i as f32;
    std::array::from_fn(|c| (RAMP[i][c] + t * (RAMP[i + 1][c] - RAMP[i][c])).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(rows: u32, cols: u32, hot: usize) -> TokenMap {
        let mut weights = vec![0.0; (rows * cols) as usize];
        weights[hot] = 0.5;
        TokenMap {
            rows,
            cols,
            weights,
        }
    }

    #[test]
    fn each_token_is_drawn_in_its_grid_cell_with_its_hot_spot_bright() {
        // Four 2x2 maps in a 2x2 grid of 2 + 2 * 51 = 104 px: token k's hot cell is cell k.
        let maps: Vec<TokenMap> = (0..4).map(|k| map(2, 2, k)).collect();
        let panel = token_panel(&maps, 104).unwrap();
        assert_eq!((panel.width, panel.height), (104, 104));
        let pixel = |x: u32, y: u32| {
            let at = ((y * 104 + x) * 3) as usize;
            [panel.rgb[at], panel.rgb[at + 1], panel.rgb[at + 2]]
        };
        let bright = heat(1.0);
        let dark = heat(0.0);
        for k in 0..4u32 {
            let (x0, y0) = (GAP + (k % 2) * 51, GAP + (k / 2) * 51);
            // The map's cell k (row k / 2, column k % 2) is bright, the opposite one dark.
            let quarter = |c: u32| (x0 + (c % 2) * 24 + 12, y0 + (c / 2) * 24 + 12);
            let (x, y) = quarter(k);
            assert_eq!(pixel(x, y), bright, "token {k}");
            let (x, y) = quarter(3 - k);
            assert_eq!(pixel(x, y), dark, "token {k}");
        }
        assert_eq!(pixel(0, 0), BACKGROUND);
    }

    #[test]
    fn malformed_or_missing_maps_are_named() {
        assert!(token_panel(&[], 100).unwrap_err().contains("no token maps"));
        let mut short = map(2, 2, 0);
        short.weights.pop();
        let error = token_panel(&[map(2, 2, 0), short], 100).unwrap_err();
        assert!(
            error.contains("token map 1 has 3 weights for 2 x 2"),
            "{error}"
        );
        assert!(
            token_panel(&[map(2, 2, 0)], 3)
                .unwrap_err()
                .contains("too small")
        );
        // 65536 x 65536 cells wrap to 0 in u32: without the cap, no weights would pass.
        let huge = TokenMap {
            rows: 65536,
            cols: 65536,
            weights: Vec::new(),
        };
        let error = token_panel(std::slice::from_ref(&huge), 100).unwrap_err();
        assert!(error.contains("65536 x 65536 cells"), "{error}");
        let error = occupancy_panel(&[huge.clone(), huge], 100).unwrap_err();
        assert!(
            error.contains("occupancy map 0 is 65536 x 65536 cells"),
            "{error}"
        );
        let error = occupancy_panel(&[map(2, 2, 0), map(1, 4, 0)], 100).unwrap_err();
        assert!(error.contains("differ in size"), "{error}");
    }

    #[test]
    fn occupancy_is_drawn_by_probability_in_its_channel_colour() {
        // A 2x2 grid: a vehicle certain in the top-left cell, a walker in the bottom-right.
        let map = |hot: usize| TokenMap {
            rows: 2,
            cols: 2,
            weights: (0..4).map(|k| if k == hot { 1.0 } else { 0.0 }).collect(),
        };
        let panel = occupancy_panel(&[map(0), map(3)], 10).unwrap();
        let pixel = |x: u32, y: u32| {
            let at = ((y * 10 + x) * 3) as usize;
            [panel.rgb[at], panel.rgb[at + 1], panel.rgb[at + 2]]
        };
        assert_eq!(pixel(1, 1), VEHICLE.map(|v| v as u8));
        assert_eq!(pixel(8, 8), WALKER.map(|v| v as u8));
        assert_eq!(pixel(8, 1), BACKGROUND);
        let error = occupancy_panel(&[map(0)], 10).unwrap_err();
        assert!(error.contains("1 occupancy maps, not 2"), "{error}");
    }

    #[test]
    fn the_ramp_runs_from_dark_to_bright_and_clamps() {
        assert_eq!(heat(0.0), [0, 0, 4]);
        assert_eq!(heat(1.0), [252, 255, 164]);
        assert_eq!(heat(2.0), heat(1.0));
        assert_eq!(heat(f32::NAN), heat(0.0));
        let sum = |c: [u8; 3]| c.iter().map(|&v| v as u32).sum::<u32>();
        assert!(sum(heat(0.25)) < sum(heat(0.5)) && sum(heat(0.5)) < sum(heat(0.75)));
    }
}
