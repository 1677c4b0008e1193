//! A readable fixed-width table of a results file: one row per record (route id, repetition,
//! status, DS, RC, IS and the event count per infraction kind), a mean row (means of DS, RC
//! and IS each taken separately, as the leaderboard does, and mean counts per record) and
//! Bench2Drive's success rate, efficiency and comfort.

use std::fmt::Write as _;

use super::bench2drive::CampaignFigures;
use super::{InfractionKind, Results};

/// The table for `results`, one line per record plus a header, a rule and the mean row.
pub fn summary_table(results: &Results) -> String {
    let records = &results.checkpoint.records;
    let id_width = records
        .iter()
        .map(|r| r.route_id.len())
        .max()
        .unwrap_or(0)
        .max(10);
    let status_width = records
        .iter()
        .map(|r| r.status.len())
        .max()
        .unwrap_or(0)
        .max(6);

    // Leaderboard 2.0's kinds only where some run has them (`--scoring lb2`).
    let kinds: Vec<InfractionKind> = InfractionKind::ALL
        .into_iter()
        .filter(|k| {
            !InfractionKind::LB2_ONLY.contains(k)
                || records.iter().any(|r| r.infractions.count(*k) > 0)
        })
        .collect();
    let mut out = String::new();
    let mut header = format!(
        "{:<id_width$} {:>4}  {:<status_width$} {:>7} {:>7} {:>6}",
        "route", "rep", "status", "DS", "RC", "IS"
    );
    for &kind in &kinds {
        let _ = write!(header, " {:>5}", kind.short());
    }
    let rule = "-".repeat(header.len());
    let _ = writeln!(out, "{header}\n{rule}");

    for r in records {
        let rep = r.meta.repetition.map_or("-".to_string(), |x| x.to_string());
        let _ = write!(
            out,
            "{:<id_width$} {:>4}  {:<status_width$} {:>7.2} {:>7.2} {:>6.3}",
            r.route_id,
            rep,
            r.status,
            r.scores.score_composed,
            r.scores.score_route,
            r.scores.score_penalty
        );
        for &kind in &kinds {
            let _ = write!(out, " {:>5}", r.infractions.count(kind));
        }
        out.push('\n');
    }

    let n = records.len().max(1) as f64;
    let mean = |f: &dyn Fn(&super::RouteRecord) -> f64| records.iter().map(f).sum::<f64>() / n;
    let _ = writeln!(out, "{rule}");
    let label = format!("mean of {}", records.len());
    let _ = write!(
        out,
        "{:<id_width$} {:>4}  {:<status_width$} {:>7.2} {:>7.2} {:>6.3}",
        label,
        "",
        "",
        mean(&|r| r.scores.score_composed),
        mean(&|r| r.scores.score_route),
        mean(&|r| r.scores.score_penalty)
    );
    for &kind in &kinds {
        let _ = write!(out, " {:>5.2}", mean(&|r| r.infractions.count(kind) as f64));
    }
    out.push('\n');
    let b2d = CampaignFigures::of(records);
    let percent = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2} %"));
    let _ = writeln!(
        out,
        "Bench2Drive: success rate {:.2} %, efficiency {}, comfort {}",
        b2d.success_rate,
        percent(b2d.efficiency),
        percent(b2d.comfort)
    );
    out
}
