//! Global localization trials scored: successes, scans to converge, the searches' cost,
//! and lost detection on the reference run (the `global` section of `metrics.json`).

use crate::drivers::global::{Reference, SearchSummary, Trial, TrialSettings};

/// The `global` section of `metrics.json`.
pub fn metrics(
    trials: &[Trial],
    reference: &Reference,
    settings: &TrialSettings,
    layers_bytes: usize,
) -> serde_json::Value {
    let successes = trials
        .iter()
        .filter(|t| t.scans_to_converge.is_some())
        .count();
    // A trial claims a wrong pose when the localizer says it is tracking (a confirmed
    // relocalization) while outside the tolerance: the failure a robot cannot see.
    let wrong_claims = trials
        .iter()
        .filter(|t| {
            t.state
                .iter()
                .zip(t.error_m.iter().zip(&t.error_deg))
                .any(|(s, (m, d))| {
                    *s == "tracking" && (*m > settings.tolerance_m || *d > settings.tolerance_deg)
                })
        })
        .count();
    let ending = |name: &str| {
        trials
            .iter()
            .filter(|t| t.state.last() == Some(&name))
            .count()
    };
    let mut hits: Vec<f32> = reference.hit_fractions.clone();
    hits.sort_by(f32::total_cmp);
    let pct = |p: f64| -> f64 {
        if hits.is_empty() {
            return f64::NAN;
        }
        let i = ((hits.len() - 1) as f64 * p).round() as usize;
        f64::from(hits.get(i).copied().unwrap_or(f32::NAN))
    };
    let searches: Vec<&SearchSummary> = trials.iter().filter_map(|t| t.search.as_ref()).collect();
    let max_nodes = searches.iter().map(|s| s.nodes).max().unwrap_or(0);
    let max_instr = searches
        .iter()
        .map(|s| s.estimated_m4_instructions)
        .max()
        .unwrap_or(0);
    let r = &settings.relocalization;
    // A search spanning scans spends about one work budget a scan at most.
    let max_instr_per_scan = searches
        .iter()
        .map(|s| {
            let work = u64::from(s.work.max(1));
            s.estimated_m4_instructions * work.min(u64::from(r.search.work_budget)) / work
        })
        .max()
        .unwrap_or(0);
    serde_json::json!({
        "trials": trials.len(),
        "successes": successes,
        "tracking_a_wrong_pose": wrong_claims,
        "final_states": {
            "tracking": ending("tracking"),
            "relocalized": ending("relocalized"),
            "lost": ending("lost"),
        },
        // Of the trials that converged (`per_trial` has every trial).
        "scans_to_converge": trials.iter().filter_map(|t| t.scans_to_converge).collect::<Vec<_>>(),
        "tolerance_m": settings.tolerance_m,
        "tolerance_deg": settings.tolerance_deg,
        "max_scans": settings.max_scans,
        "particles": settings.particles,
        "seed": settings.seed,
        "reference": "the localizer tracked from the true start pose",
        "searches_complete": searches.iter().filter(|s| s.complete).count(),
        "failed_searches": trials.iter().map(|t| t.failed_searches).sum::<u32>(),
        "max_nodes": max_nodes,
        "max_estimated_m4_instructions": max_instr,
        "max_estimated_m4_instructions_per_scan": max_instr_per_scan,
        "layers": {
            "levels": settings.levels,
            "bytes": layers_bytes,
        },
        "search": {
            "max_range_m": r.search.max_range,
            "max_beams": r.search.max_beams,
            "min_score_fraction": r.search.min_score_fraction,
            "relative_score": r.search.relative_score,
            "work_budget": r.search.work_budget,
            "search_scans": r.search_scans,
            "hypotheses": r.hypotheses,
        },
        "lost_detection": {
            "ratio": r.lost.ratio,
            "scans": r.lost.scans,
            "reference_lost_events": reference.lost_events,
            "reference_lost_scans": reference.lost_scans,
            "reference_expected_hit_fraction": reference.expected_hit_fraction,
            "reference_hit_fraction_p01": pct(0.01),
            "reference_hit_fraction_p05": pct(0.05),
            "reference_hit_fraction_median": pct(0.5),
        },
        "per_trial": trials,
    })
}
