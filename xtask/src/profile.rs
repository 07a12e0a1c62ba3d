//! `cargo xtask profile <workload> [--top N]`: where the instructions of one bench
//! workload go. The bench already runs with the plugin's per-address profile on
//! (`profile=on`: `insn_pc: window <n> 0x<pc> <count>` lines after each window's
//! count); this maps those addresses to functions through the bench ELF's symbol
//! table and prints the heaviest functions per 10 us frame. Functions are symbols of
//! the final binary, so code inlined into a caller (most of `shared`, with fat LTO)
//! counts for that caller.

use crate::bench::{self, Window};
use crate::Result;
use std::collections::HashMap;
use std::path::Path;

/// Functions printed when `--top` is not given.
const DEFAULT_TOP: usize = 15;

/// Name shown for executed addresses that lie in no function symbol.
const NO_SYMBOL: &str = "<no function symbol>";

/// Parses the command line, runs the bench and prints the matching workload's profile.
pub fn run(args: &[String]) -> Result {
    let (pattern, top) = parse_args(args)?;
    let (elves, plugin) = crate::qemu::build()?;
    let elf = elves.join("bench");
    let bench = crate::qemu::run_bench(&elf, &plugin)?;
    let (windows, overhead) = bench::windows(&bench.stdout, &bench.stderr)?;
    let index = select(&windows, &pattern)?;
    let symbols = Symbols::from_elf(&elf)?;
    let pcs = pc_counts(&bench.stderr)?;
    let w = &windows[index];
    let functions = attribute(&symbols, window_pcs(&pcs, index), w.count, index)?;
    print!("{}", table(w, index, overhead, &functions, top));
    Ok(())
}

/// The check `cargo xtask test` runs on its bench output: in every window the
/// per-function counts add up to the plugin's total, and every executed address lies
/// in a function symbol. Returns the number of windows.
pub fn check_all(elf: &Path, stdout: &str, stderr: &str) -> Result<usize> {
    let (windows, _) = bench::windows(stdout, stderr)?;
    let symbols = Symbols::from_elf(elf)?;
    let pcs = pc_counts(stderr)?;
    for (i, w) in windows.iter().enumerate() {
        let functions = attribute(&symbols, window_pcs(&pcs, i), w.count, i)
            .map_err(|e| format!("`{}`: {e}", w.name))?;
        if let Some((_, n)) = functions.iter().find(|f| f.0 == NO_SYMBOL) {
            return Err(format!(
                "`{}`: {n} executed instructions lie in no function symbol of {}",
                w.name,
                elf.display()
            ));
        }
    }
    Ok(windows.len())
}

/// `<workload-substring> [--top N]`.
fn parse_args(args: &[String]) -> Result<(String, usize)> {
    let usage = "usage: cargo xtask profile <workload-name-substring> [--top N]";
    let mut pattern = None;
    let mut top = DEFAULT_TOP;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--top" {
            let n = it.next().ok_or(format!("--top needs a number; {usage}"))?;
            top = match n.parse() {
                Ok(n) if n > 0 => n,
                _ => return Err(format!("--top `{n}` is not a positive number; {usage}")),
            };
        } else if pattern.is_none() && !a.starts_with("--") {
            pattern = Some(a.clone());
        } else {
            return Err(format!("unexpected argument `{a}`; {usage}"));
        }
    }
    Ok((pattern.ok_or(usage)?, top))
}

/// Index of the one window whose name contains `pattern` (an exact name wins when
/// several contain it).
fn select(windows: &[Window], pattern: &str) -> Result<usize> {
    if let Some(i) = windows.iter().position(|w| w.name == pattern) {
        return Ok(i);
    }
    let found: Vec<usize> = (0..windows.len())
        .filter(|&i| windows[i].name.contains(pattern))
        .collect();
    let list = |ix: &mut dyn Iterator<Item = usize>| {
        ix.map(|i| format!("\n  {}", windows[i].name))
            .collect::<String>()
    };
    match found.as_slice() {
        [i] => Ok(*i),
        [] => Err(format!(
            "no workload name contains `{pattern}`; the workloads are:{}",
            list(&mut (0..windows.len()))
        )),
        _ => Err(format!(
            "`{pattern}` matches several workloads, be more specific:{}",
            list(&mut found.iter().copied())
        )),
    }
}

/// Per window, the executed addresses and how often each ran.
type PcCounts = HashMap<usize, Vec<(u64, u64)>>;

/// Parses the plugin's `insn_pc: window <n> 0x<pc> <count>` lines.
fn pc_counts(stderr: &str) -> Result<PcCounts> {
    let mut out = PcCounts::new();
    for line in stderr.lines() {
        let Some(rest) = line.strip_prefix("insn_pc: window ") else {
            continue;
        };
        let bad = |what: &str| format!("bad plugin line `{line}`: {what}");
        let fields: Vec<&str> = rest.split_whitespace().collect();
        let [window, pc, count] = fields.as_slice() else {
            return Err(bad("expected window, address and count"));
        };
        let window = window.parse().map_err(|_| bad("window"))?;
        let pc = pc
            .strip_prefix("0x")
            .and_then(|h| u64::from_str_radix(h, 16).ok())
            .ok_or_else(|| bad("address"))?;
        let count = count.parse().map_err(|_| bad("count"))?;
        out.entry(window).or_default().push((pc, count));
    }
    Ok(out)
}

fn window_pcs(pcs: &PcCounts, window: usize) -> &[(u64, u64)] {
    pcs.get(&window).map_or(&[], Vec::as_slice)
}

/// Function start/end (exclusive) and demangled name, sorted by start.
#[derive(Debug)]
struct Symbols(Vec<(u64, u64, String)>);

impl Symbols {
    /// The function symbols of an ELF (Thumb bit cleared, names demangled).
    fn from_elf(elf: &Path) -> Result<Self> {
        use object::{Object, ObjectSymbol, SymbolKind};
        let data = std::fs::read(elf).map_err(|e| format!("cannot read {}: {e}", elf.display()))?;
        let file = object::File::parse(&*data).map_err(|e| format!("{}: {e}", elf.display()))?;
        let functions = file
            .symbols()
            .filter(|s| s.kind() == SymbolKind::Text && s.is_definition())
            .filter_map(|s| {
                let name = s.name().ok()?;
                Some((s.address() & !1, s.size(), name.to_string()))
            })
            .collect();
        Ok(Self::new(functions))
    }

    /// From `(address, size, raw name)`; a symbol of size 0 reaches to the next one.
    /// Of several symbols at one address (aliases, folded functions) the first name in
    /// sort order is kept and the others counted.
    fn new(mut functions: Vec<(u64, u64, String)>) -> Self {
        functions.sort();
        let mut out: Vec<(u64, u64, String)> = Vec::new();
        let mut aliases = 0;
        for (i, (start, size, name)) in functions.iter().enumerate() {
            if out.last().is_some_and(|l| l.0 == *start) {
                aliases += 1;
                continue;
            }
            if aliases > 0 {
                if let Some(last) = out.last_mut() {
                    last.2 += &format!(" (+{aliases} aliases)");
                }
                aliases = 0;
            }
            let end = if *size > 0 {
                start + size
            } else {
                functions[i..]
                    .iter()
                    .map(|f| f.0)
                    .find(|&a| a > *start)
                    .unwrap_or(u64::MAX)
            };
            let name = format!("{:#}", rustc_demangle::demangle(name));
            out.push((*start, end, name));
        }
        if let (true, Some(last)) = (aliases > 0, out.last_mut()) {
            last.2 += &format!(" (+{aliases} aliases)");
        }
        Self(out)
    }

    /// The function containing `pc`.
    fn lookup(&self, pc: u64) -> Option<&str> {
        let after = self.0.partition_point(|f| f.0 <= pc);
        let (_, end, name) = self.0.get(after.checked_sub(1)?)?;
        (pc < *end).then_some(name.as_str())
    }
}

/// Sums a window's address counts per function, heaviest first; fails unless they add
/// up to the plugin's `total` for that window.
fn attribute(
    symbols: &Symbols,
    pcs: &[(u64, u64)],
    total: u64,
    window: usize,
) -> Result<Vec<(String, u64)>> {
    let mut per_function: HashMap<&str, u64> = HashMap::new();
    for &(pc, count) in pcs {
        *per_function
            .entry(symbols.lookup(pc).unwrap_or(NO_SYMBOL))
            .or_default() += count;
    }
    let sum: u64 = per_function.values().sum();
    if sum != total {
        return Err(format!(
            "window {window}: the per-address profile sums to {sum} instructions, \
             the plugin counted {total}"
        ));
    }
    let mut out: Vec<(String, u64)> = per_function
        .into_iter()
        .map(|(name, count)| (name.to_string(), count))
        .collect();
    out.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    Ok(out)
}

/// The printed profile: top functions per frame and share of the window, the rest in
/// one line, and the total as the bench table prints it.
fn table(
    w: &Window,
    index: usize,
    overhead: u64,
    functions: &[(String, u64)],
    top: usize,
) -> String {
    let frames = f64::from(w.frames.max(1));
    let pct = |n: u64| 100.0 * n as f64 / w.count.max(1) as f64;
    let mut s = format!(
        "\nprofile of `{}` (window {index}, {} frames; QEMU mps2-an500 Cortex-M7):\n  {:>9} {:>8}  function\n",
        w.name, w.frames, "per frame", "% window"
    );
    for (name, n) in functions.iter().take(top) {
        s += &format!("  {:>9.1} {:>7.1}%  {name}\n", *n as f64 / frames, pct(*n));
    }
    if functions.len() > top {
        let rest: u64 = functions[top..].iter().map(|f| f.1).sum();
        s += &format!(
            "  {:>9.1} {:>7.1}%  ({} more functions)\n",
            rest as f64 / frames,
            pct(rest),
            functions.len() - top
        );
    }
    let net = w.count.saturating_sub(overhead);
    s += &format!(
        "  all functions: {} instructions, {:.1} per frame; less the window cost {overhead}: \
         {:.1} per frame (the bench figure)\n",
        w.count,
        w.count as f64 / frames,
        net as f64 / frames
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn symbols() -> Symbols {
        Symbols::new(vec![
            // Thumb bit already cleared, as from_elf does.
            (0x100, 0x20, "_RNvCs1234_6shared6decode".into()),
            (0x120, 0x10, "memcpy".into()),
            (0x200, 0, "Reset".into()), // no size: up to the next symbol
            (0x240, 0x8, "b_alias".into()),
            (0x240, 0x8, "a_alias".into()),
        ])
    }

    #[test]
    fn lookup_finds_the_containing_function_and_respects_ends() {
        let s = symbols();
        assert_eq!(s.lookup(0x100), Some("shared::decode"));
        assert_eq!(s.lookup(0x11e), Some("shared::decode"));
        assert_eq!(s.lookup(0x120), Some("memcpy"));
        assert_eq!(s.lookup(0x12f), Some("memcpy"));
        assert_eq!(s.lookup(0x130), None, "gap after memcpy");
        assert_eq!(s.lookup(0xfe), None, "before the first symbol");
        assert_eq!(s.lookup(0x23e), Some("Reset"));
        assert_eq!(s.lookup(0x244), Some("a_alias (+1 aliases)"));
        assert_eq!(s.lookup(0x248), None, "past the last symbol");
    }

    #[test]
    fn attribution_sums_per_function_and_checks_the_total() {
        let pcs = [(0x100, 10), (0x104, 30), (0x120, 25), (0x300, 2)];
        let f = attribute(&symbols(), &pcs, 67, 3).unwrap();
        assert_eq!(
            f,
            vec![
                ("shared::decode".to_string(), 40),
                ("memcpy".to_string(), 25),
                (NO_SYMBOL.to_string(), 2),
            ]
        );
        let e = attribute(&symbols(), &pcs, 68, 3).unwrap_err();
        assert!(
            e.contains("window 3") && e.contains("67") && e.contains("68"),
            "{e}"
        );
    }

    #[test]
    fn pc_lines_parse_and_garbage_fails() {
        let err = "insn_count: window 0 5\ninsn_pc: window 0 0x4d80 3\n\
                   insn_pc: window 0 0x4d82 2\nsome qemu noise\ninsn_pc: window 1 0x10 7\n";
        let p = pc_counts(err).unwrap();
        assert_eq!(window_pcs(&p, 0), &[(0x4d80, 3), (0x4d82, 2)]);
        assert_eq!(window_pcs(&p, 1), &[(0x10, 7)]);
        assert!(window_pcs(&p, 2).is_empty());
        for bad in [
            "insn_pc: window 0 4d80 3",
            "insn_pc: window 0 0x4d80",
            "insn_pc: window x 0x4d80 3",
            "insn_pc: window 0 0x4d80 -3",
            "insn_pc: window 0 0xzz 3 9",
        ] {
            assert!(pc_counts(bad).is_err(), "{bad}");
        }
    }

    fn windows() -> Vec<Window<'static>> {
        [
            "(call overhead)",
            "hans rx: vote3",
            "hans rx: super",
            "super",
        ]
        .into_iter()
        .map(|name| Window {
            name,
            frames: 32,
            count: 1,
        })
        .collect()
    }

    #[test]
    fn selection_needs_one_match_or_an_exact_name() {
        let w = windows();
        assert_eq!(select(&w, "vote3"), Ok(1));
        assert_eq!(select(&w, "super"), Ok(3), "exact name wins");
        assert!(select(&w, "hans").unwrap_err().contains("several"));
        assert!(select(&w, "xy9").unwrap_err().contains("no workload"));
    }

    #[test]
    fn arguments() {
        let a = |v: &[&str]| parse_args(&v.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        assert_eq!(a(&["worst"]), Ok(("worst".into(), DEFAULT_TOP)));
        assert_eq!(a(&["--top", "5", "worst"]), Ok(("worst".into(), 5)));
        assert!(a(&[]).is_err());
        assert!(a(&["worst", "--top"]).is_err());
        assert!(a(&["worst", "--top", "0"]).is_err());
        assert!(a(&["worst", "extra"]).is_err());
        assert!(a(&["worst", "--bottom", "3"]).is_err());
    }

    #[test]
    fn table_shows_top_rest_and_the_bench_figure() {
        let w = Window {
            name: "w",
            frames: 4,
            count: 116,
        };
        let f = vec![("a".to_string(), 80), ("b".into(), 20), ("c".into(), 16)];
        let t = table(&w, 2, 16, &f, 1);
        assert!(t.contains("20.0    69.0%  a"), "{t}");
        assert!(t.contains("9.0    31.0%  (2 more functions)"), "{t}");
        assert!(t.contains("less the window cost 16: 25.0 per frame"), "{t}");
    }
}
