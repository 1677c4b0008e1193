//! What each fuzz target does with its input, in one place for the fuzzer (`tests/fuzz/`) and for the
//! main build's regression test, which replays every seed and every crash found. Each entry
//! hands arbitrary bytes to one parser of untrusted input through its public API and says whether
//! it was accepted; an `Err` is the expected answer to garbage, and any panic, hang or runaway
//! allocation is a bug.

use std::path::Path;

use sim_bridge::map::{Map, MapOptions};
use ssrdrive_proto::camera::{CameraSpec, Rig};
use ssrdrive_proto::v1;

/// What a fuzz target does with one input: whether the parser accepted it (the seeds must be
/// accepted, so that the fuzzer starts from inputs that reach past the first check).
pub type Entry = fn(&[u8]) -> bool;

/// The fuzz targets, by name: the folders of `tests/fuzz/seeds` and `tests/fuzz/regressions`.
pub const TARGETS: [(&str, Entry); 9] = [
    ("image_decode", image_decode),
    ("rig_json", rig_json),
    ("route_xml", route_xml),
    ("map_xodr", map_xodr),
    ("checkpoint", checkpoint),
    ("dataset_frames", dataset_frames),
    ("serve_toml", serve_toml),
    ("step_log", step_log),
    ("eval_results", eval_results),
];

/// A `Step` image for a camera of the input's choosing: byte 0 picks the encoding (RGB8,
/// BGRA8, PNG, JPEG), bytes 1-2 the size (1-64 px a side), the rest is the payload.
pub fn image_decode(data: &[u8]) -> bool {
    let [encoding, width, height, payload @ ..] = data else {
        return false;
    };
    let (width, height) = (u32::from(width % 64) + 1, u32::from(height % 64) + 1);
    let camera = CameraSpec {
        id: "cam".into(),
        width,
        height,
        ..CameraSpec::tcp_front()
    };
    let image = v1::Image {
        camera_id: camera.id.clone(),
        width,
        height,
        encoding: i32::from(encoding % 5),
        data: payload.to_vec(),
    };
    ssr_agent::serve::decode::decode_image(&image, &camera).is_ok()
}

/// A camera rig file (JSON).
pub fn rig_json(data: &[u8]) -> bool {
    std::str::from_utf8(data).is_ok_and(|text| Rig::from_json(text).is_ok())
}

/// A CARLA route file (XML).
pub fn route_xml(data: &[u8]) -> bool {
    std::str::from_utf8(data).is_ok_and(|text| sim_bridge::route::xml::parse("fuzz", text).is_ok())
}

/// An OpenDRIVE map, loaded into the lane graph with its lights and signs.
pub fn map_xodr(data: &[u8]) -> bool {
    std::str::from_utf8(data)
        .is_ok_and(|text| Map::from_str("fuzz", text, MapOptions::default()).is_ok())
}

/// A checkpoint file (safetensors with the network's config in its metadata), and the
/// controller settings and rig its metadata carries.
pub fn checkpoint(data: &[u8]) -> bool {
    let device = Default::default();
    ssr_agent::checkpoint::load_bytes(data, Path::new("fuzz"), &device).is_ok_and(|(_, info)| {
        let control = ssr_agent::checkpoint::control_config(&info);
        let rig = ssr_agent::checkpoint::rig(&info);
        control.is_ok() && rig.is_ok()
    })
}

/// A dataset episode's `measurements.jsonl`.
pub fn dataset_frames(data: &[u8]) -> bool {
    ssrdrive_proto::dataset::parse_frames(data, Path::new("fuzz")).is_ok()
}

/// A server config file (TOML), parsed and checked.
pub fn serve_toml(data: &[u8]) -> bool {
    std::str::from_utf8(data).is_ok_and(|text| {
        ssr_agent::serve::ServeConfig::from_toml(text, Path::new("fuzz"))
            .is_ok_and(|config| config.validate().is_ok())
    })
}

/// A step log (`sim-bridge eval --record`), as `sim-bridge replay` reads it.
pub fn step_log(data: &[u8]) -> bool {
    sim_bridge::replay::log::parse_log(data, Path::new("fuzz")).is_ok()
}

/// A results file, as `sim-bridge eval --resume` reads it.
pub fn eval_results(data: &[u8]) -> bool {
    std::str::from_utf8(data)
        .is_ok_and(|text| sim_bridge::scoring::Results::from_json(text).is_ok())
}
