//! The open episodes of a server: each one's rig, temporal state and bookkeeping, behind one
//! lock held only for map operations (never across a forward pass).
//!
//! A step *leases* the episode's state: [`EpisodeTable::lease`] takes it out of the table and
//! the returned [`StepLease`] puts it back, advanced by [`StepLease::finish`] or unchanged when
//! the lease is dropped (a refused or abandoned step). So a failed step never corrupts the
//! episode and a second step of the same episode cannot run while one is in flight.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::camera::Rig;
use crate::policy::EpisodeState;

/// Why an episode operation was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EpisodeError {
    #[error("unknown episode '{0}' (never started, ended, or expired after being idle)")]
    NotFound(String),
    #[error("{open} episodes are open, the server's limit; end one or try another replica")]
    TooMany { open: usize },
    #[error("episode '{id}': frame_index {got} does not follow the last stepped frame {last}")]
    OutOfOrder { id: String, last: u64, got: u64 },
    #[error("episode '{0}': a step is already in flight; send the next one after its answer")]
    Busy(String),
}

struct Episode {
    rig: Rig,
    /// `None` while a step holds the lease.
    state: Option<EpisodeState>,
    last_frame: Option<u64>,
    last_seen: Instant,
    steps: u64,
}

/// All open episodes.
pub struct EpisodeTable {
    episodes: Mutex<HashMap<String, Episode>>,
    max_episodes: usize,
    idle_timeout: Duration,
    /// Makes ids unique across server runs.
    nonce: u64,
    counter: AtomicU64,
}

impl EpisodeTable {
    pub fn new(max_episodes: usize, idle_timeout: Duration) -> Arc<Self> {
        let nonce = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as u64)
            .unwrap_or_default()
            ^ ((std::process::id() as u64) << 32);
        Arc::new(Self {
            episodes: Mutex::new(HashMap::new()),
            max_episodes,
            idle_timeout,
            nonce,
            counter: AtomicU64::new(0),
        })
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<String, Episode>> {
        // Poisoning is harmless: nothing that can panic runs while the lock is held.
        self.episodes.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Opens an episode and returns its id.
    pub fn open(&self, rig: Rig, state: EpisodeState) -> Result<String, EpisodeError> {
        let mut episodes = self.lock();
        if episodes.len() >= self.max_episodes {
            return Err(EpisodeError::TooMany {
                open: episodes.len(),
            });
        }
        let n = self.counter.fetch_add(1, Ordering::Relaxed);
        let id = format!("{:016x}-{n:06}", self.nonce);
        episodes.insert(
            id.clone(),
            Episode {
                rig,
                state: Some(state),
                last_frame: None,
                last_seen: Instant::now(),
                steps: 0,
            },
        );
        Ok(id)
    }

    /// Closes an episode (even one with a step in flight; its result is then discarded) and
    /// returns how many steps it ran.
    pub fn close(&self, id: &str) -> Result<u64, EpisodeError> {
        self.lock()
            .remove(id)
            .map(|e| e.steps)
            .ok_or_else(|| EpisodeError::NotFound(id.to_string()))
    }

    /// Takes the episode's state for the step of `frame_index`.
    pub fn lease(self: &Arc<Self>, id: &str, frame_index: u64) -> Result<StepLease, EpisodeError> {
        let mut episodes = self.lock();
        let episode = episodes
            .get_mut(id)
            .ok_or_else(|| EpisodeError::NotFound(id.to_string()))?;
        if let Some(last) = episode.last_frame
            && frame_index <= last
        {
            return Err(EpisodeError::OutOfOrder {
                id: id.to_string(),
                last,
                got: frame_index,
            });
        }
        let state = episode
            .state
            .take()
            .ok_or_else(|| EpisodeError::Busy(id.to_string()))?;
        episode.last_seen = Instant::now();
        Ok(StepLease {
            table: Arc::clone(self),
            id: id.to_string(),
            rig: episode.rig.clone(),
            frame_index,
            state: Some(state),
        })
    }

    /// Closes episodes idle for longer than the timeout (not those with a step in flight) and
    /// returns their ids.
    pub fn expire_idle(&self, now: Instant) -> Vec<String> {
        let mut episodes = self.lock();
        let expired: Vec<String> = episodes
            .iter()
            .filter(|(_, e)| {
                e.state.is_some() && now.duration_since(e.last_seen) > self.idle_timeout
            })
            .map(|(id, _)| id.clone())
            .collect();
        for id in &expired {
            episodes.remove(id);
        }
        expired
    }

    /// Episodes open now.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn give_back(&self, id: &str, state: EpisodeState, stepped_frame: Option<u64>) {
        if let Some(episode) = self.lock().get_mut(id) {
            episode.state = Some(state);
            episode.last_seen = Instant::now();
            if let Some(frame) = stepped_frame {
                episode.last_frame = Some(frame);
                episode.steps += 1;
            }
        }
    }
}

/// One step's hold on an episode's state; see the module doc.
pub struct StepLease {
    table: Arc<EpisodeTable>,
    id: String,
    rig: Rig,
    frame_index: u64,
    state: Option<EpisodeState>,
}

impl StepLease {
    /// The episode's camera rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// The state to step.
    pub fn state(&mut self) -> &mut EpisodeState {
        self.state
            .as_mut()
            .expect("a lease holds its state until it ends")
    }

    /// Closes the episode: its state may be half-stepped (a forward pass that panicked), so
    /// its client must start over (NOT_FOUND from now on).
    pub fn abandon(mut self) {
        self.state = None;
        let _ = self.table.close(&self.id);
    }

    /// Returns the stepped state and records the frame as done.
    pub fn finish(mut self) {
        let state = self
            .state
            .take()
            .expect("a lease holds its state until it ends");
        self.table
            .give_back(&self.id, state, Some(self.frame_index));
    }
}

impl Drop for StepLease {
    fn drop(&mut self) {
        if let Some(state) = self.state.take() {
            self.table.give_back(&self.id, state, None);
        }
    }
}
