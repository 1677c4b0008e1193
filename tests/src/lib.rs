//! Helpers for the end-to-end tests in tests/tests/: the workspace's built binaries and a real
//! `ssr-agent serve` process on an ephemeral loopback port, killed when dropped, or one
//! [`SharedServer`] for every test of a test binary, killed when the binary exits; a valid
//! synthetic step; whether the Python-backed tests are skipped, and YAML read through Python.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, Once, OnceLock};
use std::time::{Duration, Instant};

use ssrdrive_proto::v1::agent_service_client::AgentServiceClient;
use ssrdrive_proto::{v1, wire};
use tonic::transport::Channel;
use tonic_health::pb::HealthCheckRequest;
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::health_client::HealthClient;

/// A valid step with flat grey frames for `rig`, the ego driving east at 5 m/s.
pub fn synthetic_step(episode_id: &str, frame_index: u64, rig: &v1::Rig) -> v1::StepRequest {
    v1::StepRequest {
        episode_id: episode_id.into(),
        frame_index,
        timestamp_s: frame_index as f64 * 0.05,
        images: wire::rgb_images(rig, |c| vec![100; (c.width * c.height * 3) as usize]),
        speed_mps: 5.0,
        pose: Some(v1::Pose {
            x: frame_index as f64 * 0.25,
            ..Default::default()
        }),
        command: 4,
        target_point: Some(v1::EgoPoint { x: 20.0, y: 0.0 }),
        debug: false,
    }
}

/// Whether SSRDRIVE_SKIP_PYTHON asks to skip the tests that need Python and its packages (from
/// tests/requirements.txt); says so for `what`.
pub fn python_skipped(what: &str) -> bool {
    let skipped = std::env::var_os("SSRDRIVE_SKIP_PYTHON").is_some();
    if skipped {
        eprintln!("SSRDRIVE_SKIP_PYTHON is set: {what} is skipped");
    }
    skipped
}

/// The YAML document at `path` as JSON, read with Python's yaml (from tests/requirements.txt).
pub fn yaml_as_json(path: &std::path::Path) -> serde_json::Value {
    let run = Command::new("python3")
        .args([
            "-c",
            "import json, sys, yaml; print(json.dumps(yaml.safe_load(open(sys.argv[1]))))",
        ])
        .arg(path)
        .output()
        .expect("python3 runs");
    assert!(
        run.status.success(),
        "{}: {}",
        path.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&run.stdout).expect("JSON from json.dumps")
}

/// A binary of this workspace, built by `cargo test --workspace` into the same profile folder
/// as this test (target/<profile>/).
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("tests run from target/<profile>/deps");
    let path = profile_dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(
        path.is_file(),
        "{} is missing: run the tests with `cargo test --workspace` (it builds every binary)",
        path.display()
    );
    path
}

/// A running `ssr-agent serve` with random cpu-default weights.
pub struct Server {
    child: Child,
    /// gRPC `HOST:PORT`.
    pub address: String,
    /// Metrics `HOST:PORT`.
    pub metrics: String,
}

impl Server {
    /// Starts a server with these extra flags and waits until it is SERVING.
    pub fn start(flags: &[&str]) -> Self {
        let mut child = Command::new(binary("ssr-agent"))
            .args([
                "serve",
                "--untrained-config",
                "cpu-default",
                "--listen",
                "127.0.0.1:0",
                "--metrics-listen",
                "127.0.0.1:0",
            ])
            .args(flags)
            .env("RUST_LOG", "error")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("starting ssr-agent serve");
        let mut lines = BufReader::new(child.stdout.take().expect("piped")).lines();
        let mut next = |prefix: &str| {
            let line = lines
                .next()
                .expect("the server printed its addresses")
                .expect("readable stdout");
            line.strip_prefix(prefix)
                .unwrap_or_else(|| panic!("expected '{prefix}...', got '{line}'"))
                .to_string()
        };
        let address = next("listening on ");
        let metrics = next("metrics on http://")
            .trim_end_matches("/metrics")
            .to_string();
        let server = Self {
            child,
            address,
            metrics,
        };
        server.wait_until_serving();
        server
    }

    fn wait_until_serving(&self) {
        let deadline = Instant::now() + Duration::from_secs(60);
        let runtime = runtime();
        loop {
            let serving = runtime.block_on(async {
                let mut health = HealthClient::new(self.channel().await);
                let reply = health.check(HealthCheckRequest::default()).await.ok()?;
                Some(reply.into_inner().status() == ServingStatus::Serving)
            });
            if serving == Some(true) {
                return;
            }
            assert!(Instant::now() < deadline, "server not SERVING within 60 s");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// `http://HOST:PORT` for tonic.
    pub fn uri(&self) -> String {
        format!("http://{}", self.address)
    }

    /// A connection to the server.
    pub async fn channel(&self) -> Channel {
        Channel::from_shared(self.uri())
            .expect("a valid URI")
            .connect()
            .await
            .expect("connecting to the server")
    }

    /// A connected agent client.
    pub async fn client(&self) -> AgentServiceClient<Channel> {
        AgentServiceClient::new(self.channel().await)
    }

    /// The metrics page.
    pub fn metrics_text(&self) -> String {
        let mut stream = TcpStream::connect(&self.metrics).expect("metrics port");
        write!(
            stream,
            "GET /metrics HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            self.metrics
        )
        .expect("sending the request");
        let mut text = String::new();
        stream.read_to_string(&mut text).expect("reading metrics");
        text
    }

    /// The value of one sample line of the metrics page (`name{labels}` exactly). A labelled
    /// sample no request has made yet reads 0 (the page lists a family's label sets only once
    /// they exist); an unlabelled metric the page does not declare is a panic, so a renamed or
    /// dropped gauge never reads as 0.
    pub fn metric(&self, sample: &str) -> f64 {
        let text = self.metrics_text();
        if !sample.contains('{') {
            let family = sample.strip_suffix("_total").unwrap_or(sample);
            assert!(
                text.lines()
                    .any(|line| line.starts_with(&format!("# TYPE {family} "))),
                "the metrics page does not declare {family}:\n{text}"
            );
        }
        text.lines()
            .find_map(|line| line.strip_prefix(sample)?.trim().parse().ok())
            .unwrap_or(0.0)
    }

    /// Polls `metric(sample)` every 50 ms until `reached(value)` or `within` has passed; the
    /// last value read. For what happens on the server after the call that caused it returned,
    /// or in another process's requests.
    pub fn wait_for_metric(
        &self,
        sample: &str,
        reached: impl Fn(f64) -> bool,
        within: Duration,
    ) -> f64 {
        let deadline = Instant::now() + within;
        loop {
            let value = self.metric(sample);
            if reached(value) || Instant::now() >= deadline {
                return value;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Sends SIGTERM and waits for the exit status.
    pub fn terminate(mut self) -> std::process::ExitStatus {
        let status = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .expect("running kill");
        assert!(status.success());
        self.child.wait().expect("waiting for the server")
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One server for all the tests of a test binary that use it: started on first use, killed when
/// the binary exits (a static is never dropped). Declare it as a `static` with its flags.
pub struct SharedServer {
    flags: &'static [&'static str],
    server: OnceLock<Server>,
}

/// Process ids of the shared servers to kill at exit.
static SHARED_PIDS: Mutex<Vec<u32>> = Mutex::new(Vec::new());

extern "C" fn kill_shared_servers() {
    let pids = SHARED_PIDS.lock().map(|p| p.clone()).unwrap_or_default();
    for pid in pids {
        // SAFETY: kill(2) only signals the process; a pid that is gone is an ignored error.
        unsafe { libc::kill(pid as libc::pid_t, libc::SIGKILL) };
    }
}

impl SharedServer {
    /// A server that will be started with these extra flags.
    pub const fn new(flags: &'static [&'static str]) -> Self {
        Self {
            flags,
            server: OnceLock::new(),
        }
    }

    /// The server, started on the first call.
    pub fn get(&'static self) -> &'static Server {
        self.server.get_or_init(|| {
            static AT_EXIT: Once = Once::new();
            // SAFETY: registers a plain function with no arguments, as atexit(3) requires.
            AT_EXIT.call_once(|| unsafe {
                libc::atexit(kill_shared_servers);
            });
            let server = Server::start(self.flags);
            SHARED_PIDS
                .lock()
                .expect("pid list")
                .push(server.child.id());
            server
        })
    }
}

/// A single-threaded runtime for blocking helpers.
pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("tokio runtime")
}
