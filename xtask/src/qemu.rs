//! The `cm7` crate under QEMU: the on-target tests of `shared` and the instruction-count
//! bench, both on an emulated Cortex-M7 (`mps2-an500`) with semihosting for output and
//! exit status. See the README, section "On-target checks".

use crate::{cargo, root, Result, MCU};
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Longest a QEMU run may take (the whole suite takes well under a second today).
const TIMEOUT: Duration = Duration::from_secs(60);

/// `cm7` is its own workspace (see the root `Cargo.toml`), built in place.
pub const CM7_MANIFEST: &str = "cm7/Cargo.toml";

/// Builds `cm7` and the plugin, runs the tests and the bench, prints both results, and
/// checks that the bench's per-address profile adds up to its counts.
pub fn run() -> Result {
    let (elves, plugin) = build()?;

    let tests = qemu(&elves.join("tests"), &[], "tests")?;
    print!("{}", tests.stdout);
    if !tests.ok {
        return Err(format!(
            "on-target tests failed (QEMU: {}){}",
            tests.status,
            tail(&tests.stderr)
        ));
    }
    let summary = tests.stdout.lines().find(|l| l.starts_with("cm7 tests:"));
    let Some(summary) = summary else {
        return Err("on-target tests printed no summary line".into());
    };
    println!("on-target:{}", summary.trim_start_matches("cm7 tests:"));

    let elf = elves.join("bench");
    let bench = run_bench(&elf, &plugin)?;
    crate::bench::report(&bench.stdout, &bench.stderr)?;
    // The profile costs nothing extra (same run): prove `cargo xtask profile` adds up.
    let checked = crate::profile::check_all(&elf, &bench.stdout, &bench.stderr)?;
    println!("profile: per-function sums equal the bench counts in all {checked} windows");
    Ok(())
}

/// Builds the `cm7` binaries and the plugin; returns the ELF directory and the plugin.
pub fn build() -> Result<(PathBuf, PathBuf)> {
    cargo(&[
        "build",
        "--release",
        "--target",
        MCU,
        "--manifest-path",
        CM7_MANIFEST,
    ])?;
    let elves = root().join("cm7").join("target").join(MCU).join("release");
    Ok((elves, build_plugin()?))
}

/// Runs the bench ELF under the plugin with the per-address profile on; fails if the
/// guest fails.
pub fn run_bench(elf: &Path, plugin: &Path) -> Result<Run> {
    let (start, end) = markers(elf)?;
    let arg = format!(
        "{},start={start:#x},end={end:#x},profile=on",
        plugin.display()
    );
    let bench = qemu(elf, &["-d", "plugin", "-plugin", &arg], "bench")?;
    if !bench.ok {
        return Err(format!(
            "bench failed (QEMU: {}){}",
            bench.status,
            tail(&bench.stderr)
        ));
    }
    Ok(bench)
}

/// `gcc -shared -fPIC` of `cm7/plugin/insn_count.c` into `target/cm7/`.
fn build_plugin() -> Result<PathBuf> {
    let out_dir = root().join("target").join("cm7");
    fs::create_dir_all(&out_dir)
        .map_err(|e| format!("cannot create {}: {e}", out_dir.display()))?;
    let out = out_dir.join("insn_count.so");
    let src = root().join("cm7").join("plugin").join("insn_count.c");
    eprintln!(
        "\n==> gcc -shared -fPIC {} -o {}",
        src.display(),
        out.display()
    );
    let started = Instant::now();
    let status = Command::new("gcc")
        .args([
            "-shared",
            "-fPIC",
            "-O2",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-fvisibility=hidden",
        ])
        .arg(&src)
        .arg("-o")
        .arg(&out)
        .status()
        .map_err(|e| format!("cannot start gcc (install it: .ci/run does): {e}"))?;
    crate::timing::record("gcc (QEMU plugin)", started.elapsed().as_secs_f64());
    if status.success() {
        Ok(out)
    } else {
        Err(format!("building the QEMU plugin failed: {status}"))
    }
}

/// Entry addresses of `bench_start` and `bench_end` (Thumb bit cleared).
fn markers(elf: &Path) -> Result<(u64, u64)> {
    use object::{Object, ObjectSymbol};
    let data = fs::read(elf).map_err(|e| format!("cannot read {}: {e}", elf.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("{}: {e}", elf.display()))?;
    let find = |name: &str| {
        file.symbols()
            .find(|s| s.name() == Ok(name))
            .map(|s| s.address() & !1)
            .ok_or_else(|| format!("{}: no symbol `{name}`", elf.display()))
    };
    let (start, end) = (find("bench_start")?, find("bench_end")?);
    if start == end {
        return Err("bench_start and bench_end were merged into one address".into());
    }
    Ok((start, end))
}

/// What one QEMU run left behind.
pub struct Run {
    ok: bool,
    status: String,
    /// The guest's semihosting output.
    pub stdout: String,
    /// QEMU's log, where the plugin prints.
    pub stderr: String,
}

/// Runs `elf` on the emulated Cortex-M7 with a timeout; output goes through files so a
/// chatty guest cannot fill a pipe and stall.
fn qemu(elf: &Path, extra: &[&str], name: &str) -> Result<Run> {
    let dir = root().join("target").join("cm7");
    let (out_path, err_path) = (
        dir.join(format!("{name}.stdout")),
        dir.join(format!("{name}.stderr")),
    );
    let create =
        |p: &Path| fs::File::create(p).map_err(|e| format!("cannot create {}: {e}", p.display()));
    let mut cmd = Command::new("qemu-system-arm");
    cmd.args(["-machine", "mps2-an500", "-cpu", "cortex-m7", "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(extra)
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(create(&out_path)?)
        .stderr(create(&err_path)?);
    let shown: Vec<_> = cmd.get_args().map(|a| a.to_string_lossy()).collect();
    eprintln!("\n==> qemu-system-arm {}", shown.join(" "));
    let started = Instant::now();
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm (install it: .ci/run does): {e}"))?;
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            break status;
        }
        if started.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!(
                "QEMU ({name}) timed out after {} s",
                TIMEOUT.as_secs()
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let seconds = started.elapsed().as_secs_f64();
    eprintln!("    ({seconds:.1} s)");
    crate::timing::record(&format!("qemu-system-arm ({name})"), seconds);
    let read =
        |p: &Path| fs::read_to_string(p).map_err(|e| format!("cannot read {}: {e}", p.display()));
    Ok(Run {
        ok: status.success(),
        status: status.to_string(),
        stdout: read(&out_path)?,
        stderr: read(&err_path)?,
    })
}

/// The last lines of QEMU's stderr, for an error message (without the profile's lines).
fn tail(stderr: &str) -> String {
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.starts_with("insn_pc: "))
        .collect();
    let from = lines.len().saturating_sub(15);
    if lines.is_empty() {
        String::new()
    } else {
        format!("\n{}", lines[from..].join("\n"))
    }
}
