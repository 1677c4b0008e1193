//! Dynamic batching: steps of concurrent episodes share one forward pass.
//!
//! Requests enter a bounded queue ([`Batcher::submit`] refuses when it is full, so the server
//! sheds load instead of growing latency without bound). One model thread takes the oldest step,
//! waits at most `max_queue_delay` for up to `max_batch - 1` more (not at all once every open
//! episode is in the batch: a lone episode never waits for company), drops steps whose caller has
//! gone (deadline passed or cancelled before the batch started; their episode state goes back
//! untouched: a step whose batch already started completes), runs
//! [`SsrPolicy::step_batch`] and answers each caller. `max_batch = 1` serves steps one by one.
//!
//! With `compute_threads` set, each model thread is the first worker of a rayon pool of its own
//! of that many threads, so the forward passes of different model threads never queue for the
//! same threads; with 0 they share rayon's global pool.

use std::panic::AssertUnwindSafe;
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::oneshot;

use super::episodes::StepLease;
use super::metrics::Metrics;
use crate::policy::{SsrPolicy, StepInput, StepOutput};

/// Batch shape limits.
#[derive(Debug, Clone, Copy)]
pub struct BatchSettings {
    /// Most steps in one forward pass; 1 serves steps one by one.
    pub max_batch: usize,
    /// Longest the oldest step of a batch waits for others to join it.
    pub max_queue_delay: Duration,
    /// Most steps waiting in the queue; [`Batcher::submit`] refuses more.
    pub max_queue: usize,
    /// Model threads taking batches from the queue, each running its own forward passes
    /// (Triton's instance count): parts of the network that do not spread over all cores then
    /// run side by side.
    pub model_threads: usize,
    /// Threads of each model thread's own pool; 0: rayon's global pool.
    pub compute_threads: usize,
}

/// One step waiting for the network.
pub struct StepJob {
    /// The episode's state, held for this step.
    pub lease: StepLease,
    /// The checked step input.
    pub input: StepInput,
    /// When the step was queued.
    pub enqueued: Instant,
    /// Where the result (or the reason the step failed) goes.
    pub reply: oneshot::Sender<Result<BatchedStep, String>>,
}

/// A step's result and how its batch went.
#[derive(Debug)]
pub struct BatchedStep {
    /// The policy's output for this step.
    pub output: StepOutput,
    /// Enqueued to batch start.
    pub queue: Duration,
    /// The batch's forward pass (image resize and normalisation included), control excluded.
    pub model: Duration,
    /// Steps in the batch this step ran in.
    pub batch_size: usize,
}

/// Why a step could not be queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SubmitError {
    /// The queue is full; the value is its capacity, steps.
    #[error("the step queue is full ({0} steps waiting); retry later or add replicas")]
    QueueFull(usize),
    /// Every model thread has stopped.
    #[error("the model thread has stopped")]
    Stopped,
}

/// How many episodes are open, i.e. could send a step to join a batch.
pub type OpenEpisodes = Arc<dyn Fn() -> usize + Send + Sync>;

/// The queue in front of the model thread.
pub struct Batcher {
    queue: SyncSender<StepJob>,
    capacity: usize,
}

impl Batcher {
    /// Starts the model threads.
    pub fn start(
        policy: Arc<SsrPolicy>,
        settings: BatchSettings,
        metrics: Arc<Metrics>,
        open_episodes: OpenEpisodes,
    ) -> Self {
        let (queue, jobs) = std::sync::mpsc::sync_channel(settings.max_queue);
        let jobs = Arc::new(Mutex::new(jobs));
        for index in 0..settings.model_threads.max(1) {
            let (policy, metrics, jobs, open) = (
                Arc::clone(&policy),
                Arc::clone(&metrics),
                Arc::clone(&jobs),
                Arc::clone(&open_episodes),
            );
            std::thread::Builder::new()
                .name(format!("ssr-model-{index}"))
                .spawn(move || {
                    // This thread is its pool's first worker: with one compute thread the
                    // forward pass runs right here.
                    let _pool = (settings.compute_threads > 0).then(|| {
                        rayon::ThreadPoolBuilder::new()
                            .num_threads(settings.compute_threads)
                            .use_current_thread()
                            .thread_name(move |thread| format!("ssr-model-{index}-{thread}"))
                            .build()
                            .inspect_err(|e| {
                                tracing::warn!(
                                    "model thread {index} uses rayon's global pool: {e}"
                                );
                            })
                    });
                    model_loop(&policy, settings, &metrics, &jobs, &*open);
                })
                .expect("spawning a model thread");
        }
        Self {
            queue,
            capacity: settings.max_queue,
        }
    }

    /// Queues a step; its answer arrives on the job's reply channel.
    pub fn submit(&self, job: StepJob) -> Result<(), SubmitError> {
        self.queue.try_send(job).map_err(|e| match e {
            TrySendError::Full(_) => SubmitError::QueueFull(self.capacity),
            TrySendError::Disconnected(_) => SubmitError::Stopped,
        })
    }
}

fn model_loop(
    policy: &SsrPolicy,
    settings: BatchSettings,
    metrics: &Metrics,
    jobs: &Mutex<Receiver<StepJob>>,
    open_episodes: &(dyn Fn() -> usize + Send + Sync),
) {
    loop {
        // One thread forms a batch at a time; the others run theirs meanwhile.
        let batch = {
            let jobs = jobs.lock().unwrap_or_else(|e| e.into_inner());
            collect_batch(&jobs, settings, open_episodes)
        };
        let Some(mut batch) = batch else { return };
        // A caller that gave up gets nothing; dropping its job returns its state unchanged.
        batch.retain(|job| !job.reply.is_closed());
        if !batch.is_empty() {
            run_batch(policy, metrics, batch);
        }
    }
}

/// The next batch, or `None` once the queue is closed.
fn collect_batch(
    jobs: &Receiver<StepJob>,
    settings: BatchSettings,
    open_episodes: &(dyn Fn() -> usize + Send + Sync),
) -> Option<Vec<StepJob>> {
    let first = jobs.recv().ok()?;
    let window_end = Instant::now() + settings.max_queue_delay;
    let mut batch = vec![first];
    while batch.len() < settings.max_batch {
        // This thread's share of the open episodes is all it can expect.
        let share = open_episodes().div_ceil(settings.model_threads.max(1));
        let wait = if batch.len() >= share {
            Duration::ZERO
        } else {
            window_end.saturating_duration_since(Instant::now())
        };
        match jobs.recv_timeout(wait) {
            Ok(job) => batch.push(job),
            Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => break,
        }
    }
    Some(batch)
}

fn run_batch(policy: &SsrPolicy, metrics: &Metrics, batch: Vec<StepJob>) {
    let started = Instant::now();
    let size = batch.len();
    metrics.observe_batch(size);
    let (mut waiting, inputs): (Vec<Waiting>, Vec<StepInput>) = batch
        .into_iter()
        .map(|job| ((job.lease, job.enqueued, job.reply), job.input))
        .unzip();
    let result = {
        let mut states: Vec<_> = waiting
            .iter_mut()
            .map(|(lease, ..)| lease.state())
            .collect();
        std::panic::catch_unwind(AssertUnwindSafe(|| policy.step_batch(&mut states, &inputs)))
    };
    let elapsed = started.elapsed();
    let outputs = match result {
        Ok(Ok(outputs)) => outputs,
        // Inputs are checked before anything runs: the states are untouched.
        Ok(Err(error)) => return fail(waiting, &error.to_string()),
        Err(_) => {
            // The states may be half-stepped: their episodes are closed.
            tracing::error!("a forward pass of {} episodes panicked", waiting.len());
            for (lease, _, reply) in waiting {
                lease.abandon();
                let _ = reply.send(Err(
                    "the forward pass failed; the episode was closed (see the server log)".into(),
                ));
            }
            return;
        }
    };
    let control: Duration = outputs.iter().map(|o| o.control_time).sum();
    let model = elapsed.saturating_sub(control);
    for ((lease, enqueued, reply), output) in waiting.into_iter().zip(outputs) {
        lease.finish();
        let _ = reply.send(Ok(BatchedStep {
            output,
            queue: started.saturating_duration_since(enqueued),
            model,
            batch_size: size,
        }));
    }
}

/// A batched step's lease, enqueue time and reply channel.
type Waiting = (
    StepLease,
    Instant,
    oneshot::Sender<Result<BatchedStep, String>>,
);

/// Answers every step of a refused batch; dropping the leases returns the states unchanged.
fn fail(waiting: Vec<Waiting>, message: &str) {
    tracing::error!("batch of {} failed: {message}", waiting.len());
    for (_, _, reply) in waiting {
        let _ = reply.send(Err(message.to_string()));
    }
}
