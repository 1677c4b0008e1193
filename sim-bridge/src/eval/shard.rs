//! Splitting a campaign over independent processes: `eval --shard K/N` drives share K of N of
//! the campaign's runs (route x repetition), and `results merge` puts the shares back together
//! ([`super::merge`]).
//!
//! The split is a pure function of the routes' lengths, the repetitions and N, so every process
//! computes the same one without talking to the others: runs are dealt longest first, each to the
//! share with the least length so far (ties to the lower share), which keeps the shares' driving
//! time within one run of each other. A run's world is seeded by its repetition, never by the
//! process that drives it, so the shares' records are those one process would write.

use std::fmt;
use std::str::FromStr;

/// Share `index` of `count` (0-based, as Kubernetes' `JOB_COMPLETION_INDEX` and SLURM's
/// `SLURM_ARRAY_TASK_ID` from 0 count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// Which share, `0..count`.
    pub index: usize,
    /// How many shares.
    pub count: usize,
}

/// The largest number of shares (a campaign has at most this many runs worth splitting).
pub const MAX_SHARDS: usize = 100_000;

impl FromStr for Shard {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let usage = || format!("`{text}`: a shard is K/N, share K (from 0) of N, e.g. 0/4");
        let (k, n) = text.split_once('/').ok_or_else(usage)?;
        let index: usize = k.trim().parse().map_err(|_| usage())?;
        let count: usize = n.trim().parse().map_err(|_| usage())?;
        if count == 0 || count > MAX_SHARDS {
            return Err(format!(
                "`{text}`: the number of shares must be 1 to {MAX_SHARDS}"
            ));
        }
        if index >= count {
            return Err(format!(
                "`{text}`: share {index} does not exist; shares count from 0 to {}",
                count - 1
            ));
        }
        Ok(Self { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// The runs (indices in the leaderboard's order: all routes of repetition 0, then of 1,
    /// ...) of routes of these lengths (m), driven `repetitions` times, that fall to this share,
    /// in ascending order.
    pub fn runs(&self, lengths: &[f64], repetitions: usize) -> Vec<usize> {
        let total = lengths.len() * repetitions;
        let mut order: Vec<usize> = (0..total).collect();
        let length = |run: usize| lengths[run % lengths.len()];
        order.sort_by(|&a, &b| length(b).total_cmp(&length(a)).then(a.cmp(&b)));
        let mut load = vec![0.0f64; self.count];
        let mut mine = Vec::new();
        for run in order {
            let share = (0..self.count)
                .min_by(|&a, &b| load[a].total_cmp(&load[b]).then(a.cmp(&b)))
                .expect("at least one share");
            load[share] += length(run);
            if share == self.index {
                mine.push(run);
            }
        }
        mine.sort_unstable();
        mine
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_parse_with_clear_errors() {
        assert_eq!("2/4".parse::<Shard>(), Ok(Shard { index: 2, count: 4 }));
        assert_eq!("0/1".parse::<Shard>().unwrap().to_string(), "0/1");
        for (bad, says) in [
            ("4/4", "shares count from 0 to 3"),
            ("1/0", "must be 1 to"),
            ("x/2", "a shard is K/N"),
            ("3", "a shard is K/N"),
            ("-1/2", "a shard is K/N"),
        ] {
            let err = bad.parse::<Shard>().unwrap_err();
            assert!(err.contains(says), "{bad}: {err}");
        }
    }

    #[test]
    fn the_shares_cover_every_run_once_and_balance_the_length() {
        let lengths = [1200.0, 300.0, 800.0, 450.0, 2100.0, 600.0, 90.0];
        let repetitions = 3;
        for count in 1..=8 {
            let mut seen = vec![0; lengths.len() * repetitions];
            let mut loads = Vec::new();
            for index in 0..count {
                let runs = Shard { index, count }.runs(&lengths, repetitions);
                assert!(runs.windows(2).all(|w| w[0] < w[1]), "ascending");
                for &run in &runs {
                    seen[run] += 1;
                }
                loads.push(
                    runs.iter()
                        .map(|&r| lengths[r % lengths.len()])
                        .sum::<f64>(),
                );
            }
            assert!(seen.iter().all(|&n| n == 1), "{count} shares: {seen:?}");
            // Dealt longest first, no share exceeds another by more than the longest run.
            let (min, max) = loads
                .iter()
                .fold((f64::MAX, 0.0f64), |(lo, hi), &l| (lo.min(l), hi.max(l)));
            assert!(max - min <= 2100.0 + 1e-9, "{count} shares: {loads:?}");
        }
        // More shares than runs: the extra ones are empty.
        assert!(
            Shard { index: 5, count: 6 }
                .runs(&[100.0, 200.0], 2)
                .is_empty()
        );
    }
}
