//! `cargo xtask test`: the project's single test command (README, `.ci/run`).
//!
//! Why an xtask rather than a shell script: the steps need the host target named
//! explicitly (the root package's default target is the MCU), a portable way to read
//! the firmware ELF's section sizes, and clear failure messages; one small Rust
//! program does all of that on any machine with cargo.
//!
//! Steps (any failure fails the run; the lanes below say what runs beside what):
//! 1. `rustfmt` check of the whole workspace.
//! 2. clippy `-D warnings` for the host crates (all targets) and for the MCU target
//!    (firmware, `shared` with `defmt`, and `cm7`).
//! 3. All host tests (`shared` unit + property tests, `host-tests` integration tests).
//! 4. The firmware release build, then its flash and RAM use; the hardware-in-the-loop
//!    test binary (`firmware/hil`, run on a board with `cargo test --test hil`), for
//!    the default configuration and, built and linted, for every other pairing with
//!    an end-to-end test ([`HIL_PAIRINGS`]).
//! 5. `cm7` under QEMU (Cortex-M7): `shared`'s on-target tests, then the per-frame
//!    instruction counts against the budget (`qemu.rs`, `bench.rs`), and a check that
//!    the per-function profile (`cargo xtask profile`, `profile.rs`) adds up to them.
//! 6. A few seconds of every cargo-fuzz target (`fuzz.rs`).
//!
//! The steps run in three lanes, each in its own build directories so none waits for
//! another's cargo lock. After the format check, this process starts two children
//! (`xtask test-lane host|side`) and runs the *MCU lane* itself: MCU clippy, step 4.
//! The *host lane*: host clippy, step 3. The *side lane*: `cm7` clippy, steps 5, 6.
//! Why: on two cores one lane alone leaves a core idle much of the time (the
//! firmware and HIL builds are single-crate release builds with fat LTO and one
//! codegen unit; tests, QEMU and libFuzzer are mostly single-threaded); three lanes
//! keep both busy. A child's output goes to `target/xtask-<lane>.log` and is printed
//! after the MCU lane; a failed lane stops the others. Every step's wall time is
//! printed as it ends and again, slowest first, at the end of the run (`timing.rs`);
//! under three lanes a step's time includes waiting for a core.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::time::Instant;

mod bench;
mod elf_size;
mod fuzz;
mod placement;
mod profile;
mod qemu;
mod side;
mod timing;

/// The host target the host crates are built for (the workspace default is the MCU).
const HOST: &str = "x86_64-unknown-linux-gnu";
/// The MCU target.
pub(crate) const MCU: &str = "thumbv7em-none-eabihf";
/// The cargo profile of the host crates' tests and tools (root `Cargo.toml`).
const HOST_PROFILE: &str = "host-test";
/// Host-side packages.
const HOST_PACKAGES: &[&str] = &["xy-bridge-shared", "host-tests", "xtask"];
/// Clippy's trailing arguments: every warning is an error.
const DENY_WARNINGS: &[&str] = &["--", "-D", "warnings"];
/// Flash budget for the firmware image (issue 6).
const FLASH_BUDGET: u64 = 256 * 1024;
/// proptest's seed variable, and the seed the test command uses when it is unset.
const PROPTEST_SEED_VAR: &str = "PROPTEST_RNG_SEED";
const PROPTEST_SEED: &str = "20261202";
/// The configurations, besides the default `bridge.toml`, whose HIL image carries an
/// end-to-end test through the firmware's tasks (`firmware/hil/e2e`: each test is
/// compiled only into the image of its pairing, so each image is built once). The
/// XY2-100 word pairing has two images, one per geometry of `head_word`'s thinning
/// (40 and 41 output ticks per frame period; the test reads it from the config).
const HIL_PAIRINGS: &[&str] = &[
    "configs/hans-normal-to-xy2.toml",
    "configs/xy2-to-hans.toml",
    "configs/xy3-to-xy2.toml",
    "configs/xy2-word-to-xy2-word.toml",
    "configs/xy2-word-to-xy2-word-odd.toml",
    "configs/hans-normal-to-hans.toml",
];
/// The other configurations of `configs/` (no end-to-end test in their HIL image):
/// the firmware and its HIL binary are linted for each (`--bins --tests`, no link),
/// so every pairing the company ships builds warning-free, not only those with a
/// test image (an image with no end-to-end test once failed on unused checks).
const LINT_ONLY: &[&str] = &[
    "configs/xy3-to-xy3.toml",
    "configs/xy3-to-hans.toml",
    "configs/hans-super-to-xy2.toml",
    "configs/hans-super-to-xy3-32.toml",
    "configs/hans-super-to-hans.toml",
];
/// The build script's variable naming the configuration to bake (`build.rs`).
const CONFIG_VAR: &str = "XY_BRIDGE_CONFIG";
/// ITCM and DTCM sizes (RM0433 section 2.3.2), for the size report.
const ITCM_KIB: u64 = 64;
const DTCM_KIB: u64 = 128;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("test") => test_all(),
        Some("test-lane") => child_lane(args.get(1).map_or("", String::as_str)),
        Some("size") => firmware_size(),
        Some("qemu") => qemu::run(),
        Some("fuzz") => fuzz::run(),
        Some("profile") => profile::run(&args[1..]),
        _ => {
            eprintln!("usage: cargo xtask <test|size|qemu|fuzz|profile>");
            eprintln!("  test  fmt, clippy (host + MCU), all tests, firmware size, QEMU, fuzz");
            eprintln!("  size  firmware release build and its flash/RAM use");
            eprintln!("  qemu  on-target tests and instruction counts on an emulated Cortex-M7");
            eprintln!("  fuzz  every cargo-fuzz target for a few seconds");
            eprintln!("  profile <workload-substring> [--top N]");
            eprintln!("        instructions per frame per function of one bench workload");
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
    cargo_env(args, &[])
}

/// [`cargo`] with extra environment variables for the child.
fn cargo_env(args: &[&str], env: &[(&str, &str)]) -> Result {
    let shown: String = env
        .iter()
        .map(|(k, v)| format!("{k}={v} "))
        .chain(std::iter::once(format!("cargo {}", args.join(" "))))
        .collect();
    let mut command = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    command.args(args).envs(env.iter().copied());
    run_recorded(command, &shown)
}

/// Runs a program built by an earlier step, echoing it and its duration like [`cargo`].
fn run_timed(program: &Path) -> Result {
    run_recorded(Command::new(program), &program.display().to_string())
}

/// Runs `command` in the workspace root, echoing `shown` and recording its wall time.
fn run_recorded(mut command: Command, shown: &str) -> Result {
    let started = Instant::now();
    eprintln!("\n==> {shown}");
    let status = command
        .current_dir(root())
        .status()
        .map_err(|e| format!("cannot start {shown}: {e}"))?;
    let seconds = started.elapsed().as_secs_f64();
    eprintln!("    ({seconds:.1} s)");
    timing::record(shown, seconds);
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{shown}` exited with {status}"))
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
    // `cm7` and `fuzz` are workspaces of their own, which `--all` does not reach.
    for manifest in [qemu::CM7_MANIFEST, "fuzz/Cargo.toml"] {
        cargo(&["fmt", "--manifest-path", manifest, "--", "--check"])?;
    }
    let mut lanes = [
        side::Lane::start("host", "host clippy, host tests, pipeline latency")?,
        side::Lane::start("side", "cm7 clippy, QEMU tests and bench, fuzz")?,
    ];
    let main = mcu_lane(&mut lanes);
    // A red lane stops the others at once rather than waiting minutes for them.
    let results: Vec<Result> = lanes
        .into_iter()
        .map(|lane| lane.finish(main.is_err()))
        .collect();
    let total = started.elapsed().as_secs_f64();
    eprint!("{}", timing::summary(total));
    main?;
    results.into_iter().collect::<Result<Vec<()>>>()?;
    eprintln!("\nxtask: all checks passed in {total:.0} s");
    Ok(())
}

/// Runs the steps of one child lane (`xtask test-lane <name>`, see the module doc).
fn child_lane(name: &str) -> Result {
    side::watch_parent();
    let started = Instant::now();
    let result = match name {
        "host" => host_lane(),
        "side" => side_lane(),
        _ => Err(format!("no lane `{name}`")),
    };
    timing::record("lane, all its steps", started.elapsed().as_secs_f64());
    result
}

/// The host lane: host clippy, the host tests, the added-latency table.
fn host_lane() -> Result {
    // Linted under the host tests' profile: the build scripts and proc macros
    // (`syn`, `serde_derive`, `clap_derive`, ...) are then the same units for both
    // steps and built once (no code of ours depends on `debug_assertions`).
    let host_clippy = with_packages(
        vec![
            "clippy",
            "--profile",
            HOST_PROFILE,
            "--target",
            HOST,
            "--all-targets",
        ],
        HOST_PACKAGES,
    );
    cargo(&[host_clippy.as_slice(), DENY_WARNINGS].concat())?;

    // The host profile (root `Cargo.toml`): release optimisation without the
    // firmware's fat LTO, single codegen unit and debug info, which cost minutes of
    // compile time here and buy nothing for host tests.
    let host_test = with_packages(
        vec!["test", "--profile", HOST_PROFILE, "--target", HOST],
        HOST_PACKAGES,
    );
    // Property tests draw their cases from a fixed seed unless the caller sets one:
    // a red run is then reproducible from its log, and a green commit stays green
    // on a clean clone. Exploring new cases is a deliberate act
    // (`PROPTEST_RNG_SEED=$RANDOM cargo xtask test`, README "The two commands").
    let seed = std::env::var(PROPTEST_SEED_VAR).unwrap_or_else(|_| PROPTEST_SEED.into());
    eprintln!("    ({PROPTEST_SEED_VAR}={seed})");
    cargo_env(&host_test, &[(PROPTEST_SEED_VAR, &seed)])?;
    // The bridge's added latency per pairing, on the host pipeline (a few seconds).
    // The binary the test build just made (cargo builds a package's binaries for its
    // integration tests): a `cargo run` would build `host-tests` a second time, with
    // the dependency features of a non-test build (~25 s on a cold machine).
    let latency = root()
        .join("target")
        .join(HOST)
        .join(HOST_PROFILE)
        .join("pipeline-latency");
    run_timed(&latency)
}

/// The side lane: `cm7`'s lint, the QEMU tests and bench, the fuzz smoke runs.
fn side_lane() -> Result {
    let mcu_clippy = ["clippy", "--release", "--target", MCU];
    let cm7 = [
        &["--manifest-path", qemu::CM7_MANIFEST][..],
        &["--lib", "--bins"],
    ]
    .concat();
    cargo(&[&mcu_clippy[..], &cm7, DENY_WARNINGS].concat())?;
    qemu::run()?;
    fuzz::run()
}

/// The MCU lane, in this process: MCU clippy, the firmware and its size, the HIL
/// images. Between steps it looks at the child lanes and stops when one failed.
fn mcu_lane(lanes: &mut [side::Lane]) -> Result {
    let mcu_clippy = ["clippy", "--release", "--target", MCU];
    // `--tests` covers the HIL self-test binary (firmware/hil, harness = false).
    cargo(&[&mcu_clippy[..], &["--bins", "--tests"], DENY_WARNINGS].concat())?;
    let shared = ["-p", "xy-bridge-shared", "--features", "defmt"];
    cargo(&[&mcu_clippy[..], &shared, DENY_WARNINGS].concat())?;
    side::check(lanes)?;

    firmware_size()?;
    side::check(lanes)?;
    // The hardware-in-the-loop tests need a board to run, but must always build.
    cargo(&["build", "--release", "--target", MCU, "--test", "hil"])?;
    let baked = std::env::var(CONFIG_VAR).unwrap_or_else(|_| "bridge.toml".into());
    hil_placement(&baked)?;
    // The other pairings' images: lint and build (the crate is rebuilt for each
    // baked configuration; the dependencies are not), same placement rules.
    for config in HIL_PAIRINGS {
        side::check(lanes)?;
        let env = [(CONFIG_VAR, *config)];
        cargo_env(
            &[&mcu_clippy[..], &["--tests"], DENY_WARNINGS].concat(),
            &env,
        )?;
        cargo_env(
            &["build", "--release", "--target", MCU, "--test", "hil"],
            &env,
        )?;
        hil_placement(config)?;
    }
    for config in LINT_ONLY {
        side::check(lanes)?;
        cargo_env(
            &[&mcu_clippy[..], &["--bins", "--tests"], DENY_WARNINGS].concat(),
            &[(CONFIG_VAR, *config)],
        )?;
    }
    Ok(())
}

fn firmware_size() -> Result {
    cargo(&["build", "--release", "--target", MCU, "--bin", "firmware"])?;
    let elf = root()
        .join("target")
        .join(MCU)
        .join("release")
        .join("firmware");
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
    // Hot code in ITCM, hot state in DTCM, as memory.x asks (fails otherwise).
    let tcm = placement::check(&elf, &root().join("memory.x"))?;
    println!(
        "  ITCM: {} of {} KiB hot code ({} functions; cold in flash: {} functions, {} bytes); \
         DTCM: {} of {} KiB hot state ({} statics)",
        tcm.itcm,
        ITCM_KIB,
        tcm.itcm_functions,
        tcm.cold_functions,
        tcm.cold_bytes,
        tcm.dtcm,
        DTCM_KIB,
        tcm.dtcm_statics
    );
    if size.flash > FLASH_BUDGET {
        return Err(format!(
            "firmware flash use {} exceeds the {FLASH_BUDGET}-byte budget",
            size.flash
        ));
    }
    Ok(())
}

/// Placement check of the HIL binary cargo built last, baked with `config`. The HIL
/// binary links every role's `shared` code (the HANS-100 receiver too, which the
/// default firmware configuration leaves out): same placement rules.
fn hil_placement(config: &str) -> Result {
    let hil = newest_hil_elf()?;
    let tcm = placement::check(&hil, &root().join("memory.x"))?;
    println!(
        "hil ({config}): ITCM {} bytes ({} hot functions; cold in flash: {}), DTCM {} bytes",
        tcm.itcm, tcm.itcm_functions, tcm.cold_functions, tcm.dtcm
    );
    Ok(())
}

/// The HIL test binary cargo built last (`target/<MCU>/release/deps/hil-<hash>`).
fn newest_hil_elf() -> Result<PathBuf> {
    let deps = root().join("target").join(MCU).join("release").join("deps");
    let entries =
        std::fs::read_dir(&deps).map_err(|e| format!("cannot list {}: {e}", deps.display()))?;
    entries
        .filter_map(|e| e.ok())
        .filter(|e| {
            let name = e.file_name();
            let name = name.to_string_lossy();
            name.starts_with("hil-") && !name.contains('.')
        })
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .max()
        .map(|(_, path)| path)
        .ok_or_else(|| format!("no HIL test binary in {}", deps.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every file of `configs/` is linted by the test command: as an image with an
    /// end-to-end test or as a lint-only configuration, once.
    #[test]
    fn every_config_is_linted_once() {
        let mut files: Vec<String> = std::fs::read_dir(root().join("configs"))
            .expect("configs/ is readable")
            .map(|e| {
                format!(
                    "configs/{}",
                    e.expect("entry").file_name().to_string_lossy()
                )
            })
            .filter(|f| f.ends_with(".toml"))
            .collect();
        files.sort();
        let mut listed: Vec<String> = HIL_PAIRINGS
            .iter()
            .chain(LINT_ONLY)
            .map(|s| (*s).to_string())
            .collect();
        listed.sort();
        assert_eq!(files, listed);
    }
}
