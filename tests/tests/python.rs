//! The Python client and the CARLA leaderboard adapter (proto/python) against a real server:
//! runs their unittest suites with `python3`. Needs grpcio and grpcio-tools
//! (`pip install -r tests/requirements.txt`, part of the README's test command); set
//! SSRDRIVE_SKIP_PYTHON=1 to skip on a machine without them.

use std::path::Path;
use std::process::Command;

use ssrdrive_tests::{Server, python_skipped};

#[test]
fn python_client_and_carla_adapter_pass_their_suites() {
    if python_skipped("the Python client suite") {
        return;
    }
    let python_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../proto/python");
    let probe = Command::new("python3")
        .args(["-c", "import grpc, grpc_tools"])
        .output()
        .expect("python3 runs (set SSRDRIVE_SKIP_PYTHON=1 on a machine without it)");
    assert!(
        probe.status.success(),
        "grpcio is missing: pip install -r tests/requirements.txt \
         (or set SSRDRIVE_SKIP_PYTHON=1)\n{}",
        String::from_utf8_lossy(&probe.stderr)
    );
    let server = Server::start(&[]);
    let run = Command::new("python3")
        .args(["-m", "unittest", "discover", "-s", "tests", "-t", ".", "-v"])
        .current_dir(&python_dir)
        .env("SSRDRIVE_SERVER", &server.address)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("running python3 -m unittest");
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "Python suites failed:\n{log}");
    // Every test ran: none was skipped, and there were some (a suite that cannot be found
    // runs zero tests and still "succeeds").
    assert!(!log.contains("skipped="), "{log}");
    assert!(!log.contains("Ran 0 tests"), "{log}");
}

/// Every file under `root` (relative path), to check that nothing was written there.
fn files(root: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path.strip_prefix(root).unwrap().display().to_string());
            }
        }
    }
    out.sort();
    out
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let target = to.join(path.file_name().unwrap());
        if path.is_dir() {
            copy_tree(&path, &target);
        } else {
            std::fs::copy(&path, &target).unwrap();
        }
    }
}

/// Where `python3` finds the stubs with `env`, run from `cwd`.
fn stub_file(cwd: &Path, env: &[(&str, &Path)]) -> String {
    let run = Command::new("python3")
        .args([
            "-c",
            "from ssrdrive import AgentClient\nfrom ssrdrive.stubs import load\nprint(load()[0].__file__)",
        ])
        .current_dir(cwd)
        .envs(env.iter().map(|(k, v)| (*k, v.as_os_str())))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("python3 runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    String::from_utf8_lossy(&run.stdout).trim().to_string()
}

#[test]
fn the_client_installs_with_pip_and_writes_nothing_into_its_source() {
    if python_skipped("the Python packaging test") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let proto = tmp.path().join("proto");
    let repo_proto = Path::new(env!("CARGO_MANIFEST_DIR")).join("../proto");
    for part in ["ssrdrive", "python"] {
        copy_tree(&repo_proto.join(part), &proto.join(part));
    }
    // Pycache folders are the interpreter's, not ours; leave them out of the comparison.
    let source: Vec<String> = files(&proto)
        .into_iter()
        .filter(|f| !f.contains("__pycache__"))
        .collect();
    let target = tmp.path().join("installed");
    let install = Command::new("python3")
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-build-isolation",
            "--no-deps",
        ])
        .arg("--target")
        .arg(&target)
        .arg(proto.join("python"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("pip runs");
    assert!(
        install.status.success(),
        "{}",
        String::from_utf8_lossy(&install.stderr)
    );
    assert!(target.join("ssrdrive/v1/agent_pb2_grpc.py").is_file());
    // Installed: the stubs the build generated.
    let found = stub_file(tmp.path(), &[("PYTHONPATH", &target)]);
    assert!(found.starts_with(target.to_str().unwrap()), "{found}");
    // From the checkout: generated once into the stub cache, not beside the sources.
    let cache = tmp.path().join("stubs");
    let checkout = proto.join("python");
    let env: [(&str, &Path); 2] = [("PYTHONPATH", &checkout), ("SSRDRIVE_STUB_DIR", &cache)];
    let found = stub_file(tmp.path(), &env);
    assert!(found.starts_with(cache.to_str().unwrap()), "{found}");
    assert_eq!(stub_file(tmp.path(), &env), found);
    let after: Vec<String> = files(&proto)
        .into_iter()
        .filter(|f| !f.contains("__pycache__"))
        .collect();
    assert_eq!(
        after, source,
        "the build or the import wrote into the source tree"
    );
}

#[test]
fn the_example_sends_a_synthetic_frame_to_a_server() {
    if python_skipped("the Python example") {
        return;
    }
    let python_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../proto/python");
    let server = Server::start(&[]);
    let run = Command::new("python3")
        .arg(python_dir.join("examples/one_step.py"))
        .arg(&server.address)
        .env("PYTHONPATH", &python_dir)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("python3 runs");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("control") && stdout.contains("first waypoints"),
        "{stdout}"
    );
}
