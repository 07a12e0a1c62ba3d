//! The bench's result: pairs the guest's `BENCH <name> <frames>` lines (stdout) with
//! the plugin's `insn_count: window <n> <count>` lines (stderr) in order, subtracts
//! the empty first window (the cost of the window itself) and prints instructions per
//! 10 us frame. The budget applies to the worst-path workload ([`WORST_PATH`]), which
//! the table marks; every other workload must fit it too. Fails if a workload that is
//! not a listed exception exceeds [`BUDGET`], or if the worst path is missing.

use crate::Result;

/// Instructions one frame may cost on the worst path. A 10 us frame at 480 MHz is
/// 4800 cycles; keeping the per-frame protocol work at a quarter of that leaves the
/// rest for interrupts, DMA bookkeeping and the other direction.
pub const BUDGET: f64 = 1200.0;

/// Name prefix of the workload that chains the whole worst path of issue 4 (HANS-100
/// super decode of 5 channels at 3x, bridge, XY3-100 32-bit and XY2-100 encoders):
/// the figure the budget is about.
pub const WORST_PATH: &str = "worst path";

/// Workloads (by name prefix) known to exceed the budget, with the open work that
/// fixes them. They are measured and printed with a loud mark on every run, but do not
/// fail it: the figure is the evidence the open issue tracks. Remove an entry as soon
/// as its workload fits; a workload over budget that is not listed here fails the run.
pub const KNOWN_OVER_BUDGET: &[(&str, &str)] = &[
    (
        "hans ",
        "issue 4 open: the HANS-100 receiver (shared clock, two-window table gathering, \
         centre compares) still spends about 770 instructions gathering the reference \
         channel (940 at 40 MHz keeping its centres), ~165 copying one DMA ring (~435 \
         all five), ~430..525 of per-frame bookkeeping and ~210 per extra channel \
         (centre compare)",
    ),
    (
        WORST_PATH,
        "issue 4 open: THE WORST PATH IS OVER BUDGET. Nearly all of it is the HANS-100 \
         super-mode receiver (the `hans rx: super` row); bridge and both encoders take \
         the rest",
    ),
];

/// The open-work note of a workload allowed over budget, if it is one.
fn known_over_budget(name: &str) -> Option<&'static str> {
    KNOWN_OVER_BUDGET
        .iter()
        .find(|(prefix, _)| name.starts_with(prefix))
        .map(|&(_, why)| why)
}

/// One measured window.
pub struct Window<'a> {
    /// The workload's name.
    pub name: &'a str,
    /// Frames it processes (0 for the calibration window).
    pub frames: u32,
    /// Instructions the plugin counted in the window, window cost included.
    pub count: u64,
}

/// Pairs the bench's names with the plugin's counts; also returns the window cost
/// (the count of the empty first window, which is included in the returned list).
pub fn windows<'a>(stdout: &'a str, stderr: &str) -> Result<(Vec<Window<'a>>, u64)> {
    let names: Vec<(&str, u32)> = stdout
        .lines()
        .filter_map(|l| l.strip_prefix("BENCH "))
        .filter(|l| *l != "done")
        .map(|l| {
            let (name, frames) = l
                .rsplit_once(' ')
                .ok_or_else(|| format!("bad bench line `{l}`"))?;
            Ok((
                name,
                frames
                    .parse()
                    .map_err(|e| format!("bad frame count in `{l}`: {e}"))?,
            ))
        })
        .collect::<Result<_>>()?;
    let counts: Vec<u64> = stderr
        .lines()
        .filter_map(|l| l.strip_prefix("insn_count: window "))
        .map(|l| {
            let count = l.split_whitespace().nth(1).unwrap_or("");
            count
                .parse()
                .map_err(|e| format!("bad plugin line `{l}`: {e}"))
        })
        .collect::<Result<_>>()?;
    if !stdout.lines().any(|l| l == "BENCH done") {
        return Err("the bench did not finish".into());
    }
    if names.len() != counts.len() || names.is_empty() {
        return Err(format!(
            "{} bench windows announced but {} counted",
            names.len(),
            counts.len()
        ));
    }
    let windows: Vec<Window> = names
        .iter()
        .zip(&counts)
        .map(|(&(name, frames), &count)| Window {
            name,
            frames,
            count,
        })
        .collect();
    let overhead = match windows.first() {
        Some(w) if w.frames == 0 => w.count,
        _ => return Err("the first bench window must be the empty calibration window".into()),
    };
    Ok((windows, overhead))
}

/// Parses, prints the table and checks the budget.
pub fn report(stdout: &str, stderr: &str) -> Result {
    let (windows, overhead) = windows(stdout, stderr)?;

    println!("\ninstructions per 10 us frame (QEMU mps2-an500 Cortex-M7, window cost {overhead} subtracted):");
    println!(
        "  {:<56} {:>6} {:>8} {:>10}",
        "workload", "frames", "insns", "per frame"
    );
    let mut failed: Option<(&str, f64)> = None;
    let mut worst_path: Option<(&str, f64, bool)> = None;
    let mut open = Vec::new();
    for w in windows.iter().skip(1) {
        let net = w.count.saturating_sub(overhead);
        let per_frame = net as f64 / f64::from(w.frames.max(1));
        let over = per_frame > BUDGET;
        let known = known_over_budget(w.name).filter(|_| over);
        let is_worst = w.name.starts_with(WORST_PATH);
        let mark = match (is_worst, known.is_some()) {
            (true, true) => "  <== WORST PATH (budget): OVER BUDGET (open)",
            (true, false) => "  <== WORST PATH (budget)",
            (false, true) => "  OVER BUDGET (open)",
            (false, false) => "",
        };
        println!(
            "  {:<56} {:>6} {:>8} {:>10.1}{mark}",
            w.name, w.frames, net, per_frame
        );
        if is_worst {
            worst_path = Some((w.name, per_frame, known.is_some()));
        }
        match known {
            Some(why) => open.push(why),
            None if over && failed.is_none_or(|(_, p)| per_frame > p) => {
                failed = Some((w.name, per_frame))
            }
            None => {}
        }
    }
    open.dedup();
    for why in open {
        println!("  OVER BUDGET, not failing the run: {why}");
    }
    let Some((name, per_frame, known)) = worst_path else {
        return Err(format!(
            "the bench has no worst-path workload (name starting with `{WORST_PATH}`)"
        ));
    };
    println!(
        "budget figure ({name}): {per_frame:.1} instructions per frame (budget {BUDGET:.0}){}",
        if known {
            " -- OVER BUDGET, OPEN (see above)"
        } else {
            ""
        }
    );
    if let Some((name, per_frame)) = failed {
        return Err(format!(
            "`{name}` needs {per_frame:.1} instructions per frame, over the {BUDGET:.0} budget"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::report;

    const OUT: &str =
        "BENCH (call overhead) 0\nBENCH a 10\nBENCH b 4\nBENCH worst path: w 2\nBENCH done\n";
    /// Window costs: calibration 16, then a = 10 per frame, w = 1000 per frame.
    fn counts(b: u64) -> String {
        format!(
            "insn_count: window 0 16\ninsn_count: window 1 116\ninsn_count: window 2 {b}\n\
             insn_count: window 3 2016\n"
        )
    }

    #[test]
    fn within_budget_passes() {
        assert_eq!(report(OUT, &counts(4816)), Ok(()));
    }

    #[test]
    fn over_budget_fails_naming_the_workload() {
        // b: (4817 - 16) / 4 = 1200.25 per frame.
        let e = report(OUT, &counts(4817)).unwrap_err();
        assert!(e.contains("`b`") && e.contains("1200.2"), "{e}");
    }

    #[test]
    fn known_over_budget_workloads_are_reported_not_failed() {
        let out = OUT.replace("BENCH b 4", "BENCH hans rx 4");
        assert_eq!(report(&out, &counts(90016)), Ok(()));
        // A workload that is not listed still fails.
        let out = OUT.replace("BENCH b 4", "BENCH xy2 rx 4");
        assert!(report(&out, &counts(90016)).is_err());
    }

    #[test]
    fn worst_path_is_required_and_listed_while_over_budget() {
        let without = OUT.replace("BENCH worst path: w 2\n", "");
        let err = "insn_count: window 0 16\ninsn_count: window 1 116\ninsn_count: window 2 20\n";
        let e = report(&without, err).unwrap_err();
        assert!(e.contains("worst-path"), "{e}");
        // Over budget: listed as open work, so it is reported without failing.
        let over = counts(20).replace("window 3 2016", "window 3 40016");
        assert_eq!(report(OUT, &over), Ok(()));
    }

    #[test]
    fn missing_count_or_unfinished_run_fails() {
        let err = "insn_count: window 0 16\ninsn_count: window 1 116\ninsn_count: window 2 20\n";
        assert!(report(OUT, err).is_err());
        assert!(report(&OUT.replace("BENCH done\n", ""), &counts(20)).is_err());
    }

    #[test]
    fn first_window_must_be_the_empty_one() {
        let out = "BENCH a 10\nBENCH done\n";
        assert!(report(out, "insn_count: window 0 16\n").is_err());
    }
}
