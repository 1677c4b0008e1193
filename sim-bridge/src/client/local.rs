//! [`LocalServer`]: an `ssr-agent serve` child process on a free loopback port, for
//! `sim-bridge eval --agent local`. The binary is `$SSR_AGENT_BIN`, else the `ssr-agent` beside
//! this executable (where `cargo build` puts both), else one on `PATH`. The child inherits the
//! environment, so `SSR_AGENT_CHECKPOINT` or `SSR_AGENT_UNTRAINED_CONFIG` choose its model; it
//! logs warnings and errors only unless `RUST_LOG` says otherwise, and is killed on drop. It
//! also ends with this process however that ends: it holds the write end of the child's
//! standard input, which the child (`--exit-with-stdin`) watches, so a killed `sim-bridge` leaves
//! no server running.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use crate::driver::AgentError;

/// What a local server is started for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LocalRole {
    /// Driving or re-feeding runs (`eval`, `collect --driver`, `replay`): one step per forward
    /// pass (`SSR_AGENT_MAX_BATCH=1` unless the environment sets it). Batched kernels round
    /// differently from single ones, and closed loop amplifies the difference, so a run would
    /// otherwise depend on which other runs' steps happened to share its batch; this way
    /// `--jobs N` gives the results of one run at a time. It gets one model thread per run
    /// driven at once, each with a pool of its share of the cores (`SSR_AGENT_MODEL_THREADS`
    /// and `SSR_AGENT_COMPUTE_THREADS`, unless the environment sets them), so the runs' steps
    /// go through the network side by side. No metrics port.
    Driving {
        /// Runs driven at once.
        runs: usize,
    },
    /// `load`: the server batches as configured, and opens a metrics port.
    LoadTest,
}

/// A running local server.
pub struct LocalServer {
    child: Child,
    address: String,
    metrics: Option<String>,
}

fn find_binary() -> Result<PathBuf, AgentError> {
    if let Some(path) = std::env::var_os("SSR_AGENT_BIN") {
        return Ok(PathBuf::from(path));
    }
    let name = format!("ssr-agent{}", std::env::consts::EXE_SUFFIX);
    let beside = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join(&name)));
    if let Some(path) = beside.filter(|p| p.is_file()) {
        return Ok(path);
    }
    std::env::var_os("PATH")
        .and_then(|paths| {
            std::env::split_paths(&paths)
                .map(|dir| dir.join(&name))
                .find(|p| p.is_file())
        })
        .ok_or_else(|| {
            AgentError(
                "no ssr-agent binary beside sim-bridge or on PATH: build it with \
                 `cargo build --release` (it builds both) or set SSR_AGENT_BIN"
                    .into(),
            )
        })
}

/// The addresses a server prints: `listening on ADDR`, then `metrics on URL` when asked.
fn read_addresses(
    lines: &mut impl Iterator<Item = String>,
    metrics: bool,
) -> Option<(String, Option<String>)> {
    let address = lines.find_map(|line| line.strip_prefix("listening on ").map(str::to_string))?;
    let metrics_url = if metrics {
        lines.find_map(|line| line.strip_prefix("metrics on ").map(str::to_string))
    } else {
        None
    };
    Some((address, metrics_url))
}

impl LocalServer {
    /// Starts `ssr-agent serve` on 127.0.0.1 with a free port, set up for `role`, and waits
    /// until it has bound its ports (not until it is warmed up: clients check health).
    pub fn start(role: LocalRole) -> Result<Self, AgentError> {
        let binary = find_binary()?;
        let mut command = Command::new(&binary);
        let metrics = role == LocalRole::LoadTest;
        let metrics_listen = if metrics { "127.0.0.1:0" } else { "off" };
        command
            .args(["serve", "--listen", "127.0.0.1:0"])
            .args(["--metrics-listen", metrics_listen, "--exit-with-stdin"])
            // Kept open in `child.stdin` for the child's life; closed when this process ends.
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        if std::env::var_os("RUST_LOG").is_none() {
            command.env("RUST_LOG", "warn");
        }
        if let LocalRole::Driving { runs } = role {
            // At most the server's 64 model threads.
            let runs = runs.clamp(1, 64);
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            let settings = [
                ("SSR_AGENT_MAX_BATCH", 1),
                ("SSR_AGENT_MODEL_THREADS", runs),
                ("SSR_AGENT_COMPUTE_THREADS", (cores / runs).max(1)),
            ];
            for (name, value) in settings {
                if std::env::var_os(name).is_none() {
                    command.env(name, value.to_string());
                }
            }
        }
        let mut child = command
            .spawn()
            .map_err(|e| AgentError(format!("starting {}: {e}", binary.display())))?;
        let stdout = child.stdout.take().expect("stdout is piped");
        let (sender, receiver) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut reader = BufReader::new(stdout);
            let mut lines = std::iter::from_fn(|| {
                let mut line = String::new();
                match reader.read_line(&mut line) {
                    Ok(0) | Err(_) => None,
                    Ok(_) => Some(line.trim_end().to_string()),
                }
            });
            let _ = sender.send(read_addresses(&mut lines, metrics));
            // Keep draining (any bytes) so the child never blocks on, or fails writing to, a
            // full or closed pipe.
            let _ = std::io::copy(&mut reader, &mut std::io::sink());
        });
        let mut server = Self {
            child,
            address: String::new(),
            metrics: None,
        };
        match receiver.recv_timeout(Duration::from_secs(60)) {
            Ok(Some((address, metrics))) => {
                server.address = address;
                server.metrics = metrics;
                Ok(server)
            }
            _ => {
                let status = server.child.try_wait().ok().flatten();
                Err(AgentError(format!(
                    "{} serve did not report its port{} (its log is above)",
                    binary.display(),
                    status
                        .map(|s| format!("; it exited with {s}"))
                        .unwrap_or_default()
                )))
            }
        }
    }
    /// `grpc://127.0.0.1:PORT`.
    pub fn target(&self) -> String {
        format!("grpc://{}", self.address)
    }

    /// `http://127.0.0.1:PORT/metrics`, when started with metrics.
    pub fn metrics_url(&self) -> Option<&str> {
        self.metrics.as_deref()
    }
}

impl Drop for LocalServer {
    /// SIGTERM first (the server drains and exits within a moment), SIGKILL after 5 s; nothing
    /// when it has already exited (its pid may belong to another process by then).
    fn drop(&mut self) {
        if let Ok(Some(_)) = self.child.try_wait() {
            return;
        }
        #[cfg(unix)]
        {
            let asked = Command::new("kill")
                .args(["-TERM", &self.child.id().to_string()])
                .status()
                .is_ok_and(|s| s.success());
            let deadline = std::time::Instant::now() + Duration::from_secs(5);
            while asked && std::time::Instant::now() < deadline {
                if let Ok(Some(_)) = self.child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
