//! Step logs and open-loop metrics through the public API: a log written and read back, a log
//! cut short keeps its whole ticks, corrupt or foreign files are refused with the reason, and
//! L2 / collision rate reproduce hand-computed cases.

use glam::DVec2;
use sim_bridge::replay::log::{LOG_FORMAT, LOG_VERSION, LogWriter, StepLog, read_log};
use sim_bridge::replay::metrics::open_loop;
use ssrdrive_proto::v1;

fn header() -> v1::LogHeader {
    v1::LogHeader {
        format: LOG_FORMAT.into(),
        version: LOG_VERSION,
        agent: "test".into(),
        route_id: "7".into(),
        tick_s: 0.05,
        ego_half_length: 2.0,
        ego_half_width: 1.0,
        ..Default::default()
    }
}

/// The ego driving east at 10 m/s; `actors` at every tick.
fn tick(index: usize, actors: Vec<v1::ActorBox>) -> v1::LogTick {
    v1::LogTick {
        request: Some(v1::StepRequest {
            frame_index: index as u64,
            ..Default::default()
        }),
        ego: Some(v1::Pose {
            x: index as f64 * 0.5,
            ..Default::default()
        }),
        actors,
        ..Default::default()
    }
}

#[test]
fn logs_round_trip_and_cut_logs_keep_their_whole_ticks() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("run.ssrlog");
    let mut writer = LogWriter::create(&path, header()).unwrap();
    for i in 0..5 {
        writer.tick(tick(i, Vec::new())).unwrap();
    }
    // Until finished, only the .partial file exists; it is readable all the same.
    let partial = path.with_extension("ssrlog.partial");
    assert!(partial.exists() && !path.exists());
    assert_eq!(writer.finish().unwrap(), path);
    let log = read_log(&path).unwrap();
    assert_eq!(log.header.route_id, "7");
    assert_eq!(log.ticks.len(), 5);
    assert!(!log.truncated);

    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
    let log = read_log(&path).unwrap();
    assert!(log.truncated);
    assert_eq!(log.ticks.len(), 4);

    // A whole record whose bytes are not a LogRecord.
    let mut corrupt = bytes.clone();
    corrupt.extend([3, 0xff, 0xff, 0xff]);
    std::fs::write(&path, &corrupt).unwrap();
    let error = read_log(&path).unwrap_err().to_string();
    assert!(error.contains("record 6 is corrupt"), "{error}");

    let mut foreign = header();
    foreign.version = 99;
    LogWriter::create(&path, foreign).unwrap().finish().unwrap();
    let error = read_log(&path).unwrap_err().to_string();
    assert!(error.contains("version 99"), "{error}");
    let mut instant_ticks = header();
    instant_ticks.tick_s = 1e-300;
    LogWriter::create(&path, instant_ticks)
        .unwrap()
        .finish()
        .unwrap();
    let error = read_log(&path).unwrap_err().to_string();
    assert!(error.contains("tick_s = 1e-300 s"), "{error}");
    std::fs::write(&path, b"").unwrap();
    assert!(
        read_log(&path)
            .unwrap_err()
            .to_string()
            .contains("no log header")
    );
    let missing = read_log(std::path::Path::new("/no/such.ssrlog")).unwrap_err();
    assert!(missing.to_string().contains("/no/such.ssrlog"));
}

#[test]
fn open_loop_metrics_match_hand_computed_cases() {
    // 3.5 s of driving east at 10 m/s; a parked car 15 m ahead, in the lane.
    let car = v1::ActorBox {
        id: 1,
        kind: "vehicle".into(),
        x: 15.0,
        y: 0.0,
        half_length: 2.0,
        half_width: 1.0,
        ..Default::default()
    };
    let log = StepLog {
        header: header(),
        ticks: (0..70).map(|i| tick(i, vec![car.clone()])).collect(),
        truncated: false,
    };
    // A perfect 2 s plan (10 m/s), and one that swerves 3 m left of the truth.
    let perfect: Vec<DVec2> = (1..=4).map(|k| DVec2::new(5.0 * k as f64, 0.0)).collect();
    let swerve: Vec<DVec2> = perfect.iter().map(|p| *p + DVec2::new(0.0, 3.0)).collect();
    let mut predictions = vec![perfect.clone(); 70];
    let metrics = open_loop(&log, &predictions);
    assert_eq!(metrics[0].horizon_s, 1.0);
    assert_eq!(metrics[0].samples, 50);
    assert!(metrics[0].l2_m.unwrap() < 1e-9);
    // A 2 s plan says nothing about 3 s.
    assert_eq!(metrics[2].samples, 0);
    assert_eq!(metrics[2].l2_m, None);

    // The car's box spans x 13..17 and the ego's is 4 m long, so a waypoint in [11, 19]
    // touches it. Plans from tick t reach 0.5 t + 5 and 0.5 t + 10 m within 1 s: ticks 2..=28
    // of the 50 with a 1 s future collide.
    assert!((metrics[0].collision_rate.unwrap() - 27.0 / 50.0).abs() < 1e-9);

    predictions[0] = swerve;
    let metrics = open_loop(&log, &predictions);
    assert!((metrics[0].l2_m.unwrap() - 3.0 / 50.0).abs() < 1e-9);
    let log_without_car = StepLog {
        ticks: (0..70).map(|i| tick(i, Vec::new())).collect(),
        ..log.clone()
    };
    let metrics = open_loop(&log_without_car, &vec![perfect; 70]);
    assert_eq!(metrics[0].collision_rate, Some(0.0));
    assert_eq!(metrics[1].collision_rate, Some(0.0));
}
