//! Puts `memory.x` on the linker path and adds the Cortex-M link scripts for the
//! firmware's binaries and test binaries only. Host builds of the workspace never run this script (it
//! belongs to the root firmware package), so they get no embedded link flags.

use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
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
    println!("cargo:rustc-link-arg-tests=-Tlink.x");
    println!("cargo:rustc-link-arg-tests=-Tdefmt.x");
    println!("cargo:rustc-link-arg-tests=-Tembedded-test.x");
    // embedded-test's macro emits `cfg(rust_analyzer)`; declare it so check-cfg is quiet.
    println!("cargo::rustc-check-cfg=cfg(rust_analyzer)");
}
