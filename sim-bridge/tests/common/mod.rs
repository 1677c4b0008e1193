//! Helpers shared by the integration tests.

use std::path::PathBuf;

/// ../shared/carla beside the checkout, if present; prints a skip notice otherwise (the CARLA
/// maps and routes are never copied into the repository).
pub fn carla_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/carla");
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "SKIP: {} not found; CARLA map and route tests skipped",
            dir.display()
        );
        None
    }
}
