//! What a setting's rows say: the Pareto front of time against accuracy and the plain-language
//! verdict with its numbers.

use super::{bytes, opt};
use crate::results::Row;
use crate::verdicts::{Clock, Timing, backends, matched_accuracy};

/// The rows of one setting on the Pareto front of median render time (lower better) against
/// PSNR (higher better): no other row is at least as fast and at least as accurate while
/// strictly better in one. Sorted by time. Rows without PSNR are left out.
pub fn pareto_front(rows: &[&Row]) -> Vec<usize> {
    pareto_front_on(rows, Clock::Wall)
}

/// [`pareto_front`] with times on `clock` (the run's verdict clock).
pub fn pareto_front_on(rows: &[&Row], clock: Clock) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..rows.len())
        .filter(|&i| rows[i].psnr_db.is_some())
        .collect();
    idx.sort_by(|&a, &b| {
        clock
            .median_ms(rows[a])
            .total_cmp(&clock.median_ms(rows[b]))
            .then(
                rows[b]
                    .psnr_db
                    .unwrap_or(0.0)
                    .total_cmp(&rows[a].psnr_db.unwrap_or(0.0)),
            )
    });
    let mut front = Vec::new();
    let mut best = f64::NEG_INFINITY;
    for i in idx {
        let p = rows[i].psnr_db.unwrap_or(f64::NEG_INFINITY);
        if p > best {
            front.push(i);
            best = p;
        }
    }
    front
}

pub(crate) fn label(r: &Row) -> String {
    format!("{}:{}", r.backend, r.quality)
}

/// Plain-language verdict of one setting, each claim with its numbers; times on `timing`'s
/// clock, speed ratios from [`Timing::contest`].
pub fn verdict(rows: &[&Row], timing: Timing<'_>) -> Vec<String> {
    let mut out = Vec::new();
    let clock = timing.clock;
    let names = backends(rows.iter().copied());
    let of = |b: &str| {
        rows.iter()
            .copied()
            .filter(|r| r.backend == b)
            .collect::<Vec<_>>()
    };
    let fastest = rows
        .iter()
        .min_by(|a, b| clock.median_ms(a).total_cmp(&clock.median_ms(b)));
    if let Some(f) = fastest {
        out.push(format!(
            "Fastest configuration: {} at {:.2} ms {} time ({:.2} Mrays/s, PSNR {} dB).",
            label(f),
            clock.median_ms(f),
            clock.name(),
            f.mrays_per_s,
            opt(f.psnr_db, 1)
        ));
    }
    if names.len() >= 2 {
        // Speed at matched accuracy: for each PSNR target reached by some row, which backend
        // reaches it fastest; runs of the same winner are merged into ranges.
        let mut runs: Vec<(String, f64, f64, Option<String>)> = Vec::new(); // winner, from, to, contest at `to`
        for (q, contest) in matched_accuracy(rows, timing) {
            let (winner, said) = match contest {
                Ok(c) if c.decisive => (c.faster.clone(), Some(c.to_string())),
                Ok(c) => ("no clear winner".to_string(), Some(c.to_string())),
                Err(only) => (format!("{only} (only {only} reaches it)"), None),
            };
            match runs.last_mut() {
                Some(last) if last.0 == winner => {
                    last.2 = q;
                    last.3 = said;
                }
                _ => runs.push((winner, q, q, said)),
            }
        }
        if !runs.is_empty() {
            let parts: Vec<String> = runs
                .iter()
                .map(|(w, from, to, said)| {
                    let range = if from == to {
                        format!("PSNR target {from:.1} dB")
                    } else {
                        format!("PSNR targets {from:.1}-{to:.1} dB")
                    };
                    match said {
                        Some(c) if w == "no clear winner" => {
                            format!("{range}: {c}")
                        }
                        Some(c) => format!("{w} is faster for {range} ({c} at {to:.1} dB)"),
                        None => format!("{range}: {w}"),
                    }
                })
                .collect();
            out.push(format!("At matched accuracy: {}.", parts.join("; ")));
        }
        let best_psnr: Vec<String> = names
            .iter()
            .filter_map(|b| {
                let p = of(b)
                    .iter()
                    .filter_map(|r| r.psnr_db)
                    .fold(f64::NEG_INFINITY, f64::max);
                p.is_finite().then(|| format!("{b} {p:.1} dB"))
            })
            .collect();
        if best_psnr.len() == names.len() {
            out.push(format!(
                "Best accuracy reached: {} PSNR.",
                best_psnr.join(", ")
            ));
        }
        // Median memory over each backend's quality levels, least first.
        let mut mem: Vec<(&str, u64)> = names
            .iter()
            .map(|b| {
                let mut v: Vec<u64> = of(b).iter().map(|r| r.memory_bytes).collect();
                v.sort_unstable();
                (b.as_str(), v[v.len() / 2])
            })
            .collect();
        mem.sort_by_key(|m| m.1);
        if let [(less, lo), (more, hi), ..] = mem.as_slice()
            && *lo > 0
        {
            let listed: Vec<String> = names
                .iter()
                .filter_map(|b| mem.iter().find(|m| m.0 == b))
                .map(|(b, m)| format!("{b} {}", bytes(*m)))
                .collect();
            out.push(format!(
                "Memory: {less} uses {:.1}x less than {more} (median over quality levels: {}).",
                *hi as f64 / *lo as f64,
                listed.join(", ")
            ));
        }
    }
    let exhausted: Vec<&&Row> = rows
        .iter()
        .filter(|r| r.step_exhaustion_pct > 0.1)
        .collect();
    for r in exhausted {
        out.push(format!(
            "{} ends {:.2}% of its rays by step exhaustion (drawn as misses).",
            label(r),
            r.step_exhaustion_pct
        ));
    }
    for r in rows.iter().filter(|r| r.non_finite_count > 0) {
        out.push(format!(
            "{} produced {} NaN/inf values.",
            label(r),
            r.non_finite_count
        ));
    }
    out
}
