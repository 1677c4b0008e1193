//! End to end through gRPC: a real `ssr-agent serve` process (random cpu-default weights) on an
//! ephemeral loopback port and a raw client that provokes every error status the protocol
//! defines (one test per status, on a shared server), streams, limits, health and the drain.
//! sim-bridge's commands against a server are `clients.rs`.

use std::time::Duration;

use ssrdrive_proto::v1;
use ssrdrive_proto::v1::agent_service_client::AgentServiceClient;
use ssrdrive_proto::v1::drive_request::Message;
use ssrdrive_tests::synthetic_step as step;
use ssrdrive_tests::{Server, SharedServer, runtime};
use tonic::Code;
use tonic::transport::Channel;

type Client = AgentServiceClient<Channel>;

/// The rig the server expects (tcp-small for cpu-default).
async fn expected_rig(client: &mut Client) -> v1::Rig {
    let info = client
        .get_agent_info(v1::GetAgentInfoRequest {})
        .await
        .unwrap()
        .into_inner();
    info.expected_rig.unwrap()
}

async fn start(client: &mut Client, rig: &v1::Rig) -> String {
    client
        .start_episode(v1::StartEpisodeRequest {
            rig: Some(rig.clone()),
            client: "e2e".into(),
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner()
        .episode_id
}

async fn code_of<T>(call: impl Future<Output = Result<T, tonic::Status>>) -> Code {
    match call.await {
        Ok(_) => Code::Ok,
        Err(status) => status.code(),
    }
}

/// The server the error-status tests share: idle episodes expire after 1.5 s and messages
/// over 1 MiB are refused.
static STATUS_SERVER: SharedServer =
    SharedServer::new(&["--idle-timeout-s", "1.5", "--max-message-mib", "1"]);

/// A client of the shared server and the rig it expects.
async fn status_client(server: &Server) -> (Client, v1::Rig) {
    let mut client = server.client().await;
    let rig = expected_rig(&mut client).await;
    (client, rig)
}

#[test]
fn unknown_episode_ids_are_not_found() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        assert_eq!(
            code_of(client.step(step("nope", 0, &rig))).await,
            Code::NotFound
        );
        assert_eq!(
            code_of(client.end_episode(v1::EndEpisodeRequest {
                episode_id: "nope".into()
            }))
            .await,
            Code::NotFound
        );
    });
}

#[test]
fn a_rig_that_cannot_be_is_invalid_argument() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        let mut bad_rig = rig.clone();
        bad_rig.cameras[0].fov = -5.0;
        let refused = client
            .start_episode(v1::StartEpisodeRequest {
                rig: Some(bad_rig),
                ..Default::default()
            })
            .await
            .unwrap_err();
        assert_eq!(refused.code(), Code::InvalidArgument);
        assert!(refused.message().contains("fov"), "{}", refused.message());
        // No rig, or an override outside its range, is as invalid.
        let refused = client
            .start_episode(v1::StartEpisodeRequest::default())
            .await
            .unwrap_err();
        assert_eq!(refused.code(), Code::InvalidArgument);
        assert!(
            refused.message().contains("rig is missing"),
            "{}",
            refused.message()
        );
        let refused = client
            .start_episode(v1::StartEpisodeRequest {
                rig: Some(rig.clone()),
                overrides: Some(v1::EpisodeOverrides {
                    fusion_alpha: Some(1.5),
                }),
                ..Default::default()
            })
            .await
            .unwrap_err();
        assert_eq!(refused.code(), Code::InvalidArgument);
        assert!(
            refused
                .message()
                .contains("fusion_alpha = 1.5 is not in [0, 1]"),
            "{}",
            refused.message()
        );
    });
}

#[test]
fn malformed_steps_are_invalid_argument_and_spare_every_episode() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        let good = start(&mut client, &rig).await;
        let victim = start(&mut client, &rig).await;
        let reference = start(&mut client, &rig).await;
        let mut bad_requests: Vec<(v1::StepRequest, &str)> = Vec::new();
        let mut request = step(&victim, 0, &rig);
        request.images[0].width += 1;
        bad_requests.push((request, "but the rig says"));
        let mut request = step(&victim, 0, &rig);
        request.images[0].data.truncate(10);
        bad_requests.push((request, "bytes, got 10"));
        let mut request = step(&victim, 0, &rig);
        request.speed_mps = f64::NAN;
        bad_requests.push((request, "speed_mps = NaN"));
        let mut request = step(&victim, 0, &rig);
        request.speed_mps = 1e300;
        bad_requests.push((request, "speed_mps = 1e300 is not a finite 32-bit number"));
        let mut request = step(&victim, 0, &rig);
        request.target_point = Some(v1::EgoPoint {
            x: f64::INFINITY,
            y: 0.0,
        });
        bad_requests.push((request, "target_point.x"));
        let mut request = step(&victim, 0, &rig);
        request.command = 9;
        bad_requests.push((request, "command 9"));
        let mut request = step(&victim, 0, &rig);
        request.images[0].encoding = v1::ImageEncoding::Png as i32;
        bad_requests.push((request, "not a readable PNG"));
        let mut request = step(&victim, 0, &rig);
        request.images[0].encoding = v1::ImageEncoding::Jpeg as i32;
        bad_requests.push((request, "not a readable JPEG"));
        let mut request = step(&victim, 0, &rig);
        request.images.clear();
        bad_requests.push((request, "carries 0 image(s)"));
        let mut request = step(&victim, 0, &rig);
        request.pose = None;
        bad_requests.push((request, "pose is missing"));
        let mut request = step(&victim, 0, &rig);
        request.target_point = None;
        bad_requests.push((request, "target_point is missing"));
        let mut request = step(&victim, 0, &rig);
        request.speed_mps = -2.0;
        bad_requests.push((request, "speed_mps = -2 is negative"));

        // The good episode steps between the bad requests and must answer exactly as the
        // reference episode, which sees no bad requests at all.
        for (frame, (request, expected)) in bad_requests.into_iter().enumerate() {
            let answer = client.step(step(&good, frame as u64, &rig)).await.unwrap();
            let status = client.step(request).await.unwrap_err();
            assert_eq!(status.code(), Code::InvalidArgument, "{}", status.message());
            assert!(
                status.message().contains(expected),
                "'{}' should mention '{expected}'",
                status.message()
            );
            let same = client
                .step(step(&reference, frame as u64, &rig))
                .await
                .unwrap();
            assert_eq!(answer.get_ref().control, same.get_ref().control);
            assert_eq!(answer.get_ref().trajectory, same.get_ref().trajectory);
        }
        // The victim's state was never touched: its first good step is frame 0.
        client.step(step(&victim, 0, &rig)).await.unwrap();
    });
    let invalid = r#"ssr_requests_total{method="Step",code="INVALID_ARGUMENT"}"#;
    assert!(server.metric(invalid) >= 10.0);
}

#[test]
fn a_frame_index_that_does_not_increase_is_failed_precondition() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        let episode = start(&mut client, &rig).await;
        client.step(step(&episode, 0, &rig)).await.unwrap();
        let status = client.step(step(&episode, 0, &rig)).await.unwrap_err();
        assert_eq!(status.code(), Code::FailedPrecondition);
        assert!(
            status.message().contains("does not follow"),
            "{}",
            status.message()
        );
    });
}

#[test]
fn episodes_beyond_the_limit_are_resource_exhausted() {
    // Its own server: the limit counts every open episode.
    let server = Server::start(&["--max-episodes", "2"]);
    runtime().block_on(async {
        let mut client = server.client().await;
        let rig = expected_rig(&mut client).await;
        start(&mut client, &rig).await;
        let second = start(&mut client, &rig).await;
        let start_one = || v1::StartEpisodeRequest {
            rig: Some(rig.clone()),
            ..Default::default()
        };
        let status = client.start_episode(start_one()).await.unwrap_err();
        assert_eq!(status.code(), Code::ResourceExhausted);
        client
            .end_episode(v1::EndEpisodeRequest { episode_id: second })
            .await
            .unwrap();
        client.start_episode(start_one()).await.unwrap();
    });
}

#[test]
fn a_deadline_shorter_than_a_step_is_honoured_and_the_episode_survives() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        let episode = start(&mut client, &rig).await;
        let mut request = tonic::Request::new(step(&episode, 0, &rig));
        request.set_timeout(Duration::from_micros(1));
        let status = client.step(request).await.unwrap_err();
        assert!(
            matches!(status.code(), Code::DeadlineExceeded | Code::Cancelled),
            "{status:?}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
        client.step(step(&episode, 1, &rig)).await.unwrap();
    });
}

#[test]
fn a_message_over_the_size_limit_is_out_of_range() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        let episode = start(&mut client, &rig).await;
        // Refused before it is decoded (tonic answers OUT_OF_RANGE where gRPC's C core says
        // RESOURCE_EXHAUSTED); the episode goes on.
        let mut request = step(&episode, 0, &rig);
        request.images[0].data = vec![0; 2 << 20];
        let status = client.step(request).await.unwrap_err();
        assert_eq!(status.code(), Code::OutOfRange, "{status:?}");
        assert!(status.message().contains("too large"), "{status:?}");
        client.step(step(&episode, 1, &rig)).await.unwrap();
    });
}

#[test]
fn idle_episodes_expire_as_not_found() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        let episode = start(&mut client, &rig).await;
        client.step(step(&episode, 0, &rig)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(3000)).await;
        let status = client.step(step(&episode, 1, &rig)).await.unwrap_err();
        assert_eq!(status.code(), Code::NotFound);
        assert!(status.message().contains("expired"), "{}", status.message());
    });
    assert!(server.metric("ssr_episodes_expired_total") >= 1.0);
}

#[test]
fn a_full_queue_sheds_load_and_batches_form_under_concurrency() {
    // One step at a time and one waiting: a burst of eight must be partly refused.
    let server = Server::start(&[
        "--max-batch",
        "1",
        "--max-queue",
        "1",
        "--max-queue-delay-ms",
        "0",
    ]);
    runtime().block_on(async {
        let (mut client, rig, episodes, answers) = burst_of_first_steps(&server, 8).await;
        let codes: Vec<Code> = answers
            .iter()
            .map(|a| a.as_ref().map_or_else(|s| s.code(), |_| Code::Ok))
            .collect();
        assert!(codes.contains(&Code::ResourceExhausted), "{codes:?}");
        assert!(codes.contains(&Code::Ok), "{codes:?}");
        // A refused step leaves its episode as it was: frame 0 is still next.
        for (id, code) in episodes.iter().zip(&codes) {
            if *code == Code::ResourceExhausted {
                client.step(step(id, 0, &rig)).await.unwrap();
            }
        }
    });
    drop(server);

    let server = Server::start(&["--max-batch", "8", "--max-queue-delay-ms", "50"]);
    let sizes: Vec<u32> = runtime().block_on(async {
        let (.., answers) = burst_of_first_steps(&server, 8).await;
        answers
            .into_iter()
            .map(|a| a.unwrap().timings.unwrap().batch_size)
            .collect()
    });
    assert!(sizes.iter().any(|&s| s > 1), "no batch formed: {sizes:?}");
}

/// Opens `n` episodes, then sends each one's first step at once; returns the client, the rig,
/// the episode ids and the answers in episode order.
async fn burst_of_first_steps(
    server: &Server,
    n: usize,
) -> (
    Client,
    v1::Rig,
    Vec<String>,
    Vec<Result<v1::StepResponse, tonic::Status>>,
) {
    let mut client = server.client().await;
    let rig = expected_rig(&mut client).await;
    let mut episodes = Vec::new();
    for _ in 0..n {
        episodes.push(start(&mut client, &rig).await);
    }
    let calls = episodes.iter().map(|id| {
        let mut client = client.clone();
        let request = step(id, 0, &rig);
        async move { client.step(request).await.map(|a| a.into_inner()) }
    });
    let answers = futures_join(calls).await;
    (client, rig, episodes, answers)
}

/// Runs futures concurrently on the current runtime and collects their outputs in order.
async fn futures_join<F: Future + Send + 'static>(calls: impl Iterator<Item = F>) -> Vec<F::Output>
where
    F::Output: Send,
{
    let handles: Vec<_> = calls.map(tokio::spawn).collect();
    let mut out = Vec::new();
    for handle in handles {
        out.push(handle.await.unwrap());
    }
    out
}

#[test]
fn drive_streams_one_episode_per_stream() {
    let server = Server::start(&[]);
    runtime().block_on(async {
        let mut client = server.client().await;
        let rig = expected_rig(&mut client).await;
        let mut messages = vec![v1::DriveRequest {
            message: Some(Message::Start(v1::StartEpisodeRequest {
                rig: Some(rig.clone()),
                ..Default::default()
            })),
        }];
        for frame in 0..3 {
            let mut request = step("", frame, &rig);
            request.debug = frame == 2;
            messages.push(v1::DriveRequest {
                message: Some(Message::Step(request)),
            });
        }
        let mut answers = client
            .drive(tokio_stream::iter(messages))
            .await
            .unwrap()
            .into_inner();
        let mut frames = Vec::new();
        while let Some(answer) = answers.message().await.unwrap() {
            assert_eq!(answer.trajectory.len(), 6, "cpu-default plans 3 s");
            if answer.frame_index == 2 {
                let debug = answer.debug.expect("debug was asked for");
                assert_eq!(debug.token_attention.len(), 16);
                let sum: f32 = debug.token_attention[0].weights.iter().sum();
                assert!((sum - 1.0).abs() < 1e-3, "attention sums to {sum}");
            }
            frames.push(answer.frame_index);
        }
        assert_eq!(frames, [0, 1, 2]);

        // A stream must open with `start`.
        let status = client
            .drive(tokio_stream::iter([v1::DriveRequest {
                message: Some(Message::Step(step("", 0, &rig))),
            }]))
            .await
            .unwrap_err();
        assert_eq!(status.code(), Code::InvalidArgument);
        assert!(
            status.message().contains("must be `start`"),
            "{}",
            status.message()
        );
    });
    // The stream's episode was closed when the stream ended.
    let active =
        server.wait_for_metric("ssr_active_episodes", |n| n == 0.0, Duration::from_secs(10));
    assert_eq!(active, 0.0);
}

#[test]
fn a_drive_stream_carries_one_start_and_only_its_own_steps() {
    let server = STATUS_SERVER.get();
    runtime().block_on(async {
        let (mut client, rig) = status_client(server).await;
        let start = || v1::DriveRequest {
            message: Some(Message::Start(v1::StartEpisodeRequest {
                rig: Some(rig.clone()),
                ..Default::default()
            })),
        };
        let step_of = |id: &str| v1::DriveRequest {
            message: Some(Message::Step(step(id, 0, &rig))),
        };
        for (second, expected) in [
            (step_of("another-episode"), "carries episode"),
            (start(), "carries only `step` messages"),
        ] {
            let mut answers = client
                .drive(tokio_stream::iter([start(), second]))
                .await
                .unwrap()
                .into_inner();
            let status = answers.message().await.unwrap_err();
            assert_eq!(status.code(), Code::InvalidArgument);
            assert!(status.message().contains(expected), "{}", status.message());
        }
    });
}

#[test]
fn a_drive_streams_episode_is_its_own_and_long_ids_come_back_clipped() {
    let server = Server::start(&[]);
    runtime().block_on(async {
        let mut client = server.client().await;
        let rig = expected_rig(&mut client).await;
        let (send, receive) = tokio::sync::mpsc::channel(4);
        let drive = |message| v1::DriveRequest {
            message: Some(message),
        };
        send.send(drive(Message::Start(v1::StartEpisodeRequest {
            rig: Some(rig.clone()),
            ..Default::default()
        })))
        .await
        .unwrap();
        send.send(drive(Message::Step(step("", 0, &rig))))
            .await
            .unwrap();
        let mut answers = client
            .drive(tokio_stream::wrappers::ReceiverStream::new(receive))
            .await
            .unwrap()
            .into_inner();
        let id = answers.message().await.unwrap().unwrap().episode_id;
        assert_eq!(id.len(), 32, "128 random bits in hex: {id}");

        // Unary calls may not step or end the stream's episode...
        let status = client.step(step(&id, 1, &rig)).await.unwrap_err();
        assert_eq!(status.code(), Code::FailedPrecondition);
        assert!(
            status.message().contains("Drive stream"),
            "{}",
            status.message()
        );
        let status = client
            .end_episode(v1::EndEpisodeRequest {
                episode_id: id.clone(),
            })
            .await
            .unwrap_err();
        assert_eq!(status.code(), Code::FailedPrecondition);
        // ...which the stream goes on driving.
        send.send(drive(Message::Step(step("", 1, &rig))))
            .await
            .unwrap();
        let answer = answers.message().await.unwrap().unwrap();
        assert_eq!(answer.frame_index, 1);
        // A refused step ends the stream with its status (gRPC ends a stream at its first
        // error), and the episode with it.
        let mut bad = step("", 2, &rig);
        bad.speed_mps = f64::NAN;
        send.send(drive(Message::Step(bad))).await.unwrap();
        let status = answers.message().await.unwrap_err();
        assert_eq!(status.code(), Code::InvalidArgument);
        tokio::time::sleep(Duration::from_millis(200)).await;
        let status = client.step(step(&id, 3, &rig)).await.unwrap_err();
        assert_eq!(status.code(), Code::NotFound, "{}", status.message());
        drop(send);

        // An id of 20,000 characters is echoed clipped: the client sees the real status, not
        // RESOURCE_EXHAUSTED from a status header over gRPC's 16 KiB limit.
        let status = client
            .step(step(&"x".repeat(20_000), 0, &rig))
            .await
            .unwrap_err();
        assert_eq!(status.code(), Code::NotFound);
        assert!(status.message().len() < 300, "{}", status.message());
    });
}

#[test]
fn image_memory_limits_refuse_big_rigs_and_steps() {
    let server = Server::start(&["--max-pixels-per-step", "600000", "--max-decoded-mib", "1"]);
    runtime().block_on(async {
        let mut client = server.client().await;
        let rig = expected_rig(&mut client).await;
        let sized = |width: u32, height: u32| {
            let mut rig = rig.clone();
            rig.cameras[0].width = width;
            rig.cameras[0].height = height;
            rig
        };
        // A rig of 1000x1000 pixels is over max_pixels_per_step...
        let status = client
            .start_episode(v1::StartEpisodeRequest {
                rig: Some(sized(1000, 1000)),
                ..Default::default()
            })
            .await
            .unwrap_err();
        assert_eq!(status.code(), Code::ResourceExhausted);
        assert!(
            status.message().contains("max_pixels_per_step"),
            "{}",
            status.message()
        );
        // ...and one of 800x500 (1.6 MB decoded) fits it, but its steps could never fit the
        // 1 MiB image budget: refused at the start too, not at every step.
        let status = client
            .start_episode(v1::StartEpisodeRequest {
                rig: Some(sized(800, 500)),
                ..Default::default()
            })
            .await
            .unwrap_err();
        assert_eq!(status.code(), Code::ResourceExhausted);
        assert!(
            status.message().contains("2 MiB decoded per step")
                && status.message().contains("max_decoded_mib of 1 MiB"),
            "{}",
            status.message()
        );
        // A rig within both budgets steps.
        let id = start(&mut client, &rig).await;
        client.step(step(&id, 0, &rig)).await.unwrap();
    });
}

#[test]
fn a_client_that_stops_reading_its_stream_holds_no_model_thread() {
    let server = Server::start(&["--model-threads", "1"]);
    let rt = runtime();
    rt.block_on(async {
        let mut client = server.client().await;
        let rig = expected_rig(&mut client).await;
        // A Drive stream that sends steps but never reads an answer: 64 steps asking for the
        // debug block (about 70 kB an answer), far more than HTTP/2's flow-control windows and
        // the server's stream buffer hold, so the server's sends must block.
        let steps = 64;
        let (send, receive) = tokio::sync::mpsc::channel(steps + 1);
        send.send(v1::DriveRequest {
            message: Some(Message::Start(v1::StartEpisodeRequest {
                rig: Some(rig.clone()),
                ..Default::default()
            })),
        })
        .await
        .unwrap();
        for frame in 0..steps as u64 {
            let mut request = step("", frame, &rig);
            request.debug = true;
            send.send(v1::DriveRequest {
                message: Some(Message::Step(request)),
            })
            .await
            .unwrap();
        }
        let mut stalled = server.client().await;
        let _unread = stalled
            .drive(tokio_stream::wrappers::ReceiverStream::new(receive))
            .await
            .unwrap();
        // The stream's answers stop (the start's and the steps': one count each) well short of
        // all of them: back-pressure, not a server that dropped or buffered them all.
        let answered = r#"ssr_requests_total{method="Drive",code="OK"}"#;
        let mut last = -1.0;
        let settled = loop {
            tokio::time::sleep(Duration::from_millis(500)).await;
            let now = server.metric(answered);
            if now == last {
                break now;
            }
            last = now;
        };
        assert!(
            (1.0..steps as f64).contains(&settled),
            "{settled} of {} answered",
            steps + 1
        );
        // Another episode is served on the one model thread all the while.
        let id = start(&mut client, &rig).await;
        for frame in 0..5 {
            let mut request = tonic::Request::new(step(&id, frame, &rig));
            request.set_timeout(Duration::from_secs(5));
            client.step(request).await.unwrap();
        }
        assert_eq!(server.metric(answered), settled, "the stalled stream moved");
        drop(send);
    });
}

#[test]
fn health_reflection_and_metrics_answer_and_sigterm_drains() {
    let server = Server::start(&[]);
    runtime().block_on(async {
        use tonic_health::pb::health_check_response::ServingStatus;
        use tonic_health::pb::health_client::HealthClient;
        let mut health = HealthClient::new(server.channel().await);
        for service in ["", "ssrdrive.v1.AgentService"] {
            let reply = health
                .check(tonic_health::pb::HealthCheckRequest {
                    service: service.into(),
                })
                .await
                .unwrap();
            assert_eq!(
                reply.get_ref().status(),
                ServingStatus::Serving,
                "'{service}'"
            );
        }
        let unknown = health
            .check(tonic_health::pb::HealthCheckRequest {
                service: "no.such.Service".into(),
            })
            .await
            .unwrap_err();
        assert_eq!(unknown.code(), Code::NotFound);

        use tonic_reflection::pb::v1::ServerReflectionRequest;
        use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::v1::server_reflection_response::MessageResponse;
        let mut reflection = ServerReflectionClient::new(server.channel().await);
        let requests = [
            MessageRequest::ListServices(String::new()),
            MessageRequest::FileContainingSymbol("ssrdrive.v1.AgentService".into()),
        ]
        .map(|r| ServerReflectionRequest {
            host: String::new(),
            message_request: Some(r),
        });
        let mut answers = reflection
            .server_reflection_info(tokio_stream::iter(requests))
            .await
            .unwrap()
            .into_inner();
        let Some(MessageResponse::ListServicesResponse(list)) =
            answers.message().await.unwrap().unwrap().message_response
        else {
            panic!("expected a service list");
        };
        let names: Vec<_> = list.service.iter().map(|s| s.name.as_str()).collect();
        assert!(names.contains(&"ssrdrive.v1.AgentService"), "{names:?}");
        assert!(names.contains(&"grpc.health.v1.Health"), "{names:?}");
        let Some(MessageResponse::FileDescriptorResponse(files)) =
            answers.message().await.unwrap().unwrap().message_response
        else {
            panic!("expected a file descriptor");
        };
        assert!(!files.file_descriptor_proto.is_empty());

        let info = server
            .client()
            .await
            .get_agent_info(v1::GetAgentInfoRequest {})
            .await
            .unwrap()
            .into_inner();
        assert_eq!(info.config_name, "cpu-default");
        assert_eq!(info.checkpoint, "untrained (random weights)");
        assert_eq!(info.max_batch, 8);
        // One step, so the step metrics have samples (the warm-up's are not counted).
        let mut client = server.client().await;
        let rig = info.expected_rig.unwrap();
        let id = start(&mut client, &rig).await;
        client.step(step(&id, 0, &rig)).await.unwrap();
    });
    let metrics = server.metrics_text();
    for name in [
        "ssr_requests_total",
        "ssr_step_seconds_bucket",
        "ssr_batch_size_bucket",
        "ssr_active_episodes",
        "ssr_process_resident_bytes",
    ] {
        assert!(metrics.contains(name), "{name} missing from:\n{metrics}");
    }
    let status = server.terminate();
    assert!(
        status.success(),
        "SIGTERM should drain and exit 0, got {status}"
    );
}

#[test]
fn sigterm_ends_open_drive_streams_and_the_server_exits_promptly() {
    let server = Server::start(&["--drain-timeout-s", "30", "--request-timeout-s", "60"]);
    // One runtime for the whole test: its connections stay open while the server drains.
    let rt = runtime();
    // Streams that carry no step must not hold the drain: a health watch, a reflection
    // session and a Drive stream that never sent `start`, each left open.
    let (_quiet_senders, _watch) = rt.block_on(async {
        use tonic_health::pb::health_client::HealthClient;
        use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
        let mut health = HealthClient::new(server.channel().await);
        let watch = health
            .watch(tonic_health::pb::HealthCheckRequest {
                service: String::new(),
            })
            .await
            .unwrap()
            .into_inner();
        let (reflection_sender, reflection_requests) = tokio::sync::mpsc::channel(1);
        let mut reflection = ServerReflectionClient::new(server.channel().await);
        tokio::spawn(async move {
            let stream = tokio_stream::wrappers::ReceiverStream::new(reflection_requests);
            let _ = reflection.server_reflection_info(stream).await;
        });
        let (silent_sender, silent_requests) = tokio::sync::mpsc::channel::<v1::DriveRequest>(1);
        let mut silent = server.client().await;
        tokio::spawn(async move {
            let stream = tokio_stream::wrappers::ReceiverStream::new(silent_requests);
            let _ = silent.drive(stream).await;
        });
        tokio::time::sleep(Duration::from_millis(300)).await;
        ((reflection_sender, silent_sender), watch)
    });
    let (sender, mut answers) = rt.block_on(async {
        let mut client = server.client().await;
        let rig = expected_rig(&mut client).await;
        let (sender, requests) = tokio::sync::mpsc::channel(4);
        sender
            .send(v1::DriveRequest {
                message: Some(Message::Start(v1::StartEpisodeRequest {
                    rig: Some(rig.clone()),
                    ..Default::default()
                })),
            })
            .await
            .unwrap();
        sender
            .send(v1::DriveRequest {
                message: Some(Message::Step(step("", 0, &rig))),
            })
            .await
            .unwrap();
        let mut answers = client
            .drive(tokio_stream::wrappers::ReceiverStream::new(requests))
            .await
            .unwrap()
            .into_inner();
        answers
            .message()
            .await
            .unwrap()
            .expect("the first step's answer");
        (sender, answers)
    });
    // The stream stays open (the sender is alive) while the server is told to stop.
    let started = std::time::Instant::now();
    let status = server.terminate();
    assert!(status.success(), "{status}");
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "the drain waited on the open streams: {:?}",
        started.elapsed()
    );
    // The stream has ended (UNAVAILABLE, or the connection closing under it), not hung.
    let end = rt.block_on(answers.message());
    assert!(!matches!(end, Ok(Some(_))), "{end:?}");
    drop(sender);
}
