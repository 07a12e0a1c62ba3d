//! VCD (IEEE 1364 value change dump) input and output for the [`Waveform`] model, built
//! on the `vcd` crate's parser and writer.
//!
//! Reading:
//! - any `$timescale` from 1 s down to 1 fs; times are converted to picoseconds, rounded
//!   to the nearest ps (so two fs-apart changes may merge; the later one wins);
//! - only 1-bit variables are signals; vectors, reals, strings and events are skipped;
//! - signals are matched by their *leaf* name (scopes are ignored), or by the full dotted
//!   path (`top.probe.CLK`) when a name contains a `.`, which resolves duplicates;
//! - values set before the first timestamp, inside `$dumpvars`, or at the first
//!   timestamp become the initial level;
//! - **`x` and `z` keep the previous level** (low if the signal has none yet): a logic
//!   analyser never produces them, a simulator does so before reset, and holding avoids
//!   inventing edges that a real receiver would not see;
//! - a missing `$timescale` is an error rather than a guess.
//!
//! Writing: `$timescale 1 ps` (lossless) or `1 ns`, one `$scope module bridge`, one
//! `wire 1` per signal, initial values in `$dumpvars` at `#0`.

use std::collections::HashMap;
use std::fmt;
use std::io::{self, BufRead, BufReader, Read, Write};

use vcd::{Command, IdCode, ScopeItem, TimescaleUnit, Value, VarType};

use crate::wave::{Ps, Signal, WaveError, Waveform};

/// Errors reading or writing VCD.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VcdError {
    /// Reading or writing the underlying file failed.
    Io {
        /// The I/O error's description.
        message: String,
    },
    /// The text is not valid VCD.
    Syntax {
        /// 1-based line number where the parser stopped.
        line: u64,
        /// What the parser did not accept.
        message: String,
    },
    /// The file ends in the middle of the header, a command or a value change.
    Truncated {
        /// What was being read when the file ended.
        context: String,
    },
    /// The header has no `$timescale`.
    MissingTimescale,
    /// A time does not fit in `u64` picoseconds.
    TimeOverflow {
        /// The time in file units.
        time: u64,
    },
    /// A timestamp is earlier than the previous one.
    TimeBackwards {
        /// 1-based line number.
        line: u64,
        /// The offending timestamp (file units).
        time: u64,
        /// The previous timestamp (file units).
        previous: u64,
    },
    /// A value change refers to an identifier code no `$var` declared.
    UnknownIdCode {
        /// 1-based line number.
        line: u64,
        /// The identifier code as written.
        code: String,
    },
    /// A wanted signal is not in the file.
    MissingSignal {
        /// The role the signal was wanted for.
        role: String,
        /// The name looked up in the file.
        name: String,
        /// The 1-bit signals the file does have (leaf names).
        available: Vec<String>,
    },
    /// A name matches several 1-bit variables in different scopes.
    DuplicateName {
        /// The ambiguous name.
        name: String,
        /// Full dotted paths of the matching variables.
        paths: Vec<String>,
    },
    /// A wanted name is a vector/real variable, not a single bit.
    NotSingleBit {
        /// The name.
        name: String,
        /// Declared width.
        width: u32,
    },
    /// A `--map` argument is not `ROLE=NAME`.
    BadMapping {
        /// The argument as given.
        arg: String,
    },
    /// A signal name cannot be written to VCD (empty or containing whitespace).
    InvalidName {
        /// The name.
        name: String,
    },
    /// Building the waveform failed.
    Wave(WaveError),
}

impl fmt::Display for VcdError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io { message } => write!(f, "VCD I/O error: {message}"),
            Self::Syntax { line, message } => {
                write!(f, "VCD syntax error at line {line}: {message}")
            }
            Self::Truncated { context } => write!(f, "VCD file is truncated ({context})"),
            Self::MissingTimescale => write!(f, "VCD header has no $timescale"),
            Self::TimeOverflow { time } => {
                write!(f, "VCD time {time} does not fit in 64-bit picoseconds")
            }
            Self::TimeBackwards {
                line,
                time,
                previous,
            } => write!(
                f,
                "VCD timestamp #{time} at line {line} is earlier than the previous #{previous}"
            ),
            Self::UnknownIdCode { line, code } => {
                write!(
                    f,
                    "VCD line {line}: value change for undeclared identifier `{code}`"
                )
            }
            Self::MissingSignal {
                role,
                name,
                available,
            } => write!(
                f,
                "signal `{name}` (for {role}) not found; 1-bit signals in the file: {}",
                if available.is_empty() {
                    "none".to_owned()
                } else {
                    available.join(", ")
                }
            ),
            Self::DuplicateName { name, paths } => write!(
                f,
                "signal name `{name}` is ambiguous ({}); give the full dotted path",
                paths.join(", ")
            ),
            Self::NotSingleBit { name, width } => {
                write!(
                    f,
                    "signal `{name}` is {width} bits wide; only 1-bit signals are supported"
                )
            }
            Self::BadMapping { arg } => {
                write!(f, "bad signal mapping `{arg}`: expected ROLE=NAME")
            }
            Self::InvalidName { name } => {
                write!(
                    f,
                    "signal name `{name}` cannot be written to VCD (empty or contains whitespace)"
                )
            }
            Self::Wave(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for VcdError {}

impl From<WaveError> for VcdError {
    fn from(e: WaveError) -> Self {
        Self::Wave(e)
    }
}

fn from_io(e: io::Error, context: &str) -> VcdError {
    if e.kind() == io::ErrorKind::UnexpectedEof {
        return VcdError::Truncated {
            context: context.to_owned(),
        };
    }
    if let Some(pe) = e
        .get_ref()
        .and_then(|r| r.downcast_ref::<vcd::ParseError>())
    {
        return VcdError::Syntax {
            line: pe.line(),
            message: pe.kind().to_string(),
        };
    }
    VcdError::Io {
        message: e.to_string(),
    }
}

/// Maps protocol roles (e.g. `CLK`) to signal names in a capture (e.g. `D0`), as given by
/// `--map ROLE=NAME`. Unmapped roles are looked up under their own name.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NameMap {
    pairs: Vec<(String, String)>,
}

impl NameMap {
    /// An empty map (every role is looked up under its own name).
    pub fn new() -> Self {
        Self::default()
    }

    /// Maps `role` to `name`, replacing an earlier mapping of `role`.
    pub fn set(&mut self, role: impl Into<String>, name: impl Into<String>) {
        let role = role.into();
        let name = name.into();
        match self.pairs.iter_mut().find(|(r, _)| *r == role) {
            Some(slot) => slot.1 = name,
            None => self.pairs.push((role, name)),
        }
    }

    /// Parses one `ROLE=NAME` argument and adds it.
    pub fn parse_arg(&mut self, arg: &str) -> Result<(), VcdError> {
        match arg.split_once('=') {
            Some((role, name)) if !role.trim().is_empty() && !name.trim().is_empty() => {
                self.set(role.trim(), name.trim());
                Ok(())
            }
            _ => Err(VcdError::BadMapping {
                arg: arg.to_owned(),
            }),
        }
    }

    /// The file name to look up for `role`.
    pub fn resolve<'a>(&'a self, role: &'a str) -> &'a str {
        self.pairs
            .iter()
            .find(|(r, _)| r == role)
            .map_or(role, |(_, n)| n.as_str())
    }
}

/// A variable declared in the header.
struct Decl {
    path: String,
    leaf: String,
    width: u32,
    code: IdCode,
    single_bit: bool,
}

fn collect_decls(items: &[ScopeItem], prefix: &str, out: &mut Vec<Decl>) {
    for item in items {
        match item {
            ScopeItem::Scope(s) => {
                let p = format!("{prefix}{}.", s.identifier);
                collect_decls(&s.items, &p, out);
            }
            ScopeItem::Var(v) => {
                let single_bit = v.size == 1
                    && !matches!(v.var_type, VarType::Real | VarType::Event | VarType::String);
                out.push(Decl {
                    path: format!("{prefix}{}", v.reference),
                    leaf: v.reference.clone(),
                    width: v.size,
                    code: v.code,
                    single_bit,
                });
            }
            _ => {}
        }
    }
}

/// Picoseconds per file time unit as a rational `num / den`.
fn ps_ratio(mult: u32, unit: TimescaleUnit) -> (u128, u128) {
    // divisor() = units per second; 1 unit = 1e12 / divisor ps.
    (
        u128::from(mult) * 1_000_000_000_000,
        u128::from(unit.divisor()),
    )
}

fn to_ps(t: u64, ratio: (u128, u128)) -> Result<Ps, VcdError> {
    let (num, den) = ratio;
    let v = u128::from(t)
        .checked_mul(num)
        .and_then(|x| x.checked_add(den / 2))
        .map(|x| x / den.max(1))
        .ok_or(VcdError::TimeOverflow { time: t })?;
    Ps::try_from(v).map_err(|_| VcdError::TimeOverflow { time: t })
}

/// Which variables to read and under which names.
enum Selection<'a> {
    /// Every 1-bit variable, under its leaf name.
    All,
    /// `(role, file name)` pairs; signals are named by role.
    Roles(Vec<(&'a str, &'a str)>),
}

/// Reads every 1-bit signal of a VCD file, named by leaf name. Two 1-bit variables with
/// the same leaf name give [`VcdError::DuplicateName`]; use [`read_vcd_roles`] then.
pub fn read_vcd<R: Read>(reader: R) -> Result<Waveform, VcdError> {
    read_impl(reader, Selection::All)
}

/// Reads the signals for `roles` (e.g. `["CLK", "SYNC", "X"]`), looking each up in the
/// file under `map.resolve(role)`; the returned signals are named by role. Other
/// variables, including ambiguous or non-1-bit ones, are ignored unless wanted.
pub fn read_vcd_roles<R: Read>(
    reader: R,
    roles: &[&str],
    map: &NameMap,
) -> Result<Waveform, VcdError> {
    let pairs = roles.iter().map(|&r| (r, map.resolve(r))).collect();
    read_impl(reader, Selection::Roles(pairs))
}

/// Picks the declarations to read: returns `(signal name, code)` pairs.
fn select(decls: &[Decl], sel: &Selection<'_>) -> Result<Vec<(String, IdCode)>, VcdError> {
    let matches = |name: &str| -> Vec<&Decl> {
        decls
            .iter()
            .filter(|d| {
                if name.contains('.') {
                    d.path == name
                } else {
                    d.leaf == name
                }
            })
            .collect()
    };
    let mut out = Vec::new();
    match sel {
        Selection::All => {
            for d in decls.iter().filter(|d| d.single_bit) {
                let same: Vec<&Decl> = decls
                    .iter()
                    .filter(|o| o.single_bit && o.leaf == d.leaf)
                    .collect();
                // The same code declared twice (an alias) is one signal, not a conflict.
                if same.iter().any(|o| o.code != d.code) {
                    return Err(VcdError::DuplicateName {
                        name: d.leaf.clone(),
                        paths: same.iter().map(|o| o.path.clone()).collect(),
                    });
                }
                if !out.iter().any(|(n, _)| *n == d.leaf) {
                    out.push((d.leaf.clone(), d.code));
                }
            }
        }
        Selection::Roles(pairs) => {
            for &(role, name) in pairs {
                let found = matches(name);
                let bits: Vec<&&Decl> = found.iter().filter(|d| d.single_bit).collect();
                match bits.as_slice() {
                    [] => {
                        if let Some(d) = found.first() {
                            return Err(VcdError::NotSingleBit {
                                name: name.to_owned(),
                                width: d.width,
                            });
                        }
                        let mut available: Vec<String> = decls
                            .iter()
                            .filter(|d| d.single_bit)
                            .map(|d| d.leaf.clone())
                            .collect();
                        available.dedup();
                        return Err(VcdError::MissingSignal {
                            role: role.to_owned(),
                            name: name.to_owned(),
                            available,
                        });
                    }
                    [first, rest @ ..] => {
                        if rest.iter().any(|d| d.code != first.code) {
                            return Err(VcdError::DuplicateName {
                                name: name.to_owned(),
                                paths: bits.iter().map(|d| d.path.clone()).collect(),
                            });
                        }
                        if out.iter().any(|(n, _)| n == role) {
                            return Err(VcdError::Wave(WaveError::DuplicateSignal {
                                name: role.to_owned(),
                            }));
                        }
                        out.push((role.to_owned(), first.code));
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Per-signal state while streaming value changes.
struct Track {
    signal: Signal,
    /// No value seen yet: the next defined value is the initial level.
    fresh: bool,
}

fn read_impl<R: Read>(reader: R, sel: Selection<'_>) -> Result<Waveform, VcdError> {
    // A final newline lets the parser finish a last token that ends at EOF; a genuinely
    // cut-off value change is still reported as truncation.
    let input = BufReader::new(reader.chain(&b"\n"[..]));
    let mut parser = vcd::Parser::new(input);
    let header = parser
        .parse_header()
        .map_err(|e| from_io(e, "end of file before $enddefinitions"))?;
    let (mult, unit) = header.timescale.ok_or(VcdError::MissingTimescale)?;
    let ratio = ps_ratio(mult, unit);
    let mut decls = Vec::new();
    collect_decls(&header.items, "", &mut decls);
    let chosen = select(&decls, &sel)?;

    let mut tracks: Vec<Track> = chosen
        .iter()
        .map(|(name, _)| Track {
            signal: Signal::new(name.clone(), false),
            fresh: true,
        })
        .collect();
    // Code -> indices of tracks fed by it.
    let mut by_code: HashMap<IdCode, Vec<usize>> = HashMap::new();
    for (i, (_, code)) in chosen.iter().enumerate() {
        by_code.entry(*code).or_default().push(i);
    }
    let declared: std::collections::HashSet<IdCode> = decls.iter().map(|d| d.code).collect();

    run_changes(&mut parser, &mut tracks, &by_code, &declared, ratio)?;

    let mut wave = Waveform::new();
    for t in tracks {
        wave.add(t.signal)?;
    }
    Ok(wave)
}

fn run_changes<B: BufRead>(
    parser: &mut vcd::Parser<B>,
    tracks: &mut [Track],
    by_code: &HashMap<IdCode, Vec<usize>>,
    declared: &std::collections::HashSet<IdCode>,
    ratio: (u128, u128),
) -> Result<(), VcdError> {
    // `None` until the first timestamp.
    let mut first_time: Option<u64> = None;
    let mut now: u64 = 0;
    let mut in_sim_cmd = false;
    loop {
        let line = parser.line();
        let cmd = match parser.next() {
            None => break,
            Some(Ok(c)) => c,
            Some(Err(e)) => return Err(from_io(e, "file ends inside a value change")),
        };
        let (code, value) = match cmd {
            Command::Timestamp(t) => {
                if first_time.is_some() && t < now {
                    return Err(VcdError::TimeBackwards {
                        line: parser.line(),
                        time: t,
                        previous: now,
                    });
                }
                first_time.get_or_insert(t);
                now = t;
                continue;
            }
            Command::Begin(_) => {
                in_sim_cmd = true;
                continue;
            }
            Command::End(_) => {
                in_sim_cmd = false;
                continue;
            }
            Command::ChangeScalar(code, v) => (code, Some(v)),
            // A 1-bit variable may be written as a 1-element vector (`b1 n0`).
            Command::ChangeVector(code, v) => (code, if v.len() == 1 { v.get(0) } else { None }),
            Command::ChangeReal(code, _) | Command::ChangeString(code, _) => (code, None),
            _ => continue,
        };
        if !declared.contains(&code) {
            return Err(VcdError::UnknownIdCode {
                line,
                code: code.to_string(),
            });
        }
        let Some(indices) = by_code.get(&code) else {
            continue;
        };
        let level = match value {
            Some(Value::V0) => Some(false),
            Some(Value::V1) => Some(true),
            // x / z (or a non-scalar write to a 1-bit var): hold the previous level.
            _ => None,
        };
        let Some(level) = level else { continue };
        let at_start = first_time.is_none_or(|f| f == now);
        let t_ps = to_ps(now, ratio)?;
        for &i in indices {
            if let Some(track) = tracks.get_mut(i) {
                // At the start nothing has been pushed yet, so this only sets the
                // initial level; a first value inside a later $dumpvars does the same.
                if at_start || (track.fresh && in_sim_cmd) {
                    track.signal = Signal::new(track.signal.name().to_owned(), level);
                } else {
                    track.signal.push(t_ps, level)?;
                }
                track.fresh = false;
            }
        }
    }
    if in_sim_cmd {
        return Err(VcdError::Truncated {
            context: "file ends inside $dumpvars/$dumpall/… without $end".to_owned(),
        });
    }
    Ok(())
}

/// Time unit of a written VCD file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteTimescale {
    /// `1 ps`: exact.
    Ps,
    /// `1 ns`: times rounded to the nearest ns (sub-ns edges may merge).
    Ns,
}

/// Writes `wave` as VCD: one `$scope module bridge`, one 1-bit wire per signal.
pub fn write_vcd<W: Write>(
    writer: W,
    wave: &Waveform,
    timescale: WriteTimescale,
) -> Result<(), VcdError> {
    let io = |e: io::Error| VcdError::Io {
        message: e.to_string(),
    };
    for s in wave.signals() {
        if s.name().is_empty() || s.name().chars().any(char::is_whitespace) {
            return Err(VcdError::InvalidName {
                name: s.name().to_owned(),
            });
        }
    }
    let (unit, div) = match timescale {
        WriteTimescale::Ps => (TimescaleUnit::PS, 1),
        WriteTimescale::Ns => (TimescaleUnit::NS, 1000),
    };
    let mut w = vcd::Writer::new(writer);
    w.version("xy-bridge host-tests").map_err(io)?;
    w.timescale(1, unit).map_err(io)?;
    w.add_module("bridge").map_err(io)?;
    let mut ids = Vec::new();
    for s in wave.signals() {
        ids.push(w.add_wire(1, s.name()).map_err(io)?);
    }
    w.upscope().map_err(io)?;
    w.enddefinitions().map_err(io)?;
    w.timestamp(0).map_err(io)?;
    w.begin(vcd::SimulationCommand::Dumpvars).map_err(io)?;
    for (s, id) in wave.signals().iter().zip(&ids) {
        w.change_scalar(*id, s.initial()).map_err(io)?;
    }
    w.end().map_err(io)?;

    // Merge all signals' changes in time order (stable: signal order within a time).
    let mut all: Vec<(Ps, usize, bool)> = Vec::new();
    for (i, s) in wave.signals().iter().enumerate() {
        all.extend(s.changes().iter().map(|&(t, l)| (t, i, l)));
    }
    all.sort_by_key(|&(t, i, _)| (t, i));
    let mut last_ts: Option<u64> = Some(0);
    for (t, i, level) in all {
        let ts = (t + div / 2) / div;
        if last_ts != Some(ts) {
            w.timestamp(ts).map_err(io)?;
            last_ts = Some(ts);
        }
        if let Some(id) = ids.get(i) {
            w.change_scalar(*id, level).map_err(io)?;
        }
    }
    w.flush().map_err(io)
}

/// Opens `path` and reads the signals for `roles` (see [`read_vcd_roles`]); I/O errors
/// name the file.
pub fn read_vcd_file(
    path: &std::path::Path,
    roles: &[&str],
    map: &NameMap,
) -> Result<Waveform, VcdError> {
    let file = std::fs::File::open(path).map_err(|e| VcdError::Io {
        message: format!("{}: {e}", path.display()),
    })?;
    read_vcd_roles(file, roles, map)
}

/// Creates `path` and writes `wave` to it (see [`write_vcd`]); I/O errors name the file.
pub fn write_vcd_file(
    path: &std::path::Path,
    wave: &Waveform,
    timescale: WriteTimescale,
) -> Result<(), VcdError> {
    let file = std::fs::File::create(path).map_err(|e| VcdError::Io {
        message: format!("{}: {e}", path.display()),
    })?;
    write_vcd(io::BufWriter::new(file), wave, timescale)
}
