//! Unit tests of reading, writing, checking and merging results.

use super::*;

#[test]
fn dates() {
    assert_eq!(utc_strings(0).0, "1970-01-01T00:00:00Z");
    assert_eq!(utc_strings(951_782_400).0, "2000-02-29T00:00:00Z");
    // The run stamp is the ISO time without its separators.
    let (iso, stamp) = utc_strings(1_700_000_000);
    assert_eq!(iso, "2023-11-14T22:13:20Z");
    assert_eq!(stamp, iso.replace(['-', ':'], ""));
}

#[test]
fn merge_combines_shards_and_refuses_mismatches() {
    use tests_support::{results, row};
    let mut a = results(vec![row("sdf", "a", 1.0, None, 1)]);
    a.provenance.machine = "alpha".into();
    a.shard = Some("1/2".into());
    let mut b = results(vec![row("mesh", "b", 2.0, None, 1)]);
    b.provenance.machine = "beta".into();
    b.shard = Some("2/2".into());
    let m = Results::merge(
        vec![("A".into(), a.clone()), ("B".into(), b.clone())],
        "merged".into(),
        "marchmesh merge A B".into(),
    )
    .unwrap();
    assert_eq!(m.rows.len(), 2);
    assert_eq!(m.rows[0].machine, "alpha");
    assert_eq!(m.rows[1].machine, "beta");
    assert_eq!(m.merged_from.len(), 2);
    assert_eq!(m.merged_from[1].shard.as_deref(), Some("2/2"));
    assert_eq!(m.provenance.command, "marchmesh merge A B");

    let mut other_suite = b.clone();
    other_suite.suite = "scaling".into();
    let e = Results::merge(
        vec![("A".into(), a.clone()), ("B".into(), other_suite)],
        String::new(),
        String::new(),
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("A ran suite \"suite\" but B ran \"scaling\""),
        "{e}"
    );

    let mut other_commit = b.clone();
    other_commit.provenance.git_commit = "0123abc".into();
    let e = Results::merge(
        vec![("A".into(), a.clone()), ("B".into(), other_commit)],
        String::new(),
        String::new(),
    )
    .unwrap_err();
    assert!(matches!(e, MergeError::CommitMismatch { .. }), "{e}");
    assert!(e.to_string().contains("0123abc"), "{e}");

    let mut dirty = b.clone();
    dirty.provenance.git_dirty = !a.provenance.git_dirty;
    assert!(matches!(
        Results::merge(
            vec![("A".into(), a.clone()), ("B".into(), dirty)],
            String::new(),
            String::new()
        ),
        Err(MergeError::CommitMismatch { .. })
    ));

    let e = Results::merge(
        vec![("A".into(), a.clone()), ("A again".into(), a)],
        String::new(),
        String::new(),
    )
    .unwrap_err();
    assert!(matches!(e, MergeError::Overlap { .. }), "{e}");
    assert_eq!(
        Results::merge(vec![], String::new(), String::new()),
        Err(MergeError::Empty)
    );
}

#[test]
fn the_accuracy_columns_are_the_ones_set_accuracy_fills() {
    assert_eq!(
        accuracy_columns(),
        [
            "silhouette_mismatch_pct",
            "depth_err_mean",
            "depth_err_p95",
            "depth_err_max",
            "depth_err_p95_rel_scene",
            "depth_err_max_rel_scene",
            "scene_size_world",
            "normal_err_deg_mean",
            "normal_err_deg_p95",
            "depth_err_rel_max",
            "depth_err_rel_tail_px",
            "normal_err_deg_max",
            "normal_err_deg_tail_px",
            "psnr_db",
            "ssim",
        ]
    );
    let row = Row {
        notes: "no reference".into(),
        ..Row::default()
    };
    assert!(row.why_empty("ssim").is_some() && row.why_empty("steps_mean").is_none());
}

#[test]
fn merge_refuses_a_configuration_missing_in_one_input_and_measured_in_another() {
    use tests_support::{results, row};
    let a = results(vec![row("sdf", "a", 1.0, None, 1)]);
    let mut b = results(vec![]);
    b.interrupted = true;
    b.missing = vec![a.rows[0].config_id.clone()];
    let e = Results::merge(
        vec![("A".into(), a), ("B".into(), b)],
        String::new(),
        String::new(),
    )
    .unwrap_err();
    assert!(matches!(e, MergeError::Overlap { .. }), "{e}");
}

#[test]
fn failures_repeating_a_row_or_each_other_are_refused_naming_the_id() {
    use tests_support::{results, row};
    let base = results(vec![row("sdf", "a", 1.0, None, 1)]);
    let id = base.rows[0].config_id.clone();
    let failure = |id: &str| Failure {
        config_id: id.into(),
        error: "boom".into(),
    };
    let mut beside = base.clone();
    beside.failures = vec![failure(&id)];
    let (at, why) = beside.check_unique_rows().unwrap_err();
    assert_eq!(at, "failures[0].config_id");
    assert!(
        why.contains(&id) && why.contains("failed but has a row"),
        "{why}"
    );
    let mut twice = base.clone();
    twice.failures = vec![failure("zz"), failure("zz")];
    let (at, why) = twice.check_unique_rows().unwrap_err();
    assert_eq!(at, "failures[1].config_id");
    assert!(why.contains("zz") && why.contains("failed twice"), "{why}");
    let mut missing = base.clone();
    missing.failures = vec![failure("zz")];
    missing.missing = vec!["zz".into()];
    let (at, why) = missing.check_unique_rows().unwrap_err();
    assert_eq!(at, "missing[0]");
    assert!(why.contains("missing but failed"), "{why}");
    let mut fine = base;
    fine.failures = vec![failure("zz")];
    fine.check_unique_rows().unwrap();
}

#[test]
fn header_has_units_and_every_field() {
    let h = csv_header();
    assert_eq!(h.len(), 61);
    for c in [
        "render_ms_median",
        "render_cpu_ms_median",
        "mrays_per_cpu_s",
        "machine",
        "peak_heap_bytes_render",
        "depth_err_p95",
        "mrays_per_s",
    ] {
        assert!(h.iter().any(|x| x == c), "{c}");
    }
}
