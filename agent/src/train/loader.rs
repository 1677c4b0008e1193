//! A background thread that reads and prepares the batches of a run, a few ahead of the
//! optimiser. Batch k of a run is a pure function of the seed and k (the epoch's shuffle and
//! each sample's augmentation and history dropout are seeded by them), so a resumed run sees
//! exactly the batches the interrupted one would have.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};
use std::thread::JoinHandle;

use rand::seq::SliceRandom;
use rand::{RngExt as _, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ssrdrive_proto::dataset::{DatasetError, fnv1a};

use super::augment::Photometric;
use super::config::TrainConfig;
use super::data::{Batch, SampleDraw, SampleRef, TrainingData};

/// Batches prepared ahead of the optimiser.
const PREFETCH: usize = 3;

/// The variation seed of sample `index` of step `step`.
fn sample_seed(seed: u64, step: u64, index: usize) -> u64 {
    fnv1a(
        &[
            seed.to_le_bytes(),
            step.to_le_bytes(),
            (index as u64).to_le_bytes(),
        ]
        .concat(),
    )
}

/// Training batches for steps `first..last`, in order.
pub struct BatchLoader {
    batches: Receiver<(u64, Result<Batch, DatasetError>)>,
    worker: Option<JoinHandle<()>>,
}

impl BatchLoader {
    /// Starts the background thread preparing the batches of `steps` from `data`, as `config` says
    /// (batch size, seed, balanced sampling, augmentation, history dropout).
    pub fn start(
        data: Arc<TrainingData>,
        config: &TrainConfig,
        steps: std::ops::Range<u64>,
    ) -> Self {
        let (sender, batches) = sync_channel(PREFETCH);
        let config = config.clone();
        let (batch_size, seed) = (config.batch_size, config.seed);
        let worker = std::thread::Builder::new()
            .name("batch-loader".into())
            .spawn(move || {
                // Shuffles are cached per epoch: recomputing one per step would cost more
                // than the batch itself on a large dataset.
                let per_epoch = (data.train.len() / batch_size).max(1) as u64;
                let mut epoch_order: Option<(u64, Vec<SampleRef>)> = None;
                for step in steps {
                    let epoch = step / per_epoch;
                    if epoch_order.as_ref().is_none_or(|(e, _)| *e != epoch) {
                        let order = if config.balanced {
                            weighted(&data.train, &data.train_weights, seed, epoch)
                        } else {
                            shuffled(&data.train, seed, epoch)
                        };
                        epoch_order = Some((epoch, order));
                    }
                    let (_, order) = epoch_order.as_ref().expect("set above");
                    let position = (step % per_epoch) as usize * batch_size;
                    let samples: Vec<SampleRef> = order
                        .iter()
                        .cycle()
                        .skip(position)
                        .take(batch_size)
                        .copied()
                        .collect();
                    let batch = data.batch(&samples, &config.model, config.history, |i| {
                        draw(&config, sample_seed(seed, step, i))
                    });
                    let failed = batch.is_err();
                    if sender.send((step, batch)).is_err() || failed {
                        return;
                    }
                }
            })
            .expect("spawning the batch loader");
        Self {
            batches,
            worker: Some(worker),
        }
    }

    /// The next step's batch; `None` once every step was delivered.
    pub fn next_batch(&mut self) -> Option<(u64, Result<Batch, DatasetError>)> {
        self.batches.recv().ok()
    }
}

impl Drop for BatchLoader {
    fn drop(&mut self) {
        // Dropping the receiver first makes a blocked send fail, so the worker ends.
        let (_, empty) = sync_channel(0);
        drop(std::mem::replace(&mut self.batches, empty));
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
    }
}

/// A sample's photometric jitter, history dropout and later target point, from its seed.
fn draw(config: &TrainConfig, seed: u64) -> SampleDraw {
    let augment = config.augment;
    let mut later = ChaCha8Rng::seed_from_u64(seed.rotate_left(17) ^ 0x7a9e);
    SampleDraw {
        photometric: (augment > 0.0).then(|| Photometric::draw(seed, augment)),
        drop_history: config.history_dropout > 0.0
            && ChaCha8Rng::seed_from_u64(!seed).random_bool(config.history_dropout),
        later_target: (config.later_target > 0.0 && later.random_bool(config.later_target))
            .then(|| 1.0 - later.random::<f64>()),
    }
}

/// Epoch `epoch`'s seeded draw of as many samples as there are, with replacement, each with
/// probability proportional to its weight (balanced sampling).
fn weighted(train: &[SampleRef], weights: &[f32], seed: u64, epoch: u64) -> Vec<SampleRef> {
    let mut total = 0.0f64;
    let cumulative: Vec<f64> = weights
        .iter()
        .map(|w| {
            total += f64::from(*w);
            total
        })
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ epoch.wrapping_mul(0x9e37_79b9) ^ 0xba1a_2ced);
    (0..train.len())
        .map(|_| {
            let x = rng.random_range(0.0..total);
            let i = cumulative.partition_point(|&c| c <= x).min(train.len() - 1);
            train[i]
        })
        .collect()
}

/// Epoch `epoch`'s seeded shuffle of the training samples. Step k of the epoch takes the k-th
/// full batch of it (the remainder waits for the next epoch's shuffle).
fn shuffled(train: &[SampleRef], seed: u64, epoch: u64) -> Vec<SampleRef> {
    let mut order = train.to_vec();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(
        seed ^ epoch.wrapping_mul(0x9e37_79b9),
    ));
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::config::SsrConfig;

    #[test]
    fn history_dropout_drops_its_share_of_samples() {
        let mut config = TrainConfig::new(SsrConfig::cpu_default(), 1);
        let dropped = |config: &TrainConfig| {
            (0..2000)
                .filter(|&i| draw(config, sample_seed(3, i / 8, (i % 8) as usize)).drop_history)
                .count()
        };
        assert_eq!(dropped(&config), 0, "off by default");
        config.history_dropout = 0.3;
        let share = dropped(&config) as f64 / 2000.0;
        assert!((0.25..0.35).contains(&share), "{share}");
        config.history_dropout = 1.0;
        assert_eq!(dropped(&config), 2000);
    }

    #[test]
    fn later_targets_are_drawn_for_their_share_of_samples_independently_of_history_dropout() {
        let mut config = TrainConfig::new(SsrConfig::cpu_default(), 1);
        let draws = |config: &TrainConfig| -> Vec<SampleDraw> {
            (0..2000)
                .map(|i| draw(config, sample_seed(3, i / 8, (i % 8) as usize)))
                .collect()
        };
        assert!(
            draws(&config).iter().all(|d| d.later_target.is_none()),
            "off by default"
        );
        config.later_target = 0.3;
        config.history_dropout = 0.3;
        let drawn = draws(&config);
        let later: Vec<f64> = drawn.iter().filter_map(|d| d.later_target).collect();
        let share = later.len() as f64 / 2000.0;
        assert!((0.25..0.35).contains(&share), "{share}");
        assert!(later.iter().all(|&s| s > 0.0 && s <= 1.0));
        let both = drawn
            .iter()
            .filter(|d| d.drop_history && d.later_target.is_some())
            .count();
        let both = both as f64 / 2000.0;
        assert!((0.05..0.13).contains(&both), "drawn independently: {both}");
    }
}
