//! Two agents' results on the same runs, paired run by run: how far apart they are and how sure
//! that difference is.
//!
//! Closed loop, a run's path diverges from the smallest difference (the same checkpoint on two
//! builds that round one angle differently scored DS 72.8 and 63.4 on the same 12 held-out
//! runs), so a difference of means says little without its spread. [`compare`] pairs the runs
//! both results hold (same part, route and repetition), and gives each side's means, the mean
//! of the paired differences (second minus first) and its 95 % confidence interval from
//! Student's t over the pairs. An interval that holds 0 means these runs cannot tell the two
//! apart.

use std::collections::BTreeMap;

use crate::scoring::record::{RouteRecord, Scores};

/// One side's runs, keyed by (part, route id, repetition); the part is a suite's route file, or
/// empty for a single results file.
pub type Runs = BTreeMap<(String, String, Option<usize>), Scores>;

/// The runs of `records` under `part`.
pub fn runs_of<'a>(part: &str, records: impl IntoIterator<Item = &'a RouteRecord>) -> Runs {
    records
        .into_iter()
        .map(|r| {
            (
                (part.to_string(), r.route_id.clone(), r.meta.repetition),
                r.scores,
            )
        })
        .collect()
}

/// A score's means on both sides and the paired difference.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Paired {
    /// The first side's mean.
    pub first: f64,
    /// The second side's mean.
    pub second: f64,
    /// Mean of (second - first) over the pairs.
    pub difference: f64,
    /// Half the width of the difference's 95 % confidence interval (`None` for one pair).
    pub half_width: Option<f64>,
}

impl Paired {
    /// Whether the interval leaves 0 out: the runs tell the two apart.
    pub fn tells_apart(&self) -> bool {
        self.half_width
            .is_some_and(|half| self.difference.abs() > half)
    }
}

/// What [`compare`] found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Comparison {
    /// Runs both sides scored.
    pub pairs: usize,
    /// Runs only the first side scored.
    pub only_first: usize,
    /// Runs only the second side scored.
    pub only_second: usize,
    /// Driving score.
    pub ds: Paired,
    /// Route completion, percent.
    pub rc: Paired,
    /// Infraction score.
    pub is: Paired,
    /// Pairs where the second side's DS is higher.
    pub second_better: usize,
    /// Pairs where it is lower.
    pub second_worse: usize,
    /// Pairs where it is the same.
    pub same: usize,
}

/// Pairs `first` and `second` run by run; `None` when they share no run.
pub fn compare(first: &Runs, second: &Runs) -> Option<Comparison> {
    let pairs: Vec<(&Scores, &Scores)> = first
        .iter()
        .filter_map(|(key, a)| second.get(key).map(|b| (a, b)))
        .collect();
    if pairs.is_empty() {
        return None;
    }
    let paired = |score: fn(&Scores) -> f64| {
        let n = pairs.len() as f64;
        let first = pairs.iter().map(|(a, _)| score(a)).sum::<f64>() / n;
        let second = pairs.iter().map(|(_, b)| score(b)).sum::<f64>() / n;
        let differences: Vec<f64> = pairs.iter().map(|(a, b)| score(b) - score(a)).collect();
        let difference = second - first;
        let half_width = (pairs.len() > 1).then(|| {
            let variance = differences
                .iter()
                .map(|d| (d - difference).powi(2))
                .sum::<f64>()
                / (n - 1.0);
            t_975(pairs.len() - 1) * (variance / n).sqrt()
        });
        Paired {
            first,
            second,
            difference,
            half_width,
        }
    };
    let ds = |s: &Scores| s.score_composed;
    let count =
        |keep: fn(f64, f64) -> bool| pairs.iter().filter(|(a, b)| keep(ds(a), ds(b))).count();
    Some(Comparison {
        pairs: pairs.len(),
        only_first: first.keys().filter(|k| !second.contains_key(*k)).count(),
        only_second: second.keys().filter(|k| !first.contains_key(*k)).count(),
        ds: paired(ds),
        rc: paired(|s| s.score_route),
        is: paired(|s| s.score_penalty),
        second_better: count(|a, b| b > a),
        second_worse: count(|a, b| b < a),
        same: count(|a, b| b == a),
    })
}

/// Student's t quantile 0.975 for `df` degrees of freedom (at least 1).
fn t_975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match df {
        0 => f64::INFINITY,
        1..=30 => TABLE[df - 1],
        31..=60 => 2.0,
        61..=120 => 1.98,
        _ => 1.96,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn runs(scores: &[(&str, f64, f64)]) -> Runs {
        scores
            .iter()
            .map(|&(route, ds, rc)| {
                (
                    (String::new(), route.to_string(), Some(0)),
                    Scores {
                        score_composed: ds,
                        score_penalty: ds / rc,
                        score_route: rc,
                    },
                )
            })
            .collect()
    }

    #[test]
    fn pairs_runs_and_gives_the_difference_its_interval() {
        let first = runs(&[
            ("0", 50.0, 100.0),
            ("1", 60.0, 100.0),
            ("2", 70.0, 100.0),
            ("9", 1.0, 10.0),
        ]);
        let second = runs(&[
            ("0", 60.0, 100.0),
            ("1", 72.0, 100.0),
            ("2", 78.0, 100.0),
            ("5", 1.0, 10.0),
        ]);
        let c = compare(&first, &second).unwrap();
        assert_eq!((c.pairs, c.only_first, c.only_second), (3, 1, 1));
        assert_eq!((c.second_better, c.second_worse, c.same), (3, 0, 0));
        assert!((c.ds.first - 60.0).abs() < 1e-9 && (c.ds.second - 70.0).abs() < 1e-9);
        assert!((c.ds.difference - 10.0).abs() < 1e-9);
        // Differences 10, 12, 8: sd 2, half width t(2) 4.303 x 2 / sqrt 3.
        let half = c.ds.half_width.unwrap();
        assert!((half - 4.303 * 2.0 / 3f64.sqrt()).abs() < 1e-9, "{half}");
        assert!(c.ds.tells_apart());
        assert_eq!(c.rc.difference, 0.0);
        assert!(!c.rc.tells_apart(), "no spread, no difference");
    }

    #[test]
    fn a_noisy_difference_is_not_told_apart_and_one_pair_has_no_interval() {
        let first = runs(&[("0", 100.0, 100.0), ("1", 20.0, 100.0), ("2", 90.0, 100.0)]);
        let second = runs(&[("0", 30.0, 100.0), ("1", 95.0, 100.0), ("2", 100.0, 100.0)]);
        let c = compare(&first, &second).unwrap();
        assert!(c.ds.difference > 0.0 && !c.ds.tells_apart(), "{:?}", c.ds);
        let one = compare(&runs(&[("0", 1.0, 1.0)]), &runs(&[("0", 2.0, 2.0)])).unwrap();
        assert_eq!(one.ds.half_width, None);
        assert!(!one.ds.tells_apart());
        assert!(compare(&runs(&[("0", 1.0, 1.0)]), &runs(&[("1", 1.0, 1.0)])).is_none());
    }
}
