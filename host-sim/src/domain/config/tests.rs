use super::*;

#[test]
fn builtins_parse_and_overlay_changes_only_given_keys() {
    let base = Settings::load("mrclam", None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.toml");
    std::fs::write(&p, "[sighting]\nrange_std = 0.25\n").unwrap();
    let s = Settings::load("mrclam", Some(&p)).unwrap();
    assert_eq!(s.sighting.range_std, 0.25);
    assert_eq!(s.sighting.bearing_std, base.sighting.bearing_std);
    assert_eq!(s.odometry, base.odometry);
    Settings::load("sim", None).unwrap();
    std::fs::write(&p, "[sighting]\nrange_sdt = 0.25\n").unwrap();
    assert!(
        Settings::load("mrclam", Some(&p)).is_err(),
        "typos are refused"
    );
    std::fs::write(&p, "[sighting]\nrange_std = -1.0\n").unwrap();
    assert!(Settings::load("mrclam", Some(&p)).is_err());
    // Finite, but beyond any physical range: refused with the key and the range.
    for (text, expected) in [
        (
            "[sighting]\nrange_std = 1e30\n",
            "sighting.range_std = 1000000000000000000000000000000: beyond any physical range (0 ..= 100)",
        ),
        (
            "[odometry]\nlatency_s = 3600.0\n",
            "odometry.latency_s = 3600: beyond any physical range (0 ..= 10)",
        ),
        (
            "[sighting]\nbearing_std = 7.0\n",
            "sighting.bearing_std = 7: beyond any physical range (0 ..= 3.141592653589793)",
        ),
    ] {
        std::fs::write(&p, text).unwrap();
        let e = format!("{:#}", Settings::load("mrclam", Some(&p)).unwrap_err());
        assert!(e.contains(expected), "{e}");
    }
    // The unknown-id overlay applies to ICNN/JCBB only.
    std::fs::write(&p, "[unknown_ids.sighting]\nrange_std = 0.3\n").unwrap();
    let known = Settings::load_for("mrclam", Some(&p), Some(AssociationMode::Known)).unwrap();
    let jcbb = Settings::load_for("mrclam", Some(&p), Some(AssociationMode::Jcbb)).unwrap();
    assert_eq!(known.sighting.range_std, base.sighting.range_std);
    assert_eq!(jcbb.sighting.range_std, 0.3);
    assert_eq!(jcbb.association.mode, AssociationMode::Jcbb);
}

#[test]
fn a_value_beyond_f32_is_refused_with_its_key() {
    let mut base = Settings::load("mrclam", None).unwrap();
    base.validate().unwrap();
    let huge = 1e39; // finite as an f64, ∞ as an f32
    type SetValue = fn(&mut Settings, f64);
    // Keys without a physical bound (the noise figures have one, checked first:
    // `builtins_parse_and_overlay_changes_only_given_keys`).
    let cases: [(SetValue, &str); 3] = [
        (|s, v| s.sighting.mount[2] = v, "sighting.mount"),
        (|s, v| s.recovery.huber_sigma = v, "recovery.huber_sigma"),
        (|s, v| s.recovery.heading_std = v, "recovery.heading_std"),
    ];
    for (set, key) in cases {
        let mut s = base.clone();
        set(&mut s, huge);
        let err = format!("{:#}", s.validate().unwrap_err());
        assert!(
            err.starts_with(&format!("{key}: beyond the range of f32")),
            "{err}"
        );
        // Just inside f32's range it is taken.
        set(&mut s, 1e38);
        s.validate().unwrap();
    }
    // A noise figure that large is beyond any physical range before it is beyond f32.
    base.sighting.range_std = 1e38;
    let err = format!("{:#}", base.validate().unwrap_err());
    assert!(err.contains("beyond any physical range"), "{err}");
}

#[test]
fn a_files_keys_win_over_the_builtin_unknown_id_overlay() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.toml");
    let builtin_jcbb = Settings::load_for("mrclam", None, Some(AssociationMode::Jcbb)).unwrap();
    let builtin_known = Settings::load_for("mrclam", None, Some(AssociationMode::Known)).unwrap();
    // The built-in overlay changes these two keys for unknown ids (else this test
    // checks nothing).
    assert_ne!(
        builtin_jcbb.sighting.range_std,
        builtin_known.sighting.range_std
    );
    assert_ne!(
        builtin_jcbb.sighting.bearing_std,
        builtin_known.sighting.bearing_std
    );
    std::fs::write(
        &p,
        "[sighting]\nrange_std = 0.55\n[unknown_ids.sighting]\nbearing_std = 0.07\n",
    )
    .unwrap();
    let jcbb = Settings::load_for("mrclam", Some(&p), Some(AssociationMode::Jcbb)).unwrap();
    assert_eq!(jcbb.sighting.range_std, 0.55, "the file's plain key");
    assert_eq!(jcbb.sighting.bearing_std, 0.07, "the file's overlay");
    // Keys the file leaves alone keep the built-in overlay's values.
    assert_eq!(jcbb.odometry, builtin_jcbb.odometry);
    assert_eq!(jcbb.association, builtin_jcbb.association);
    let known = Settings::load_for("mrclam", Some(&p), Some(AssociationMode::Known)).unwrap();
    assert_eq!(known.sighting.range_std, 0.55);
    assert_eq!(
        known.sighting.bearing_std,
        builtin_known.sighting.bearing_std
    );
    // The mode may also come from the file.
    std::fs::write(&p, "[association]\nmode = \"icnn\"\n").unwrap();
    let icnn = Settings::load_for("mrclam", Some(&p), None).unwrap();
    assert_eq!(icnn.association.mode, AssociationMode::Icnn);
    assert_eq!(icnn.sighting, builtin_jcbb.sighting);
}

#[test]
fn the_files_supervision_is_the_firmwares() {
    // The firmware's session runs HealthConfig::DEFAULT_F32: the file's [recovery]
    // must be the same, so that `hil --dataset-settings` runs what `replay` runs.
    let s = Settings::load("mrclam", None).unwrap();
    assert_eq!(s.health_config::<f32>(), HealthConfig::DEFAULT_F32);
}

#[test]
fn a_range_bias_mean_needs_the_bias_as_a_state() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.toml");
    std::fs::write(
        &p,
        "[sighting]\nrange_bias_offset_mean = 0.17\nrange_bias_curvature_mean = -1.7\n",
    )
    .unwrap();
    let s = Settings::load("mrclam", Some(&p)).unwrap();
    assert_eq!(s.sighting.range_bias_offset_mean, 0.17);
    assert_eq!(s.sighting.range_bias_curvature_mean, -1.7);
    assert!(s.sighting.has_bias_mean());
    // Without a prior standard deviation the bias is no state: refused, not ignored.
    std::fs::write(
        &p,
        "[sighting]\nrange_bias_offset_std = 0.0\nrange_bias_curvature_std = 0.0\n\
         range_bias_offset_mean = 0.17\n",
    )
    .unwrap();
    let e = Settings::load("mrclam", Some(&p)).unwrap_err();
    assert!(format!("{e:#}").contains("range_bias_offset_mean"), "{e:#}");
    std::fs::write(&p, "[sighting]\nrange_bias_curvature_mean = nan\n").unwrap();
    assert!(Settings::load("mrclam", Some(&p)).is_err());
}
