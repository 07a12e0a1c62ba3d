//! The firmware's baked configuration (issue 6): `build.rs` parses `bridge.toml` into
//! `shared::bridge::Config`, validates it and writes it postcard-encoded;
//! `firmware/config.rs` decodes it with `postcard::from_bytes` and validates again.
//! These tests run the same steps on the host: the shipped file must survive the
//! trip unchanged, and a bad file must be refused with the key named.

use shared::bridge::{Config, ConfigError, Protocol};

const SHIPPED: &str = include_str!("../../bridge.toml");

/// What build.rs does, returning the bytes or the message it would fail the build with.
fn bake(text: &str) -> Result<Vec<u8>, String> {
    let config: Config = toml::from_str(text).map_err(|e| e.to_string())?;
    config.validate().map_err(|e| e.to_string())?;
    postcard::to_stdvec(&config).map_err(|e| e.to_string())
}

/// What the firmware does at boot.
fn load(bytes: &[u8]) -> Option<Config> {
    let config: Config = postcard::from_bytes(bytes).ok()?;
    config.validate().ok()?;
    Some(config)
}

#[test]
fn shipped_file_bakes_and_loads_unchanged() {
    let bytes = bake(SHIPPED).unwrap();
    let loaded = load(&bytes).unwrap();
    assert_eq!(loaded, toml::from_str::<Config>(SHIPPED).unwrap());
    assert_eq!(loaded.controller.protocol, Protocol::Xy2);
    assert_eq!(loaded.head.protocol, Protocol::Xy3);
}

#[test]
fn every_field_survives_the_trip() {
    // Non-default values everywhere the firmware reads them.
    let text = r#"
        [controller]
        protocol = "xy3"
        xy3.back_rate = 921600
        xy3.lines = ["x", "y", "u", "w"]
        xy2 = { mode = "extended18", parity = "data_only", polarity = "high_is_ok" }
        [head]
        protocol = "xy2"
        xy2 = { mode = "extended18", enhanced_commands = false, polarity = "high_is_ok" }
        xy3.frame_bits = 32
        [axes]
        swap_xy = true
        offset_x = -5
        [z]
        source = "none"
        [output]
        frame_rate_hz = 50000
        [failsafe]
        after_hold = "stop"
        park_x = 0x12345
        park_u = 0x23456
        park_w = 0x34567
    "#;
    let want: Config = toml::from_str(text).unwrap();
    assert_ne!(want, Config::default());
    assert_eq!(load(&bake(text).unwrap()), Some(want));
}

#[test]
fn bad_files_name_the_key() {
    let invalid = "[head]\nprotocol = \"xy2\"\nxy2.mode = \"extended18\"\n";
    let err = bake(invalid).unwrap_err();
    assert!(err.starts_with("head.xy2.enhanced_commands:"), "{err}");

    let typo = SHIPPED.replace("frame_rate_hz = 100000", "frame_rate = 100000");
    let err = bake(&typo).unwrap_err();
    assert!(err.contains("unknown field `frame_rate`"), "{err}");

    let park = SHIPPED.replace("park_w = 0x80000", "park_w = 0x100000");
    let err = bake(&park).unwrap_err();
    assert!(err.starts_with("failsafe.park_w:"), "{err}");

    let typo = SHIPPED.replace("park_u = 0x80000", "park_v = 0x80000");
    let err = bake(&typo).unwrap_err();
    assert!(err.contains("unknown field `park_v`"), "{err}");

    let range = SHIPPED.replace("frame_rate_hz = 100000", "frame_rate_hz = 500");
    let err = bake(&range).unwrap_err();
    assert_eq!(err, ConfigError::FrameRate(500).to_string());
}

#[test]
fn damaged_bytes_are_refused_at_boot() {
    let bytes = bake(SHIPPED).unwrap();
    // Truncated anywhere: never a configuration.
    for n in 0..bytes.len() {
        assert_eq!(load(&bytes[..n]), None, "truncated to {n}");
    }
    // A frame rate out of range slips past postcard but not past validate().
    let mut bad = toml::from_str::<Config>(SHIPPED).unwrap();
    bad.output.frame_rate_hz = 7;
    assert_eq!(load(&postcard::to_stdvec(&bad).unwrap()), None);
}
