//! `cargo xtask test`: the project's single test command (README, `.ci/run`).
//!
//! Why an xtask rather than a shell script: the steps need the host target named
//! explicitly (the root package's default target is the MCU), a portable way to read
//! the firmware ELF's section sizes, and clear failure messages; one small Rust
//! program does all of that on any machine with cargo.
//!
//! Steps, in order (each stops the run on failure):
//! 1. `rustfmt` check of the whole workspace.
//! 2. clippy `-D warnings` for the host crates (all targets) and for the MCU target
//!    (firmware and `shared` with `defmt`).
//! 3. All host tests (`shared` unit + property tests, `host-tests` integration tests).
//! 4. The firmware release build, then its flash and RAM use.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::time::Instant;

mod elf_size;

/// The host target the host crates are built for (the workspace default is the MCU).
const HOST: &str = "x86_64-unknown-linux-gnu";
/// The MCU target.
const MCU: &str = "thumbv7em-none-eabihf";
/// Host-side packages.
const HOST_PACKAGES: &[&str] = &["xy-bridge-shared", "host-tests", "xtask"];
/// Flash budget for the firmware image (issue 6).
const FLASH_BUDGET: u64 = 256 * 1024;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("test") => test_all(),
        Some("size") => firmware_size(),
        _ => {
            eprintln!("usage: cargo xtask <test|size>");
            eprintln!("  test  fmt, clippy (host + MCU), all tests, firmware build and size");
            eprintln!("  size  firmware release build and its flash/RAM use");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: FAILED: {e}");
            ExitCode::FAILURE
        }
    }
}

type Result<T = ()> = std::result::Result<T, String>;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives one level below the workspace root")
        .to_path_buf()
}

/// Runs `cargo <args>` in the workspace root, echoing the command and its duration.
fn cargo(args: &[&str]) -> Result {
    let started = Instant::now();
    eprintln!("\n==> cargo {}", args.join(" "));
    let status = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(args)
        .current_dir(root())
        .status()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    eprintln!("    ({:.1} s)", started.elapsed().as_secs_f64());
    if status.success() {
        Ok(())
    } else {
        Err(format!("`cargo {}` exited with {status}", args.join(" ")))
    }
}

fn with_packages<'a>(mut args: Vec<&'a str>, packages: &[&'a str]) -> Vec<&'a str> {
    for p in packages {
        args.push("-p");
        args.push(p);
    }
    args
}

fn test_all() -> Result {
    let started = Instant::now();
    cargo(&["fmt", "--all", "--", "--check"])?;

    let host_clippy = with_packages(vec!["clippy", "--target", HOST, "--all-targets"], HOST_PACKAGES);
    cargo(&[host_clippy.as_slice(), &["--", "-D", "warnings"]].concat())?;
    cargo(&["clippy", "--release", "--target", MCU, "--bins", "--", "-D", "warnings"])?;
    cargo(&[
        "clippy", "--release", "--target", MCU, "-p", "xy-bridge-shared", "--features", "defmt",
        "--", "-D", "warnings",
    ])?;

    let host_test = with_packages(vec!["test", "--release", "--target", HOST], HOST_PACKAGES);
    cargo(&host_test)?;

    firmware_size()?;
    eprintln!("\nxtask: all checks passed in {:.0} s", started.elapsed().as_secs_f64());
    Ok(())
}

fn firmware_size() -> Result {
    cargo(&["build", "--release", "--target", MCU, "--bin", "firmware"])?;
    let elf = root().join("target").join(MCU).join("release").join("firmware");
    let size = elf_size::read(&elf)?;
    println!(
        "firmware: flash {} bytes ({:.1} KiB of {} KiB budget), RAM {} bytes ({:.1} KiB) static",
        size.flash,
        size.flash as f64 / 1024.0,
        FLASH_BUDGET / 1024,
        size.ram,
        size.ram as f64 / 1024.0,
    );
    for (name, bytes) in &size.regions {
        println!("  {name:<8} {bytes:>8} bytes");
    }
    if size.flash > FLASH_BUDGET {
        return Err(format!("firmware flash use {} exceeds the {FLASH_BUDGET}-byte budget", size.flash));
    }
    Ok(())
}
