use super::*;

#[test]
fn settings_beyond_any_physical_range_are_refused_with_their_key() {
    let read = |text: &str| {
        toml::from_str::<GridToml>(text)
            .unwrap()
            .apply()
            .map_err(|e| e.to_string())
    };
    assert_eq!(
        read("distance_std = 1e30").unwrap_err(),
        "grid filter settings: `distance_std` = 1000000000000000000000000000000 is beyond any physical range (0 ..= 100 m)"
    );
    assert_eq!(
        read("heading_std_per_metre = 500.0").unwrap_err(),
        "grid filter settings: `heading_std_per_metre` = 500 is beyond any physical range (0 ..= 100 rad/m)"
    );
    assert_eq!(
        read("resolution = 1e-5").unwrap_err(),
        "grid filter settings: `resolution` = 0.00001 is beyond any physical range (0.001 ..= 10 m)"
    );
    assert!(read("resolution = 0.0").unwrap_err().contains("resolution"));
    assert!(
        read("resolution = -0.05")
            .unwrap_err()
            .contains("resolution")
    );
    for base in ["default", "untuned", "microcontroller"] {
        assert!(read(&format!("base = \"{base}\"")).is_ok(), "{base}");
    }
}
