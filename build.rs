//! Two jobs, both for the firmware's binaries and test binaries only (host builds of
//! the workspace never run this script: it belongs to the root firmware package):
//!
//! 1. **Bake the bridge configuration** (issue 6): read `bridge.toml` (or the file named
//!    by `XY_BRIDGE_CONFIG`), parse it into `shared::bridge::Config` and run
//!    `Config::validate()` -- the same types and checks the host tools and tests use --
//!    and write it postcard-encoded to `OUT_DIR/bridge_config.bin`, which
//!    `firmware/config.rs` includes and decodes at boot. A file that does not parse or
//!    validate stops the build with a message naming the key. Its two protocols also
//!    go to `OUT_DIR/bridge_roles.rs` as a `Roles` constant (`config::BAKED_ROLES`):
//!    the bridge loops pick their receiver and encoder by it, so the compiler leaves
//!    the other roles' receivers and encoders out of the image (and out of ITCM;
//!    README "Memory placement"). The same pair is emitted as the cfg
//!    `bridge_pairing = "<controller>_to_<head>"` (e.g. `"xy2_to_xy3"`): the
//!    hardware-in-the-loop binary compiles each end-to-end test only into the image
//!    whose pairing it is written for (`firmware/hil/e2e`).
//! 2. Put `memory.x` on the linker path and add the Cortex-M link scripts. The HIL
//!    test binary also links `hil_cold.x` ([`hil_cold_x`]): what only its tests
//!    use stays out of ITCM, so its ITCM holds what the firmware image of the
//!    baked pairing holds there.

use std::{env, fs, path::PathBuf, process};

use shared::bridge::{Config, Protocol};

/// Environment variable naming another configuration file (relative to the package
/// root, or absolute).
const CONFIG_ENV: &str = "XY_BRIDGE_CONFIG";
/// The file used when the variable is not set.
const DEFAULT_CONFIG: &str = "bridge.toml";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let config = bake_config(&out);
    fs::write(out.join("hil_cold.x"), hil_cold_x(&config)).expect("write OUT_DIR/hil_cold.x");

    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");

    // `link.x` (cortex-m-rt) includes memory.x; `defmt.x` places the defmt tables.
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");

    // The HIL test binary (firmware/hil) links like the firmware, plus embedded-test's
    // script, which keeps the test table the probe-rs runner reads from the ELF.
    println!("cargo:rustc-link-arg-tests=--nmagic");
    // Before link.x: lld hands an input section to the first output section whose
    // pattern matches in the order it read them, so `hil_cold.x`'s win over
    // `memory.x`'s `.itcm`.
    println!("cargo:rustc-link-arg-tests=-Thil_cold.x");
    println!("cargo:rustc-link-arg-tests=-Tlink.x");
    println!("cargo:rustc-link-arg-tests=-Tdefmt.x");
    println!("cargo:rustc-link-arg-tests=-Tembedded-test.x");
    // embedded-test's macro emits `cfg(rust_analyzer)`; declare it so check-cfg is quiet.
    println!("cargo::rustc-check-cfg=cfg(rust_analyzer)");
}

/// The protocols' names in `bridge_pairing` values.
const PROTOCOL_NAMES: [&str; 3] = ["xy2", "xy3", "hans"];

/// `p`'s name in a `bridge_pairing` value (one of [`PROTOCOL_NAMES`]).
fn cfg_name(p: Protocol) -> &'static str {
    match p {
        Protocol::Xy2 => "xy2",
        Protocol::Xy3 => "xy3",
        Protocol::Hans => "hans",
    }
}

/// Declares `bridge_pairing` with its nine values and sets it to `config`'s.
fn emit_pairing_cfg(config: &Config) {
    let values: Vec<String> = PROTOCOL_NAMES
        .iter()
        .flat_map(|c| {
            PROTOCOL_NAMES
                .iter()
                .map(move |h| format!("\"{c}_to_{h}\""))
        })
        .collect();
    println!(
        "cargo::rustc-check-cfg=cfg(bridge_pairing, values({}))",
        values.join(", ")
    );
    println!(
        "cargo::rustc-cfg=bridge_pairing=\"{}_to_{}\"",
        cfg_name(config.controller.protocol),
        cfg_name(config.head.protocol)
    );
}

/// The HIL test binary's extra linker script: an output section `.hil_cold` in
/// flash (after `.text`) that takes, before `memory.x`'s `.itcm` can, what only the
/// tests use, so that the HIL image's ITCM holds the baked firmware's hot code and
/// fits beside the two receivers of a HANS-100 -> HANS-100 image (README "Memory
/// placement"):
/// * the `hil` crate's own instances of hot generic code (the tests' closures
///   given to `shared::hans::rx::HansRx::push`; v0 spells the crate `..._3hil`);
/// * the XY2-100 / XY3-100 codec modules of the roles not baked: the bridge
///   loops link only the baked receiver and encoder (`config::BAKED_ROLES`), so
///   in this image only the driver-level tests call the others.
fn hil_cold_x(config: &Config) -> String {
    let (ctrl, head) = (config.controller.protocol, config.head.protocol);
    let mut patterns = vec!["    *(.text._R*_3hil*)".to_string()];
    for (module, baked) in [
        ("6shared3xy22rx", ctrl == Protocol::Xy2),
        ("6shared3xy22tx", head == Protocol::Xy2),
        ("6shared3xy32rx", ctrl == Protocol::Xy3),
        ("6shared3xy34step", ctrl == Protocol::Xy3),
        ("6shared3xy32tx", head == Protocol::Xy3),
    ] {
        if !baked {
            patterns.push(format!("    *(.text._R*{module}*)"));
        }
    }
    let mut script = String::from(
        "/* HIL test binary only, written by build.rs (`hil_cold_x`): what only the\n\
         \x20* tests use, in flash. Linked before link.x, so these patterns win over\n\
         \x20* memory.x's `.itcm`. */\n\
         SECTIONS\n{\n  .hil_cold : ALIGN(4)\n  {\n",
    );
    for p in patterns {
        script.push_str(&p);
        script.push('\n');
    }
    script.push_str("  } > FLASH\n} INSERT AFTER .text;\n");
    script
}

/// Parses, validates and writes the configuration; exits with a message on any
/// error. Returns it.
fn bake_config(out: &std::path::Path) -> Config {
    println!("cargo:rerun-if-env-changed={CONFIG_ENV}");
    let path = env::var_os(CONFIG_ENV)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(DEFAULT_CONFIG));
    println!("cargo:rerun-if-changed={}", path.display());
    let shown = path.display();

    let text = fs::read_to_string(&path).unwrap_or_else(|e| {
        fail(&format!(
            "cannot read bridge configuration {shown}: {e} (set {CONFIG_ENV} to another file)"
        ))
    });
    // toml's error names the key and shows the offending line.
    let config: Config = toml::from_str(&text).unwrap_or_else(|e| {
        fail(&format!(
            "bridge configuration {shown} does not parse:\n{e}"
        ))
    });
    if let Err(e) = config.validate() {
        // ConfigError's Display starts with the key, e.g. `head.xy2.enhanced_commands: ...`.
        fail(&format!("bridge configuration {shown} is invalid: {e}"));
    }
    let bytes = postcard::to_stdvec(&config)
        .unwrap_or_else(|e| fail(&format!("cannot encode the bridge configuration: {e}")));
    fs::write(out.join("bridge_config.bin"), bytes).expect("write OUT_DIR/bridge_config.bin");

    // The same roles `config::Roles::of` finds in the decoded bytes, as an expression
    // `firmware/config.rs` includes.
    let variant = |p: Protocol| match p {
        Protocol::Xy2 => "Xy2",
        Protocol::Xy3 => "Xy3",
        Protocol::Hans => "Hans",
    };
    let roles = format!(
        "Roles {{ controller: Controller::{}, head: Head::{} }}\n",
        variant(config.controller.protocol),
        variant(config.head.protocol)
    );
    fs::write(out.join("bridge_roles.rs"), roles).expect("write OUT_DIR/bridge_roles.rs");
    emit_pairing_cfg(&config);
    config
}

/// Stops the build. Cargo prints a failed build script's stderr.
fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    process::exit(1)
}
