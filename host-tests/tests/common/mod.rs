//! Helpers shared by the `bridge-sim` tests that run the built binary
//! (`bridge_sim`, `bridge_sim_decode`, `bridge_sim_bridge`): running it, `generate`,
//! and reading its JSON lines.

use std::path::{Path, PathBuf};
use std::process::Command;

use host_tests::sim::jsonl;

const BIN: &str = env!("CARGO_BIN_EXE_bridge-sim");

/// What a run printed and how it ended.
pub struct Out {
    /// Exit code (-1: killed by a signal).
    pub code: i32,
    /// Standard output.
    pub stdout: String,
    /// Standard error (the summary and errors).
    pub stderr: String,
}

/// Runs `bridge-sim args` in `cwd`. A panic is never an acceptable outcome, whatever
/// the input.
pub fn run_in(cwd: &Path, args: &[&str]) -> Out {
    let o = Command::new(BIN)
        .current_dir(cwd)
        .args(args)
        .output()
        .unwrap();
    let out = Out {
        code: o.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    };
    assert!(!out.stderr.contains("panicked"), "panic: {}", out.stderr);
    out
}

/// [`run_in`], which must succeed.
pub fn ok_in(cwd: &Path, args: &[&str]) -> Out {
    let o = run_in(cwd, args);
    assert_eq!(o.code, 0, "{args:?}: {}", o.stderr);
    o
}

/// The records of JSON lines text (line numbers dropped).
pub fn records<T: serde::de::DeserializeOwned>(text: &str) -> Vec<T> {
    jsonl::parse::<T>(text)
        .unwrap()
        .into_iter()
        .map(|(_, r)| r)
        .collect()
}

/// `generate args` into `d/name.vcd`, with the frames it sent in `d/name.jsonl`;
/// returns the VCD path and the JSON lines text.
pub fn generate(d: &Path, name: &str, args: &[&str]) -> (PathBuf, String) {
    let vcd = d.join(format!("{name}.vcd"));
    let jl = d.join(format!("{name}.jsonl"));
    let mut a = vec![
        "generate",
        "--output",
        vcd.to_str().unwrap(),
        "--frames-out",
        jl.to_str().unwrap(),
    ];
    a.extend_from_slice(args);
    ok_in(d, &a);
    let text = std::fs::read_to_string(jl).unwrap();
    (vcd, text)
}
