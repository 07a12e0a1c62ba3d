//! Checks that the linker put the hot code into ITCM and the hot state into DTCM
//! as `memory.x` asks (issue 6), read back from the linked ELF, and the start-up
//! invariants the placement depends on.
//!
//! The input-section patterns are read from `memory.x` itself (the `.itcm`,
//! `.dtcm` and `.dtcm_bss` blocks), so the check and the script cannot drift apart:
//! every function whose input section (`.text.<symbol>` or `.text.unlikely.<symbol>`)
//! a `.itcm` pattern matches must lie in `.itcm`, or in `.flash_cold`, where
//! `memory.x` keeps the cold code of the hot modules (read before `.itcm`, so it
//! takes only what its own patterns match), never in `.text`; every static whose
//! `.bss.<symbol>` / `.data.<symbol>` a DTCM pattern matches must lie in DTCM. A
//! pattern that stops matching (a renamed module, a changed mangling) leaves
//! nothing in ITCM, which fails too.

use object::{Object, ObjectSection, ObjectSymbol, SymbolKind};
use std::path::Path;

/// ITCM and DTCM bounds (RM0433 section 2.3.2), as in `memory.x`.
const ITCM: std::ops::Range<u64> = 0x0000_0000..0x0001_0000;
const DTCM: std::ops::Range<u64> = 0x2000_0000..0x2002_0000;
/// AXI SRAM, where `.bss` and the stack live.
const AXI_SRAM: std::ops::Range<u64> = 0x2400_0000..0x2408_0000;
/// SRAM1..3 (DMA1/DMA2) and SRAM4 (BDMA): where DMA rings may be.
const DMA_RAM: [std::ops::Range<u64>; 2] = [0x3000_0000..0x3004_8000, 0x3800_0000..0x3801_0000];

/// What the TCMs hold.
pub struct Tcm {
    /// Bytes of `.itcm` (hot code), and how many functions the patterns matched.
    pub itcm: u64,
    pub itcm_functions: usize,
    /// Functions of the hot modules kept in flash as cold (`.flash_cold`; in the
    /// HIL binary also `.hil_cold`, what only its tests use), and
    /// their bytes.
    pub cold_functions: usize,
    pub cold_bytes: u64,
    /// Bytes of `.dtcm` + `.dtcm_bss` (hot state), and how many statics matched.
    pub dtcm: u64,
    pub dtcm_statics: usize,
}

/// Whether `line` opens the description of output section `name`.
fn opens(line: &str, name: &str) -> bool {
    let line = line.trim();
    line.starts_with(name) && line[name.len()..].starts_with([' ', '\t'])
}

/// The line number where output section `name` is described.
fn opening_line(script: &str, name: &str) -> Option<usize> {
    script.lines().position(|l| opens(l, name))
}

/// The input-section patterns of output section `name` in the linker script text.
fn patterns(script: &str, name: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut inside = false;
    for line in script.lines() {
        if opens(line, name) {
            inside = true;
            continue;
        }
        let line = line.trim();
        if !inside {
            continue;
        }
        if line.starts_with('}') {
            break;
        }
        // `*(.a .b)` -> [".a", ".b"]
        if let Some(list) = line.strip_prefix("*(").and_then(|l| l.strip_suffix(')')) {
            out.extend(list.split_whitespace().map(str::to_string));
        }
    }
    out
}

/// `*`-only glob match, as lld matches input-section names.
fn glob(pattern: &str, text: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    let (first, rest) = match parts.split_first() {
        Some(p) => p,
        None => return text.is_empty(),
    };
    let Some(mut tail) = text.strip_prefix(first) else {
        return false;
    };
    let Some((last, middle)) = rest.split_last() else {
        return tail.is_empty();
    };
    for part in middle {
        match tail.find(part) {
            Some(i) => tail = &tail[i + part.len()..],
            None => return false,
        }
    }
    tail.len() >= last.len() && tail.ends_with(last)
}

fn matches_any(patterns: &[String], sections: &[String]) -> bool {
    patterns.iter().any(|p| sections.iter().any(|s| glob(p, s)))
}

/// Reads `elf`, checks the placement against `memory.x` and returns the TCM use.
/// Every violation is listed in the error.
pub fn check(elf: &Path, memory_x: &Path) -> Result<Tcm, String> {
    let script = std::fs::read_to_string(memory_x)
        .map_err(|e| format!("cannot read {}: {e}", memory_x.display()))?;
    let code = patterns(&script, ".itcm");
    let state: Vec<String> = [patterns(&script, ".dtcm"), patterns(&script, ".dtcm_bss")]
        .concat()
        .into_iter()
        // `.dtcm .dtcm.*` are for explicit `#[link_section]`s, not symbol names.
        .filter(|p| !p.starts_with(".dtcm"))
        .collect();
    // `.flash_cold` must come first: lld gives an input section to the first
    // matching output section in script order, so only then does it keep the cold
    // functions of the hot modules out of `.itcm`.
    match (
        opening_line(&script, ".flash_cold"),
        opening_line(&script, ".itcm"),
    ) {
        (Some(cold), Some(hot)) if cold < hot => {}
        _ => {
            return Err(format!(
                "{}: `.flash_cold` must precede `.itcm` (cold code of the hot modules)",
                memory_x.display()
            ))
        }
    }
    // The task polls are the bulk of the hot code and never cold: no exception.
    let polls: Vec<String> = code
        .iter()
        .filter(|p| p.contains("4poll"))
        .cloned()
        .collect();
    if code.is_empty() || state.is_empty() {
        return Err(format!(
            "{}: no input-section patterns found in the .itcm / .dtcm_bss blocks",
            memory_x.display()
        ));
    }

    let data = std::fs::read(elf).map_err(|e| format!("cannot read {}: {e}", elf.display()))?;
    let file =
        object::File::parse(&*data).map_err(|e| format!("{}: not an ELF: {e}", elf.display()))?;
    let section = |name: &str| {
        file.section_by_name(name)
            .map(|s| s.address()..s.address() + s.size())
            .ok_or_else(|| format!("{}: no {name} section", elf.display()))
    };
    let itcm = section(".itcm")?;
    // The linker drops an empty output section: no cold code then.
    let cold = section(".flash_cold").unwrap_or(0..0);
    // The HIL binary's `.hil_cold` (build.rs `hil_cold_x`, flash): what only its
    // tests use, kept out of ITCM like cold code. Not in the firmware.
    let hil_cold = section(".hil_cold").unwrap_or(0..0);
    let dtcm = section(".dtcm")?;
    let dtcm_bss = section(".dtcm_bss")?;
    let symbol = |name: &str| {
        file.symbols()
            .find(|s| s.name() == Ok(name))
            .map(|s| s.address())
            .ok_or_else(|| format!("{}: no symbol `{name}`", elf.display()))
    };

    let mut errors = Vec::new();
    if itcm.start == 0 || itcm.end > ITCM.end {
        errors.push(format!(
            ".itcm {:#x}..{:#x} must lie in ITCM above address 0",
            itcm.start, itcm.end
        ));
    }
    for (name, r) in [(".dtcm", &dtcm), (".dtcm_bss", &dtcm_bss)] {
        if !r.is_empty() && (r.start < DTCM.start || r.end > DTCM.end) {
            errors.push(format!(
                "{name} {:#x}..{:#x} is not in DTCM",
                r.start, r.end
            ));
        }
    }
    // The loader must be firmware/tcm.rs, not cortex-m-rt's empty default: without it
    // ITCM holds garbage and the first call into it faults.
    if symbol("__pre_init")? == symbol("DefaultPreInit")? {
        errors.push("`__pre_init` is cortex-m-rt's default: firmware/tcm.rs is not linked".into());
    }
    // The reset handler zeroes __sbss..__ebss: both must be in AXI SRAM.
    let (sbss, ebss) = (symbol("__sbss")?, symbol("__ebss")?);
    if !(AXI_SRAM.contains(&sbss) && sbss <= ebss && ebss <= AXI_SRAM.end) {
        errors.push(format!(
            "reset zeroes .bss from {sbss:#x} to {ebss:#x}: not within AXI SRAM"
        ));
    }

    let mut itcm_functions = 0;
    let mut cold_functions = 0;
    let mut cold_bytes = 0;
    let mut dtcm_statics = 0;
    for s in file.symbols() {
        let Ok(name) = s.name() else { continue };
        // Linker-made long-branch thunks carry their target's name but are placed
        // next to their callers.
        if name.is_empty() || name.starts_with('$') || name.contains("LongThunk") {
            continue;
        }
        let addr = s.address() & !1;
        match s.kind() {
            SymbolKind::Text => {
                let sections = [format!(".text.{name}"), format!(".text.unlikely.{name}")];
                if matches_any(&code, &sections) {
                    if itcm.contains(&addr) {
                        itcm_functions += 1;
                    } else if (cold.contains(&addr) || hil_cold.contains(&addr))
                        && !matches_any(&polls, &sections)
                    {
                        cold_functions += 1;
                        cold_bytes += s.size();
                    } else {
                        errors.push(format!(
                            "hot function at {addr:#010x}, not in .itcm: {name}"
                        ));
                    }
                }
            }
            SymbolKind::Data => {
                // `dma_ring!` statics: DMA1/DMA2/BDMA cannot reach the TCMs.
                if name.ends_with("4RING") && !DMA_RAM.iter().any(|r| r.contains(&addr)) {
                    errors.push(format!(
                        "DMA ring at {addr:#010x}, outside SRAM1..4: {name}"
                    ));
                }
                let sections = [format!(".bss.{name}"), format!(".data.{name}")];
                if matches_any(&state, &sections) {
                    dtcm_statics += 1;
                    if !(dtcm.contains(&addr) || dtcm_bss.contains(&addr)) {
                        errors.push(format!("hot static at {addr:#010x}, not in DTCM: {name}"));
                    }
                }
            }
            _ => {}
        }
    }
    if itcm_functions == 0 {
        errors.push("no function matches the .itcm patterns of memory.x".into());
    }
    if errors.is_empty() {
        Ok(Tcm {
            itcm: itcm.end - itcm.start,
            itcm_functions,
            cold_functions,
            cold_bytes,
            dtcm: (dtcm.end - dtcm.start) + (dtcm_bss.end - dtcm_bss.start),
            dtcm_statics,
        })
    } else {
        Err(format!(
            "{}: TCM placement broken:\n  {}",
            elf.display(),
            errors.join("\n  ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::{glob, opening_line, patterns};

    #[test]
    fn glob_matches_like_the_linker() {
        assert!(glob(
            ".text.*6shared4hans2rx*",
            ".text._RNvX_6shared4hans2rx3new"
        ));
        assert!(glob(
            ".text.*6shared4hans2rx*",
            ".text.unlikely._RX6shared4hans2rxY"
        ));
        assert!(!glob(
            ".text.*6shared4hans2rx*",
            ".text._RNvX_6shared4hans2tx3new"
        ));
        assert!(!glob(
            ".text.*6shared4hans2rx*",
            ".rodata._R6shared4hans2rx"
        ));
        assert!(glob(
            ".bss.*11hans_decode4POOL",
            ".bss._RNv7hans_in11hans_decode4POOL"
        ));
        assert!(!glob(
            ".bss.*11hans_decode4POOL",
            ".bss._RNv11hans_decode4POOLs_"
        ));
        assert!(glob("a*", "a"));
        assert!(!glob("ab*b", "ab"));
    }

    /// The patterns of `memory.x` against real v0 names (HANS-100 -> HANS-100 build).
    #[test]
    fn hot_and_cold_patterns_split_as_intended() {
        let poll = ".text._RNvMs1_NtCsfXHtcMZqoOm_16embassy_executor3rawINtB5_11TaskStorageNCNvNv\
                    NtNtCsfB4nzik74cd_8firmware5tasks7hans_in18___hans_decode_task33___hans_\
                    decode_task_inner_function0E4pollB1a_";
        let spawn = ".text._RINvMNtNtCsfXHtcMZqoOm_16embassy_executor3raw4utilINtB3_10UninitCell\
                     NCNvNvNtNtCsfB4nzik74cd_8firmware5tasks7hans_in18___hans_decode_task33___\
                     hans_decode_task_inner_function0E14write_in_placeNCNvB1r_11hans_decode0EB1x_";
        let task = ".text._R*18___hans_decode_task*4poll*";
        assert!(glob(task, poll));
        assert!(!glob(task, spawn), "spawn-time code is not the task's poll");
        // `#[cold]` functions come as `.text.unlikely.`: not hot, `.flash_cold`'s.
        let hot = ".text._R*6shared4hans2rx*";
        let rephased = "_RNvMs_NtNtCs6jdyWnklaPu_6shared4hans2rxNtB4_6HansRx8rephased";
        assert!(glob(hot, &format!(".text.{rephased}")));
        assert!(!glob(hot, &format!(".text.unlikely.{rephased}")));
        assert!(glob(
            ".text.unlikely.*",
            &format!(".text.unlikely.{rephased}")
        ));
        // Constructors by name only: `HansRx::new` is cold, `Frame::new` is not matched.
        let new = ".text._R*6shared4hans2rx*6HansRx3new";
        assert!(glob(
            new,
            ".text._RNvMs_NtNtCs6jdyWnklaPu_6shared4hans2rxNtB4_6HansRx3new"
        ));
        assert!(!glob(
            new,
            ".text._RNvMNtNtCs6jdyWnklaPu_6shared4hans5frameNtB2_5Frame3new"
        ));
        assert!(!glob(
            new,
            ".text._RNvMs_NtNtCs6jdyWnklaPu_6shared4hans2rxNtB4_6HansRx3newer"
        ));
        // Debug impls, with `core::fmt` spelled out or as a back-reference.
        let debug = ".text._R*5Debug3fmt*";
        assert!(glob(
            debug,
            ".text._RNvXs1g_NtCs7ldSeZOOJos_4core3fmtRNtNtNtCs6jdyWnklaPu_6shared3xy22rx\
             12FramingFaultNtB6_5Debug3fmtCsjX6BYcUsawX_3hil"
        ));
        assert!(glob(
            debug,
            ".text._RNvXs_NtNtCs6jdyWnklaPu_6shared4hans5frameNtB4_5FrameNtNtCs7ldSeZOOJos_\
             4core3fmt5Debug3fmt"
        ));
        assert!(glob(
            ".text._R*6Format*format*",
            ".text._RNvXs_NtNtCs6jdyWnklaPu_6shared4hans2rxNtB4_4ModeNtNtCs720NRxyUi84_\
             5defmt6traits6Format12_format_data"
        ));
    }

    #[test]
    fn patterns_are_read_per_output_section() {
        let script = "SECTIONS {\n  .itcm ORIGIN(ITCM) + 32 : ALIGN(8)\n  {\n    __sitcm = .;\n    \
                      *(.text.*a*)\n    *(.text.*b* .text.*c*)\n  } > ITCM\n  .itcm_x : { *(.z) }\n}";
        assert_eq!(
            patterns(script, ".itcm"),
            [".text.*a*", ".text.*b*", ".text.*c*"]
        );
        assert_eq!(patterns(script, ".itcm_x"), Vec::<String>::new());
        let script = "SECTIONS {\n  .flash_cold : ALIGN(4)\n  {\n    *(.text.unlikely.*)\n  } \
                      > FLASH\n  .itcm ORIGIN(ITCM) + 32 : ALIGN(8)\n  {\n    *(.text.*a*)\n  }\n}";
        assert_eq!(patterns(script, ".flash_cold"), [".text.unlikely.*"]);
        assert_eq!(patterns(script, ".itcm"), [".text.*a*"]);
        assert_eq!(opening_line(script, ".flash_cold"), Some(1));
        assert_eq!(opening_line(script, ".itcm"), Some(5));
        assert_eq!(opening_line("/* `.itcm` holds */", ".itcm"), None);
    }
}
