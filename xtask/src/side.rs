//! The child lanes of `cargo xtask test`: this program again (`xtask test-lane
//! <name>`) as a child process, its output in `target/xtask-<name>.log`, printed when
//! the lane is joined (module doc of `main.rs` for why and what runs where).
//!
//! A child leads a process group of its own, so a failed lane can be stopped with
//! every cargo and rustc it started by one signal. Ctrl-C reaches only the terminal's
//! foreground group, so the child also watches its parent and stops its group when
//! the parent is gone.

use crate::{root, timing, Result};
use std::fs;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A running child lane.
pub struct Lane {
    name: &'static str,
    child: Child,
    /// Set once the child has exited (seen by [`check`] or [`Lane::finish`]).
    status: Option<ExitStatus>,
    log: PathBuf,
    times: PathBuf,
    started: Instant,
}

impl Lane {
    /// Starts `xtask test-lane <name>`; `what` says what it runs, for the log.
    pub fn start(name: &'static str, what: &str) -> Result<Self> {
        let dir = root().join("target");
        fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
        let log = dir.join(format!("xtask-{name}.log"));
        let times = dir.join(format!("xtask-{name}.times"));
        let _ = fs::remove_file(&times);
        let out =
            fs::File::create(&log).map_err(|e| format!("cannot create {}: {e}", log.display()))?;
        let err = out.try_clone().map_err(|e| e.to_string())?;
        let exe = std::env::current_exe().map_err(|e| format!("cannot find xtask: {e}"))?;
        eprintln!(
            "\n==> {name} lane started ({what}), output in {}",
            log.display()
        );
        let child = Command::new(exe)
            .args(["test-lane", name])
            .env(timing::FILE_VAR, &times)
            // Not in the terminal's foreground group: it must never read the terminal.
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .process_group(0)
            .spawn()
            .map_err(|e| format!("cannot start the {name} lane: {e}"))?;
        Ok(Lane {
            name,
            child,
            status: None,
            log,
            times,
            started: Instant::now(),
        })
    }

    /// Stops the child's whole process group.
    fn stop(&mut self) {
        // The child leads its group: its pid is the group id.
        let group = -(self.child.id() as libc::pid_t);
        // SAFETY: kill(2) with a negative pid signals that process group only; no
        // memory is involved.
        unsafe { libc::kill(group, libc::SIGTERM) };
    }

    /// Waits for the lane (stops it first when `stop` and it still runs), prints its
    /// output and records its step times; fails if the lane failed.
    pub fn finish(mut self, stop: bool) -> Result {
        let running = self.status.is_none();
        if stop && running {
            self.stop();
        } else if running {
            eprintln!("\n==> waiting for the {} lane", self.name);
        }
        let waiting = Instant::now();
        let status = match self.status {
            Some(status) => status,
            None => self
                .child
                .wait()
                .map_err(|e| format!("{} lane: {e}", self.name))?,
        };
        let seconds = self.started.elapsed().as_secs_f64();
        let waited = waiting.elapsed().as_secs_f64();
        eprintln!("\n==> {} lane output ({})", self.name, self.log.display());
        print!("{}", fs::read_to_string(&self.log).unwrap_or_default());
        timing::import(&self.times, &format!("[{}] ", self.name));
        if stop && running {
            eprintln!("    ({} lane stopped after {seconds:.1} s)", self.name);
            return Ok(());
        }
        eprintln!(
            "    ({} lane: {seconds:.1} s; the MCU lane waited {waited:.1} s for it)",
            self.name
        );
        if !stop {
            timing::record(&format!("waiting for the {} lane", self.name), waited);
        }
        if status.success() {
            Ok(())
        } else {
            Err(format!(
                "the {} lane failed ({status}): see its output above or {}",
                self.name,
                self.log.display()
            ))
        }
    }
}

/// Fails when a child lane has exited with a failure (its output is printed when it is
/// joined), so the MCU lane stops early instead of building for minutes in vain.
pub fn check(lanes: &mut [Lane]) -> Result {
    for lane in lanes.iter_mut() {
        if lane.status.is_none() {
            lane.status = lane.child.try_wait().map_err(|e| e.to_string())?;
        }
        if let Some(status) = lane.status.filter(|s| !s.success()) {
            return Err(format!("the {} lane failed ({status})", lane.name));
        }
    }
    Ok(())
}

/// In a child lane: stops the child's whole process group once the parent
/// `cargo xtask test` is gone (Ctrl-C, or killed), so no cargo keeps running or holds
/// a build-directory lock after it.
pub fn watch_parent() {
    let parent = std::os::unix::process::parent_id();
    std::thread::spawn(move || loop {
        std::thread::sleep(Duration::from_millis(200));
        if std::os::unix::process::parent_id() != parent {
            // SAFETY: kill(2) with pid 0 signals this process's own group (this
            // process leads it); no memory is involved.
            unsafe { libc::kill(0, libc::SIGTERM) };
        }
    });
}
