//! The server's plain-Rust parts through their public API: episode leases, config files and
//! rules, and image decoding. (The process end to end is in tests/tests/grpc.rs.)

mod common;

use std::time::{Duration, Instant};

use ssr_agent::device::Backend;
use ssr_agent::model::config::SsrConfig;
use ssr_agent::policy::SsrPolicy;
use ssr_agent::serve::ServeConfig;
use ssr_agent::serve::config::ServeConfigError;
use ssr_agent::serve::decode::decode_image;
use ssr_agent::serve::episodes::{Driver, EpisodeError, EpisodeTable};
use ssrdrive_proto::camera::{CameraSpec, Rig};
use ssrdrive_proto::v1;

fn policy() -> SsrPolicy {
    common::policy_of(common::tiny_config())
}

#[test]
fn a_lease_holds_the_state_until_finished_or_dropped() {
    let policy = policy();
    let table = EpisodeTable::new(2, Duration::from_secs(60));
    let id = table
        .open(Rig::tcp_small(), policy.new_episode(), Driver::Unary)
        .unwrap();
    let other = table
        .open(Rig::tcp_small(), policy.new_episode(), Driver::Unary)
        .unwrap();
    assert_ne!(id, other);
    assert_eq!(
        table.open(Rig::tcp_small(), policy.new_episode(), Driver::Unary),
        Err(EpisodeError::TooMany { open: 2 })
    );

    let lease = table.lease(&id, 0, Driver::Unary).unwrap();
    assert_eq!(lease.rig(), &Rig::tcp_small());
    assert!(matches!(
        table.lease(&id, 1, Driver::Unary),
        Err(EpisodeError::Busy(_))
    ));
    // Idle expiry never takes an episode with a step in flight.
    let far_future = Instant::now() + Duration::from_secs(3600);
    assert_eq!(table.expire_idle(far_future), vec![other.clone()]);
    drop(lease);
    // A dropped lease gives the state back without counting the frame.
    table.lease(&id, 0, Driver::Unary).unwrap().finish();
    assert!(matches!(
        table.lease(&id, 0, Driver::Unary),
        Err(EpisodeError::OutOfOrder {
            last: 0,
            got: 0,
            ..
        })
    ));
    table.lease(&id, 5, Driver::Unary).unwrap().finish();
    assert_eq!(table.close(&id, Driver::Unary), Ok(2));
    assert_eq!(
        table.close(&id, Driver::Unary),
        Err(EpisodeError::NotFound(id.clone()))
    );

    // Closing an episode mid-step discards the step's result quietly.
    let id = table
        .open(Rig::tcp_small(), policy.new_episode(), Driver::Unary)
        .unwrap();
    let lease = table.lease(&id, 0, Driver::Unary).unwrap();
    assert_eq!(table.close(&id, Driver::Unary), Ok(0));
    lease.finish();
    assert!(table.is_empty());
}

#[test]
fn episode_ids_are_unguessable_and_stream_episodes_refuse_unary_calls() {
    let policy = policy();
    let table = EpisodeTable::new(8, Duration::from_secs(60));
    let open = |driver| {
        table
            .open(Rig::tcp_small(), policy.new_episode(), driver)
            .unwrap()
    };
    let (a, b) = (open(Driver::Unary), open(Driver::Unary));
    for id in [&a, &b] {
        assert_eq!(id.len(), 32, "{id}");
        assert!(id.chars().all(|c| c.is_ascii_hexdigit()), "{id}");
    }
    // Random, not a counter: the two differ in many places.
    let differing = a.chars().zip(b.chars()).filter(|(x, y)| x != y).count();
    assert!(differing > 8, "{a} vs {b}");

    let streamed = open(Driver::Stream);
    let owned = EpisodeError::StreamOwned(streamed.clone());
    assert_eq!(
        table.lease(&streamed, 0, Driver::Unary).err(),
        Some(owned.clone())
    );
    assert_eq!(table.close(&streamed, Driver::Unary), Err(owned));
    table.lease(&streamed, 0, Driver::Stream).unwrap().finish();
    assert_eq!(table.close(&streamed, Driver::Stream), Ok(1));

    // A huge unknown id comes back clipped.
    let huge = "x".repeat(20_000);
    let error = table.lease(&huge, 0, Driver::Unary).err().unwrap();
    assert!(error.to_string().len() < 200, "{error}");
}

#[test]
fn config_files_override_defaults_and_bad_values_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let write_temp = |name: &str, text: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    let path = write_temp(
        "ok.toml",
        "max_batch = 4\nidle_timeout_s = 5.0\nlog_format = \"json\"\nbackend = \"wgpu\"\n",
    );
    let config = ServeConfig::from_file(&path).unwrap();
    assert_eq!(config.max_batch, 4);
    assert_eq!(config.backend, Backend::Wgpu);
    assert_eq!(config.idle_timeout_s, 5.0);
    assert_eq!(config.max_episodes, ServeConfig::default().max_episodes);
    config.validate().unwrap();

    // TOML has no null: no metrics is "off", as on the command line.
    let path = write_temp("no-metrics.toml", "metrics_listen = \"off\"\n");
    assert_eq!(ServeConfig::from_file(&path).unwrap().metrics_listen, None);
    let path = write_temp("metrics.toml", "metrics_listen = \"127.0.0.1:9999\"\n");
    let config = ServeConfig::from_file(&path).unwrap();
    assert_eq!(
        config.metrics_listen,
        Some("127.0.0.1:9999".parse().unwrap())
    );
    let path = write_temp("bad-metrics.toml", "metrics_listen = \"nowhere\"\n");
    let error = ServeConfig::from_file(&path).unwrap_err();
    assert!(
        error.to_string().contains("HOST:PORT") && error.to_string().contains("`off`"),
        "{error}"
    );
    // A host name is an address, in a file too.
    let path = write_temp("named.toml", "listen = \"localhost:0\"\n");
    let listen = ServeConfig::from_file(&path).unwrap().listen;
    assert!(listen.ip().is_loopback() && listen.port() == 0, "{listen}");

    let path = write_temp("typo.toml", "max_bach = 4\n");
    let error = ServeConfig::from_file(&path).unwrap_err();
    assert!(matches!(error, ServeConfigError::Parse { .. }));
    assert!(error.to_string().contains("max_bach"), "{error}");

    let bad = ServeConfig {
        max_batch: 0,
        ..ServeConfig::default()
    };
    assert_eq!(
        bad.validate().unwrap_err().to_string(),
        "max_batch = 0: must be in 1..=256"
    );
    // Each bad value is named with its field; durations too long for the clock are refused,
    // not a panic at start or at SIGTERM.
    let with = |change: fn(&mut ServeConfig)| {
        let mut config = ServeConfig::default();
        change(&mut config);
        config.validate().unwrap_err().to_string()
    };
    let refusals = [
        (
            with(|c| c.idle_timeout_s = f64::NAN),
            "idle_timeout_s = NaN",
        ),
        (
            with(|c| c.max_pixels_per_step = 0),
            "max_pixels_per_step = 0",
        ),
        (with(|c| c.max_decoded_mib = 0), "max_decoded_mib = 0"),
        (with(|c| c.compute_threads = 5000), "compute_threads = 5000"),
        (with(|c| c.idle_timeout_s = 1e308), "idle_timeout_s = 1e308"),
        (
            with(|c| c.request_timeout_s = 1e308),
            "request_timeout_s = 1e308",
        ),
        (with(|c| c.drain_grace_s = 1e308), "drain_grace_s = 1e308"),
        (
            with(|c| c.drain_timeout_s = 1e308),
            "drain_timeout_s = 1e308",
        ),
    ];
    for (error, named) in refusals {
        assert!(
            error.starts_with(&format!("{named}: must be in")),
            "{error}"
        );
    }
    let missing = ServeConfig::from_file(std::path::Path::new("/no/such/serve.toml"));
    assert!(
        missing
            .unwrap_err()
            .to_string()
            .contains("/no/such/serve.toml")
    );
}

fn camera(width: u32, height: u32) -> CameraSpec {
    CameraSpec {
        id: "front".into(),
        width,
        height,
        ..CameraSpec::tcp_front()
    }
}

fn image(encoding: v1::ImageEncoding, width: u32, height: u32, data: Vec<u8>) -> v1::Image {
    v1::Image {
        camera_id: "front".into(),
        width,
        height,
        encoding: encoding as i32,
        data,
    }
}

#[test]
fn images_decode_from_every_encoding_to_the_same_rgb() {
    let (w, h) = (4, 2);
    let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 256) as u8).collect();
    let spec = camera(w, h);

    let frame = decode_image(&image(v1::ImageEncoding::Rgb8, w, h, rgb.clone()), &spec).unwrap();
    assert_eq!(frame.rgb, rgb);

    let bgra: Vec<u8> = rgb
        .chunks_exact(3)
        .flat_map(|p| [p[2], p[1], p[0], 255])
        .collect();
    let frame = decode_image(&image(v1::ImageEncoding::Bgra8, w, h, bgra), &spec).unwrap();
    assert_eq!(frame.rgb, rgb);

    let png = ssrdrive_proto::image::encode_png(w, h, &rgb).unwrap();
    let frame = decode_image(&image(v1::ImageEncoding::Png, w, h, png.clone()), &spec).unwrap();
    assert_eq!(frame.rgb, rgb);

    // A 4x2 JPEG of one colour (200, 100, 50), quality 100: lossy, so within a few levels.
    let jpeg = include_bytes!("data/orange_4x2.jpg").to_vec();
    let frame = decode_image(&image(v1::ImageEncoding::Jpeg, w, h, jpeg.clone()), &spec).unwrap();
    for pixel in frame.rgb.chunks_exact(3) {
        for (got, want) in pixel.iter().zip([200u8, 100, 50]) {
            assert!(got.abs_diff(want) <= 3, "{pixel:?}");
        }
    }

    // Sizes are checked against the rig before any pixel memory is allocated.
    let error = decode_image(&image(v1::ImageEncoding::Png, w, h, png), &camera(8, 2)).unwrap_err();
    assert!(
        error
            .to_string()
            .contains("image is 4x2 but the rig says 8x2"),
        "{error}"
    );
    let error =
        decode_image(&image(v1::ImageEncoding::Jpeg, 8, 2, jpeg), &camera(8, 2)).unwrap_err();
    assert!(error.to_string().contains("JPEG is 4x2"), "{error}");
    let error =
        decode_image(&image(v1::ImageEncoding::Bgra8, w, h, vec![0; 12]), &spec).unwrap_err();
    assert!(
        error
            .to_string()
            .contains("BGRA8 image is 32 bytes, got 12"),
        "{error}"
    );
    let mut wrong_id = image(v1::ImageEncoding::Rgb8, w, h, rgb);
    wrong_id.camera_id = "rear".into();
    let error = decode_image(&wrong_id, &spec).unwrap_err();
    assert!(error.to_string().contains("'rear'"), "{error}");
    let unknown = v1::Image {
        encoding: 42,
        ..image(v1::ImageEncoding::Rgb8, w, h, vec![])
    };
    let error = decode_image(&unknown, &spec).unwrap_err();
    assert!(error.to_string().contains("encoding 42"), "{error}");
}

#[test]
fn the_safety_stop_follows_the_checkpoint_unless_told_and_needs_the_occupancy_head() {
    let device = Backend::Cpu.device().unwrap();
    let safety = |config: &ServeConfig| {
        let (policy, _) = ssr_agent::serve::load_policy(config, &device).unwrap();
        policy.control().safety.enabled
    };
    // The bundled checkpoint has the head and carries the stop on; a setting overrides it.
    assert!(safety(&ServeConfig::default()));
    let off = ServeConfig {
        safety_stop: Some(false),
        ..ServeConfig::default()
    };
    assert!(!safety(&off));
    // An untrained preset has the head but the default controller: off unless asked.
    let preset = ServeConfig {
        untrained_config: Some("cpu-default".into()),
        ..ServeConfig::default()
    };
    assert!(!safety(&preset));
    let asked = ServeConfig {
        safety_stop: Some(true),
        ..preset
    };
    assert!(safety(&asked));
    // A network without the head is refused, with what to do.
    let dir = tempfile::tempdir().unwrap();
    let headless = dir.path().join("headless.json");
    let mut config = SsrConfig::cpu_default();
    config.occupancy_head = false;
    std::fs::write(&headless, serde_json::to_string(&config).unwrap()).unwrap();
    let refused = ServeConfig {
        untrained_config: Some(headless.to_str().unwrap().into()),
        ..asked
    };
    let error = ssr_agent::serve::load_policy(&refused, &device)
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.contains("occupancy head") && error.contains("--safety-stop false"),
        "{error}"
    );
}
