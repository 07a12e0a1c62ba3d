//! Runs every cargo-fuzz target of `fuzz/Cargo.toml` for a few seconds: builds them
//! once (`cargo +nightly fuzz build`), then `cargo +nightly fuzz run <target>` each.
//! A crash, a leak or a timeout found by libFuzzer fails the test command.

use crate::{root, Result};
use std::fs;
use std::process::Command;
use std::time::Instant;

/// Seconds of fuzzing per target: a smoke run in the test command (4 targets x 5 s);
/// run longer by hand (`cargo +nightly fuzz run <target>`).
const SECONDS: u32 = 5;

/// The `name`s of the `[[bin]]` tables of `fuzz/Cargo.toml` (a line scan: the
/// manifest is ours and flat, so no TOML parser is pulled in for it).
fn targets(manifest: &str) -> Vec<String> {
    let mut in_bin = false;
    let mut names = Vec::new();
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            in_bin = line == "[[bin]]";
        } else if let Some(value) = line.strip_prefix("name").map(str::trim_start) {
            if let (true, Some(value)) = (in_bin, value.strip_prefix('=')) {
                names.push(value.trim().trim_matches('"').to_string());
            }
        }
    }
    names
}

/// `cargo +nightly fuzz <args>` in `fuzz/`; the output goes to `log` when given.
fn cargo_fuzz(args: &[&str], log: Option<&std::path::Path>) -> Result {
    let started = Instant::now();
    eprintln!("\n==> cargo +nightly fuzz {}", args.join(" "));
    let mut cmd = Command::new("cargo");
    // `cargo xtask` runs under the pinned toolchain; let `+nightly` pick the fuzzer's.
    cmd.env_remove("RUSTUP_TOOLCHAIN")
        .env_remove("CARGO")
        .arg("+nightly")
        .arg("fuzz")
        .args(args)
        .current_dir(root().join("fuzz"));
    if let Some(log) = log {
        let file =
            fs::File::create(log).map_err(|e| format!("cannot create {}: {e}", log.display()))?;
        let err = file.try_clone().map_err(|e| e.to_string())?;
        cmd.stdout(file).stderr(err);
    }
    let status = cmd
        .status()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    let seconds = started.elapsed().as_secs_f64();
    eprintln!("    ({seconds:.1} s)");
    crate::timing::record(&format!("cargo +nightly fuzz {}", args.join(" ")), seconds);
    if status.success() {
        return Ok(());
    }
    let detail = log
        .and_then(|l| fs::read_to_string(l).ok())
        .map(|text| {
            let lines: Vec<&str> = text.lines().collect();
            format!("\n{}", lines[lines.len().saturating_sub(30)..].join("\n"))
        })
        .unwrap_or_default();
    Err(format!(
        "`cargo +nightly fuzz {}` failed: {status}{detail}",
        args.join(" ")
    ))
}

/// Checks the tools, builds all targets once and runs each for [`SECONDS`].
pub fn run() -> Result {
    let nightly = Command::new("cargo")
        .env_remove("RUSTUP_TOOLCHAIN")
        .args(["+nightly", "fuzz", "--version"])
        .output();
    if !nightly.is_ok_and(|o| o.status.success()) {
        return Err("fuzzing needs the nightly toolchain and cargo-fuzz: \
                    `rustup toolchain install nightly --profile minimal && cargo install cargo-fuzz --locked` \
                    (.ci/run does both)"
            .into());
    }
    let manifest_path = root().join("fuzz").join("Cargo.toml");
    let manifest = fs::read_to_string(&manifest_path)
        .map_err(|e| format!("cannot read {}: {e}", manifest_path.display()))?;
    let names = targets(&manifest);
    if names.is_empty() {
        return Err("fuzz/Cargo.toml lists no [[bin]] targets".into());
    }
    cargo_fuzz(&["build"], None)?;
    let logs = root().join("target").join("fuzz-logs");
    fs::create_dir_all(&logs).map_err(|e| format!("cannot create {}: {e}", logs.display()))?;
    let limit = format!("-max_total_time={SECONDS}");
    for name in &names {
        let log = logs.join(format!("{name}.log"));
        cargo_fuzz(&["run", name, "--", &limit], Some(&log))?;
        let text = fs::read_to_string(&log).unwrap_or_default();
        let done = text
            .lines()
            .rev()
            .find(|l| l.starts_with("Done "))
            .unwrap_or("(no summary)");
        println!("fuzz {name}: {done}");
    }
    println!("fuzz: {} targets, {SECONDS} s each, no crash", names.len());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::targets;

    #[test]
    fn finds_only_bin_names() {
        let manifest = "[package]\nname = \"pkg\"\n\n[[bin]]\nname = \"one\"\npath = \"a.rs\"\n\n\
                        [profile.release]\ndebug = 1\n\n[[bin]]\nname=\"two\"\n";
        assert_eq!(targets(manifest), ["one", "two"]);
    }
}
