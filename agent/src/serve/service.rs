//! The tonic `AgentService`: a thin layer that hands each RPC to the [`Engine`], turns its
//! errors into gRPC statuses and counts every answer by method and code.
//!
//! `Drive` carries one episode per stream: the first message must be `start`, every later one
//! a `step` (its `episode_id` may be empty). The episode belongs to the stream (unary calls on
//! it get FAILED_PRECONDITION). A failed step ends the stream with its status; the episode is
//! closed whenever the stream ends.
//!
//! Every answer and error carries the server's replica id as `x-ssrdrive-replica` metadata
//! ([`ssrdrive_proto::REPLICA_HEADER`]), so a client behind a load balancer sees which replica
//! served it.

use std::pin::Pin;
use std::sync::Arc;

use ssrdrive_proto::v1;
use ssrdrive_proto::v1::agent_service_server::AgentService;
use ssrdrive_proto::v1::drive_request::Message;
use ssrdrive_support::error_text::clipped;
use tokio::sync::watch;
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tonic::metadata::{Ascii, MetadataValue};
use tonic::{Request, Response, Status, Streaming};

use super::engine::{Engine, ServeError};
use super::episodes::Driver;

/// The gRPC face of an [`Engine`].
pub struct AgentServiceImpl {
    engine: Arc<Engine>,
    /// Flips to `true` when the server starts draining; open Drive streams then end.
    draining: watch::Receiver<bool>,
    /// This server's replica id, sent with every answer.
    replica: MetadataValue<Ascii>,
}

impl AgentServiceImpl {
    /// Serves `engine` as replica `replica` (printable ASCII, checked by the config); Drive
    /// streams end once `draining` turns `true`.
    pub fn new(engine: Arc<Engine>, draining: watch::Receiver<bool>, replica: &str) -> Self {
        let replica = replica
            .parse()
            .unwrap_or_else(|_| MetadataValue::from_static("invalid-replica-id"));
        Self {
            engine,
            draining,
            replica,
        }
    }

    /// `result` as the RPC's answer, with the replica id in its metadata.
    fn reply<T>(&self, result: Result<T, Status>) -> Result<Response<T>, Status> {
        match result {
            Ok(message) => {
                let mut response = Response::new(message);
                response
                    .metadata_mut()
                    .insert(ssrdrive_proto::REPLICA_HEADER, self.replica.clone());
                Ok(response)
            }
            Err(mut status) => {
                status
                    .metadata_mut()
                    .insert(ssrdrive_proto::REPLICA_HEADER, self.replica.clone());
                Err(status)
            }
        }
    }
}

/// Counts an answer by method and code, logs refusals at debug level, and converts the error.
fn answer<T>(
    engine: &Engine,
    method: &'static str,
    result: Result<T, ServeError>,
) -> Result<T, Status> {
    let result = result.map_err(Status::from);
    let code = match &result {
        Ok(_) => tonic::Code::Ok,
        Err(status) => {
            tracing::debug!(method, code = ?status.code(), "{}", status.message());
            status.code()
        }
    };
    engine.metrics().request(method, code);
    result
}

type StepStream = Pin<Box<dyn Stream<Item = Result<v1::StepResponse, Status>> + Send>>;

#[tonic::async_trait]
impl AgentService for AgentServiceImpl {
    async fn get_agent_info(
        &self,
        _request: Request<v1::GetAgentInfoRequest>,
    ) -> Result<Response<v1::AgentInfo>, Status> {
        self.reply(answer(
            &self.engine,
            "GetAgentInfo",
            Ok(self.engine.agent_info()),
        ))
    }

    async fn start_episode(
        &self,
        request: Request<v1::StartEpisodeRequest>,
    ) -> Result<Response<v1::StartEpisodeResponse>, Status> {
        let result = self.engine.start_episode(request.get_ref(), Driver::Unary);
        self.reply(answer(&self.engine, "StartEpisode", result))
    }

    async fn step(
        &self,
        request: Request<v1::StepRequest>,
    ) -> Result<Response<v1::StepResponse>, Status> {
        let result = self.engine.step(request.into_inner(), Driver::Unary).await;
        self.reply(answer(&self.engine, "Step", result))
    }

    type DriveStream = StepStream;

    async fn drive(
        &self,
        request: Request<Streaming<v1::DriveRequest>>,
    ) -> Result<Response<Self::DriveStream>, Status> {
        let mut inbound = request.into_inner();
        let mut draining = self.draining.clone();
        // A stream that has not sent `start` carries nothing a drain should wait for.
        let first = tokio::select! {
            first = inbound.message() => first,
            _ = draining.wait_for(|draining| *draining) => {
                return self.reply(Err(Status::unavailable("the server is shutting down")));
            }
        };
        let start = match first {
            Ok(Some(v1::DriveRequest {
                message: Some(Message::Start(start)),
            })) => Ok(start),
            Ok(_) => Err(ServeError::BadRequest(
                "the first message of a Drive stream must be `start`".into(),
            )),
            Err(status) => return self.reply(Err(status)),
        };
        let started = answer(
            &self.engine,
            "Drive",
            start.and_then(|start| self.engine.start_episode(&start, Driver::Stream)),
        );
        let id = match started {
            Ok(started) => started.episode_id,
            Err(status) => return self.reply(Err(status)),
        };
        let (sender, receiver) = tokio::sync::mpsc::channel(4);
        let engine = Arc::clone(&self.engine);
        tokio::spawn(async move {
            loop {
                let message = tokio::select! {
                    message = inbound.message() => message,
                    () = async {
                        let _ = draining.wait_for(|draining| *draining).await;
                    } => {
                        let _ = sender
                            .send(Err(Status::unavailable("the server is shutting down")))
                            .await;
                        break;
                    }
                    () = sender.closed() => break,
                };
                let result = match message {
                    Ok(Some(message)) => drive_step(&engine, &id, message).await,
                    Ok(None) => break,
                    // A broken or oversized message ends the stream with its status.
                    Err(status) => {
                        let _ = sender.send(Err(status)).await;
                        break;
                    }
                };
                let result = answer(&engine, "Drive", result);
                let failed = result.is_err();
                if sender.send(result).await.is_err() || failed {
                    break;
                }
            }
            let _ = engine.end_episode(&id, Driver::Stream);
        });
        self.reply(Ok(Box::pin(ReceiverStream::new(receiver)) as StepStream))
    }

    async fn end_episode(
        &self,
        request: Request<v1::EndEpisodeRequest>,
    ) -> Result<Response<v1::EndEpisodeResponse>, Status> {
        let result = self
            .engine
            .end_episode(&request.get_ref().episode_id, Driver::Unary);
        self.reply(answer(&self.engine, "EndEpisode", result))
    }
}

/// One message of a Drive stream after `start`: a step of the stream's episode, bounded by the
/// server's request timeout (tonic's timeout covers only the call that opens the stream).
async fn drive_step(
    engine: &Engine,
    id: &str,
    message: v1::DriveRequest,
) -> Result<v1::StepResponse, ServeError> {
    let mut step = match message.message {
        Some(Message::Step(step)) if step.episode_id.is_empty() || step.episode_id == id => step,
        Some(Message::Step(step)) => {
            return Err(ServeError::BadRequest(format!(
                "this Drive stream carries episode '{id}', not '{}'",
                clipped(&step.episode_id)
            )));
        }
        _ => {
            return Err(ServeError::BadRequest(
                "after `start`, a Drive stream carries only `step` messages".into(),
            ));
        }
    };
    step.episode_id = id.to_string();
    tokio::time::timeout(engine.request_timeout(), engine.step(step, Driver::Stream))
        .await
        .map_err(|_| ServeError::DeadlineExceeded(engine.request_timeout()))?
}
