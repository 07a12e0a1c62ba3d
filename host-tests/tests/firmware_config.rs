//! The firmware's baked configuration (issue 6): `build.rs` parses `bridge.toml` into
//! `shared::bridge::Config`, validates it and writes it postcard-encoded;
//! `firmware/config.rs` decodes it with `postcard::from_bytes` and validates again.
//! These tests run the same steps on the host: the shipped file must survive the
//! trip unchanged, and a bad file must be refused with the key named.

use shared::bridge::{Config, ConfigError, Protocol, StatusForm};

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
        xy3.select = "always"
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

/// The protocol a `configs/` file name puts on one side (`xy2-word` -> XY2-100).
fn named(side: &str) -> Protocol {
    match side.split('-').next() {
        Some("xy2") => Protocol::Xy2,
        Some("xy3") => Protocol::Xy3,
        Some("hans") => Protocol::Hans,
        _ => panic!("configs/ file names are CONTROLLER-to-HEAD: {side}"),
    }
}

/// Every example in `configs/` (the rows of README "Firmware size", one per pairing
/// an engineer commissions) bakes as build.rs would, loads as the firmware would, and
/// is the pairing its name says: a file that drifted from the schema, or was copied
/// without its protocols changed, fails here and not at a factory's build.
#[test]
fn every_example_config_bakes_as_named() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    names.sort();
    let mut pairs = std::collections::HashSet::new();
    for path in &names {
        let text = std::fs::read_to_string(path).unwrap();
        let stem = path.file_stem().unwrap().to_str().unwrap();
        let bytes = bake(&text).unwrap_or_else(|e| panic!("{stem}: {e}"));
        let config = load(&bytes).unwrap_or_else(|| panic!("{stem}: does not load"));
        let (ctrl, head) = stem.split_once("-to-").expect("CONTROLLER-to-HEAD");
        assert_eq!(
            config.controller.protocol,
            named(ctrl),
            "{stem}: controller"
        );
        assert_eq!(config.head.protocol, named(head), "{stem}: head");
        assert_ne!(config, Config::default(), "{stem}: the default file again");
        assert!(
            text.contains(&format!("configs/{stem}.toml")),
            "{stem}: its header names another file"
        );
        pairs.insert((config.controller.protocol, config.head.protocol));
    }
    // With the shipped XY2-100 -> XY3-100, every one of the nine pairings has an
    // example.
    pairs.insert((Protocol::Xy2, Protocol::Xy3));
    assert_eq!(pairs.len(), 9, "{pairs:?}");
}

/// The two XY2-100 STATUS-word examples are the two images of the HIL end-to-end
/// test through `head_word` (xtask's `HIL_PAIRINGS`; the test takes either
/// geometry from the baked file): one with an even number of output ticks per frame
/// period (40 at 100 kHz: 20 samples a period) and one with an odd number (41 at
/// 97.56 kHz: 20 bits and an idle tick, 21 samples), as `tasks/encode.rs` derives
/// them. A rate edited into the other parity would leave one of `head_word`'s
/// thinning cases without its run through the tasks.
#[test]
fn xy2_word_examples_have_even_and_odd_head_ticks() {
    let ticks = |stem: &str| {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../configs")
            .join(format!("{stem}.toml"));
        let text = std::fs::read_to_string(&path).unwrap();
        let config: Config = toml::from_str(&text).unwrap();
        assert_eq!(config.head.protocol, Protocol::Xy2, "{stem}");
        assert_eq!(config.head.xy2.status, StatusForm::Word, "{stem}");
        shared::head_port::XY2_TICK_HZ / config.output.frame_rate_hz
    };
    assert_eq!(ticks("xy2-word-to-xy2-word"), 40);
    assert_eq!(ticks("xy2-word-to-xy2-word-odd"), 41);
}
