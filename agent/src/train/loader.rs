//! A background thread that reads and prepares the batches of a run, a few ahead of the
//! optimiser. Batch k of a run is a pure function of the seed and k (the epoch's shuffle and
//! each sample's augmentation are seeded by them), so a resumed run sees exactly the batches
//! the interrupted one would have.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};
use std::thread::JoinHandle;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::augment::Photometric;
use super::data::{Batch, SampleRef, TrainingData, fnv1a};
use crate::model::config::SsrConfig;
use sim_bridge::dataset::DatasetError;

/// Batches prepared ahead of the optimiser.
const PREFETCH: usize = 3;

/// The augmentation seed of sample `index` of step `step`.
fn augment_seed(seed: u64, step: u64, index: usize) -> u64 {
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
    pub fn start(
        data: Arc<TrainingData>,
        model: SsrConfig,
        batch_size: usize,
        augment: f32,
        seed: u64,
        steps: std::ops::Range<u64>,
    ) -> Self {
        let (sender, batches) = sync_channel(PREFETCH);
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
                        epoch_order = Some((epoch, shuffled(&data.train, seed, epoch)));
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
                    let batch = data.batch(&samples, &model, |i| {
                        (augment > 0.0)
                            .then(|| Photometric::draw(augment_seed(seed, step, i), augment))
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

/// Epoch `epoch`'s seeded shuffle of the training samples. Step k of the epoch takes the k-th
/// full batch of it (the remainder waits for the next epoch's shuffle).
fn shuffled(train: &[SampleRef], seed: u64, epoch: u64) -> Vec<SampleRef> {
    let mut order = train.to_vec();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(
        seed ^ epoch.wrapping_mul(0x9e37_79b9),
    ));
    order
}
