//! The tonic `AgentService`: a thin layer that hands each RPC to the [`Engine`], turns its
//! errors into gRPC statuses and counts every answer by method and code.
//!
//! `Drive` carries one episode per stream: the first message must be `start`, every later one
//! a `step` (its `episode_id` may be empty). A failed step ends the stream with its status; the
//! episode is closed whenever the stream ends.

use std::pin::Pin;
use std::sync::Arc;

use ssrdrive_proto::v1;
use ssrdrive_proto::v1::agent_service_server::AgentService;
use ssrdrive_proto::v1::drive_request::Message;
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status, Streaming};

use super::engine::{Engine, ServeError};

/// The gRPC face of an [`Engine`].
pub struct AgentServiceImpl {
    engine: Arc<Engine>,
}

impl AgentServiceImpl {
    pub fn new(engine: Arc<Engine>) -> Self {
        Self { engine }
    }

    fn answer<T>(&self, method: &'static str, result: Result<T, ServeError>) -> Result<T, Status> {
        let result = result.map_err(Status::from);
        let code = match &result {
            Ok(_) => tonic::Code::Ok,
            Err(status) => {
                tracing::debug!(method, code = ?status.code(), "{}", status.message());
                status.code()
            }
        };
        self.engine.metrics().request(method, code);
        result
    }
}

type StepStream = Pin<Box<dyn Stream<Item = Result<v1::StepResponse, Status>> + Send>>;

#[tonic::async_trait]
impl AgentService for AgentServiceImpl {
    async fn get_agent_info(
        &self,
        _request: Request<v1::GetAgentInfoRequest>,
    ) -> Result<Response<v1::AgentInfo>, Status> {
        self.answer("GetAgentInfo", Ok(self.engine.agent_info()))
            .map(Response::new)
    }

    async fn start_episode(
        &self,
        request: Request<v1::StartEpisodeRequest>,
    ) -> Result<Response<v1::StartEpisodeResponse>, Status> {
        let result = self.engine.start_episode(request.get_ref());
        self.answer("StartEpisode", result).map(Response::new)
    }

    async fn step(
        &self,
        request: Request<v1::StepRequest>,
    ) -> Result<Response<v1::StepResponse>, Status> {
        let result = self.engine.step(request.into_inner()).await;
        self.answer("Step", result).map(Response::new)
    }

    type DriveStream = StepStream;

    async fn drive(
        &self,
        request: Request<Streaming<v1::DriveRequest>>,
    ) -> Result<Response<Self::DriveStream>, Status> {
        let mut inbound = request.into_inner();
        let first = inbound.message().await?;
        let start = match first.and_then(|m| m.message) {
            Some(Message::Start(start)) => start,
            _ => {
                let status =
                    Status::invalid_argument("the first message of a Drive stream must be `start`");
                self.engine.metrics().request("Drive", status.code());
                return Err(status);
            }
        };
        let id = self
            .answer("Drive", self.engine.start_episode(&start))?
            .episode_id;
        let (sender, receiver) = tokio::sync::mpsc::channel(4);
        let engine = Arc::clone(&self.engine);
        let service = Self::new(Arc::clone(&engine));
        tokio::spawn(async move {
            while let Ok(Some(message)) = inbound.message().await {
                let result = match message.message {
                    Some(Message::Step(mut step))
                        if step.episode_id.is_empty() || step.episode_id == id =>
                    {
                        step.episode_id = id.clone();
                        engine.step(step).await
                    }
                    Some(Message::Step(step)) => Err(ServeError::BadRequest(format!(
                        "this Drive stream carries episode '{id}', not '{}'",
                        step.episode_id
                    ))),
                    _ => Err(ServeError::BadRequest(
                        "after `start`, a Drive stream carries only `step` messages".into(),
                    )),
                };
                let result = service.answer("Drive", result);
                let failed = result.is_err();
                if sender.send(result).await.is_err() || failed {
                    break;
                }
            }
            let _ = engine.end_episode(&id);
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(receiver))))
    }

    async fn end_episode(
        &self,
        request: Request<v1::EndEpisodeRequest>,
    ) -> Result<Response<v1::EndEpisodeResponse>, Status> {
        let result = self.engine.end_episode(&request.get_ref().episode_id);
        self.answer("EndEpisode", result).map(Response::new)
    }
}
