//! How both command lines (`sim-bridge`, `ssr-agent`) log: events to stderr at a default level
//! that `RUST_LOG` overrides, one readable line or one JSON object (for log collectors) each;
//! colours only when stderr is a terminal (a redirected log file gets plain text).

/// Starts logging; does nothing when a subscriber is already installed (as in tests).
pub fn init(default_level: &str, json: bool) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_level));
    let terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(terminal)
        .with_writer(std::io::stderr);
    let _ = if json {
        logs.json().try_init()
    } else {
        logs.try_init()
    };
}
