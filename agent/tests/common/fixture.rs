//! A tiny expert dataset written in the `sim-bridge collect` format: straight drives at a
//! different speed per route, with camera frames whose brightness tells the speed, so a few
//! optimiser steps visibly lower the loss.

use std::collections::BTreeMap;
use std::path::Path;

use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::{
    ActorClass, ActorRecord, EpisodeEntry, EpisodeInfo, EpisodeOutcome, FrameRecord, LightAhead,
    Manifest, NoiseConfig, TownCount, safe_name,
};
use ssrdrive_proto::image::encode_png;

use super::rig;

pub const FIXTURE_ROUTES: usize = 8;
pub const FIXTURE_FRAMES: usize = 10;
pub const FIXTURE_SIZE: (u32, u32) = (64, 32);

/// Writes the fixture under `root` and returns its manifest.
pub fn write_fixture_dataset(root: &Path) -> Manifest {
    let (width, height) = FIXTURE_SIZE;
    let camera_rig = rig(1, width, height);
    let mut episode_list = Vec::new();
    for route in 0..FIXTURE_ROUTES {
        let name = format!("fixture__fixture__{route}__r0");
        let dir = root.join("episodes").join(safe_name(&name));
        std::fs::create_dir_all(dir.join("cam0")).unwrap();
        let speed = 2.0 + route as f64;
        let throttle = 0.2 + 0.08 * route as f32;
        let control = Control {
            steer: 0.05 * route as f32 - 0.2,
            throttle,
            brake: 0.0,
        };
        let mut lines = String::new();
        for index in 0..FIXTURE_FRAMES {
            let time = index as f64 * 0.5;
            let shade = (30 * route) as u8 + (index * 2) as u8;
            let rgb: Vec<u8> = (0..width * height)
                .flat_map(|p| [shade, shade / 2, (p % 256) as u8])
                .collect();
            let image = format!("cam0/{index:06}.png");
            std::fs::write(dir.join(&image), encode_png(width, height, &rgb).unwrap()).unwrap();
            let record = FrameRecord {
                index,
                tick: index as u64 * 10,
                time,
                speed,
                position: [speed * time, 0.0, 0.0],
                yaw: 0.0,
                command: 4,
                target_point: [30.0, 0.0],
                control,
                executed: control,
                noise: false,
                brake_reason: None,
                waypoints: (1..=6).map(|k| [speed * 0.5 * k as f64, 0.0]).collect(),
                // The plan leads 0.25 m to the left of where the car went, so a test can
                // tell which labels it trained on.
                plan: (1..=6).map(|k| [speed * 0.5 * k as f64, 0.25]).collect(),
                future_controls: vec![control; 6],
                future_complete: true,
                images: vec![image],
                // A car ahead in the even routes; the odd ones record no actors, as datasets
                // from before they were recorded.
                actors: (route % 2 == 0).then(|| {
                    vec![ActorRecord {
                        class: ActorClass::Vehicle,
                        centre: [12.0 - index as f64, 0.0],
                        yaw: 0.0,
                        half: [2.4, 1.0],
                    }]
                }),
                // The even routes approach a red light 20 m ahead; the odd ones record none,
                // as datasets from before the label.
                light: (route % 2 == 0).then_some(LightAhead::Red {
                    distance: 20.0 - index as f64,
                }),
                light_in_view: (route % 2 == 0).then_some(true),
            };
            lines.push_str(&serde_json::to_string(&record).unwrap());
            lines.push('\n');
        }
        std::fs::write(dir.join("measurements.jsonl"), lines).unwrap();
        let info = EpisodeInfo {
            name: name.clone(),
            town: "fixture".into(),
            route_set: "fixture".into(),
            route_id: route.to_string(),
            repetition: 0,
            seed: route as u64,
            rig: camera_rig.clone(),
            rate_hz: 2.0,
            ticks_per_frame: 10,
            noise: NoiseConfig::default(),
            driver: None,
            randomise_appearance: false,
            frames: FIXTURE_FRAMES,
            truncated_frames: 0,
            bytes: 0,
            outcome: EpisodeOutcome {
                status: "Completed".into(),
                route_completion: 100.0,
                driving_score: 100.0,
                sim_seconds: FIXTURE_FRAMES as f64 * 0.5,
            },
            wall_seconds: 0.0,
        };
        std::fs::write(
            dir.join("episode.json"),
            serde_json::to_string(&info).unwrap(),
        )
        .unwrap();
        episode_list.push(EpisodeEntry {
            name,
            town: "fixture".into(),
            route_set: "fixture".into(),
            route_id: route.to_string(),
            frames: FIXTURE_FRAMES,
        });
    }
    let frames = FIXTURE_ROUTES * FIXTURE_FRAMES;
    let manifest = Manifest {
        format: ssrdrive_proto::dataset::FORMAT.into(),
        version: ssrdrive_proto::dataset::VERSION,
        rig: camera_rig,
        rate_hz: 2.0,
        future_step_s: 0.5,
        future_count: 6,
        episodes: FIXTURE_ROUTES,
        frames,
        truncated_frames: 0,
        bytes: 0,
        towns: BTreeMap::from([(
            "fixture".to_string(),
            TownCount {
                episodes: FIXTURE_ROUTES,
                frames,
            },
        )]),
        episode_list,
    };
    std::fs::write(
        root.join("manifest.json"),
        serde_json::to_string_pretty(&manifest).unwrap(),
    )
    .unwrap();
    manifest
}
