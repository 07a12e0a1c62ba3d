//! Wall time of every step of `cargo xtask test`, and the sorted summary it ends with.
//!
//! Why: the whole run has to stay well under the CI's 15 minutes on two cores, and the
//! one number at the end does not say where the time goes. Every command the test
//! command starts records its duration here; a child lane (`side.rs`) appends its
//! records to a file the MCU lane reads back when it joins the lane.

use std::io::Write;
use std::sync::Mutex;

/// Environment variable naming the file a side-lane child appends its records to.
pub const FILE_VAR: &str = "XTASK_TIMES_FILE";

/// One step: what ran, in which lane, and how long it took.
struct Step {
    label: String,
    seconds: f64,
}

static STEPS: Mutex<Vec<Step>> = Mutex::new(Vec::new());

/// Records one step (and appends it to [`FILE_VAR`]'s file when this is a child lane).
pub fn record(label: &str, seconds: f64) {
    // A label is one line: the summary is line-based and the file is tab-separated.
    let label = label.replace(['\n', '\t'], " ");
    if let Some(path) = std::env::var_os(FILE_VAR) {
        if let Ok(mut file) = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
        {
            // Timing is a report, never a reason to fail the run.
            let _ = writeln!(file, "{seconds:.3}\t{label}");
        }
    }
    if let Ok(mut steps) = STEPS.lock() {
        steps.push(Step { label, seconds });
    }
}

/// Records the steps a child lane wrote to `path`, each label prefixed with `lane`.
pub fn import(path: &std::path::Path, lane: &str) {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    for (seconds, label) in text.lines().filter_map(parse_line) {
        if let Ok(mut steps) = STEPS.lock() {
            steps.push(Step {
                label: format!("{lane}{label}"),
                seconds,
            });
        }
    }
}

fn parse_line(line: &str) -> Option<(f64, &str)> {
    let (seconds, label) = line.split_once('\t')?;
    Some((seconds.parse().ok()?, label))
}

/// The steps, slowest first, with each step's share of `total` seconds.
pub fn summary(total: f64) -> String {
    let steps = STEPS.lock().map(|s| {
        let mut v: Vec<(f64, String)> = s.iter().map(|s| (s.seconds, s.label.clone())).collect();
        v.sort_by(|a, b| b.0.total_cmp(&a.0));
        v
    });
    let steps = steps.unwrap_or_default();
    let mut out = format!(
        "\nxtask: step times, slowest first (wall clock, {total:.0} s in all; the three lanes \
         run side by side, so a step's time includes waiting for a core):\n"
    );
    for (seconds, label) in &steps {
        let share = if total > 0.0 {
            100.0 * seconds / total
        } else {
            0.0
        };
        out.push_str(&format!("  {seconds:>7.1} s {share:>4.0} %  {label}\n"));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::parse_line;

    #[test]
    fn reads_back_what_record_writes() {
        assert_eq!(
            parse_line("12.500\tcargo build --release"),
            Some((12.5, "cargo build --release"))
        );
        assert_eq!(parse_line("no tab"), None);
        assert_eq!(parse_line("x\tlabel"), None);
    }
}
