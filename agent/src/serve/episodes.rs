//! The open episodes of a server: each one's rig, temporal state and bookkeeping, behind one
//! lock held only for map operations (never across a forward pass).
//!
//! A step *leases* the episode's state: [`EpisodeTable::lease`] takes it out of the table and
//! the returned [`StepLease`] puts it back, advanced by [`StepLease::finish`] or unchanged when
//! the lease is dropped (a refused or abandoned step). So a failed step never corrupts the
//! episode and a second step of the same episode cannot run while one is in flight.
//!
//! Ids are 128 random bits (hex), so no client can guess another's episode; an episode opened
//! by a `Drive` stream belongs to it, and unary calls on it are refused. Errors repeat a
//! client's id clipped ([`clipped`]).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use ssrdrive_proto::camera::Rig;
use ssrdrive_support::error_text::clipped;

use crate::policy::EpisodeState;

/// Why an episode operation was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EpisodeError {
    /// No open episode has this id (clipped).
    #[error("unknown episode '{0}' (never started, ended, or expired after being idle)")]
    NotFound(String),
    /// The table is at its episode limit.
    #[error("{open} episodes are open, the server's limit; end one or try another replica")]
    TooMany {
        /// Episodes open now.
        open: usize,
    },
    /// A step whose frame index is not above the last stepped one.
    #[error("episode '{id}': frame_index {got} does not follow the last stepped frame {last}")]
    OutOfOrder {
        /// The episode's id.
        id: String,
        /// Frame index of the episode's last completed step.
        last: u64,
        /// Frame index of the refused step.
        got: u64,
    },
    /// A step of this episode (id given) is already in flight.
    #[error("episode '{0}': a step is already in flight; send the next one after its answer")]
    Busy(String),
    /// A unary call on an episode (id clipped) that a `Drive` stream owns.
    #[error("episode '{0}' belongs to the Drive stream that started it; step and end it there")]
    StreamOwned(String),
    /// The operating system's random source failed (its message given).
    #[error("no randomness for an episode id: {0}")]
    NoRandomness(String),
}

/// Who drives an episode: unary `Step` / `EndEpisode` calls, or the `Drive` stream that
/// started it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Driver {
    /// Unary `Step` and `EndEpisode` calls.
    Unary,
    /// The `Drive` stream that started the episode.
    Stream,
}

struct Episode {
    rig: Rig,
    driver: Driver,
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
}

/// 128 bits from the operating system's random source, as 32 hex digits.
fn random_id() -> Result<String, EpisodeError> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes).map_err(|e| EpisodeError::NoRandomness(e.to_string()))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

impl EpisodeTable {
    /// An empty table holding at most `max_episodes`, closing those idle past `idle_timeout`.
    pub fn new(max_episodes: usize, idle_timeout: Duration) -> Arc<Self> {
        Arc::new(Self {
            episodes: Mutex::new(HashMap::new()),
            max_episodes,
            idle_timeout,
        })
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<String, Episode>> {
        // Poisoning is harmless: nothing that can panic runs while the lock is held.
        self.episodes.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Opens an episode driven by `driver` and returns its id.
    pub fn open(
        &self,
        rig: Rig,
        state: EpisodeState,
        driver: Driver,
    ) -> Result<String, EpisodeError> {
        let id = random_id()?;
        let mut episodes = self.lock();
        if episodes.len() >= self.max_episodes {
            return Err(EpisodeError::TooMany {
                open: episodes.len(),
            });
        }
        episodes.insert(
            id.clone(),
            Episode {
                rig,
                driver,
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
    pub fn close(&self, id: &str, driver: Driver) -> Result<u64, EpisodeError> {
        let mut episodes = self.lock();
        driven_by(&episodes, id, driver)?;
        Ok(episodes.remove(id).expect("checked above").steps)
    }

    /// Takes the episode's state for the step of `frame_index`.
    pub fn lease(
        self: &Arc<Self>,
        id: &str,
        frame_index: u64,
        driver: Driver,
    ) -> Result<StepLease, EpisodeError> {
        let mut episodes = self.lock();
        driven_by(&episodes, id, driver)?;
        let episode = episodes.get_mut(id).expect("checked above");
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

    /// Whether no episode is open.
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

/// Refuses `id` unless it is open and `driver` drives it.
fn driven_by(
    episodes: &HashMap<String, Episode>,
    id: &str,
    driver: Driver,
) -> Result<(), EpisodeError> {
    match episodes.get(id) {
        None => Err(EpisodeError::NotFound(clipped(id))),
        Some(episode) if episode.driver != driver => Err(EpisodeError::StreamOwned(clipped(id))),
        Some(_) => Ok(()),
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
        self.table.lock().remove(&self.id);
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
