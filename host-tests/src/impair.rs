//! Line impairments applied to waveforms, reproducible from a seed.
//!
//! Random impairments draw from a ChaCha8 generator seeded with the given `u64`
//! (`rand`'s named, portable generator), visiting signals in waveform order, so a seed
//! gives the same result on every machine and run.
//!
//! Every function keeps each signal's changes strictly ordered; changes that an
//! impairment makes coincide are merged (a zero-width pulse disappears).

use std::fmt;

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use crate::wave::{Ps, Signal, WaveError, Waveform};

/// Errors applying an impairment.
#[derive(Debug, Clone, PartialEq)]
pub enum ImpairError {
    /// The named signal is not in the waveform.
    MissingSignal {
        /// The missing name.
        name: String,
    },
    /// A parameter is out of range.
    BadParameter {
        /// Which parameter.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// Rebuilding a signal failed (internal ordering error).
    Wave(WaveError),
}

impl fmt::Display for ImpairError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::MissingSignal { name } => write!(f, "impairment: no signal named `{name}`"),
            Self::BadParameter { what, value } => {
                write!(f, "impairment: parameter {what} = {value} is out of range")
            }
            Self::Wave(e) => write!(f, "impairment: {e}"),
        }
    }
}

impl std::error::Error for ImpairError {}

impl From<WaveError> for ImpairError {
    fn from(e: WaveError) -> Self {
        Self::Wave(e)
    }
}

fn get_mut<'a>(wave: &'a mut Waveform, name: &str) -> Result<&'a mut Signal, ImpairError> {
    wave.get_mut(name)
        .ok_or_else(|| ImpairError::MissingSignal {
            name: name.to_owned(),
        })
}

/// Rebuilds `s` from changes that are in non-decreasing time order.
fn rebuild(
    s: &mut Signal,
    changes: impl IntoIterator<Item = (Ps, bool)>,
) -> Result<(), ImpairError> {
    *s = Signal::from_changes(s.name().to_owned(), s.initial(), changes)?;
    Ok(())
}

/// Bit-rate offset: the sender's clock runs `ppm` parts per million fast (negative =
/// slow), so every time `t` becomes `t / (1 + ppm * 1e-6)` (all signals). Use
/// `percent * 1e4` for a percentage.
pub fn rate_offset_ppm(wave: &mut Waveform, ppm: f64) -> Result<(), ImpairError> {
    let factor = 1.0 + ppm * 1e-6;
    if !(factor.is_finite() && factor > 0.0) {
        return Err(ImpairError::BadParameter {
            what: "ppm",
            value: ppm,
        });
    }
    for s in wave.signals_mut() {
        // Monotonic mapping, so order is kept (equal rounded times merge in push).
        let changes: Vec<(Ps, bool)> = s
            .changes()
            .iter()
            .map(|&(t, l)| ((t as f64 / factor).round() as Ps, l))
            .collect();
        rebuild(s, changes)?;
    }
    Ok(())
}

/// Edge jitter: every edge of the named signals (all if `names` is empty) moves by an
/// independent uniform offset in `±max_ps`. To keep edge order and pulses alive, each
/// edge stays strictly inside the half-way points to its neighbours (so a jitter larger
/// than half a pulse is clipped). For "±x of a bit time", pass `x * bit_ps`.
pub fn jitter(
    wave: &mut Waveform,
    names: &[&str],
    max_ps: u64,
    seed: u64,
) -> Result<(), ImpairError> {
    for n in names {
        get_mut(wave, n)?;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let max = i128::from(max_ps);
    for s in wave.signals_mut() {
        if !names.is_empty() && !names.contains(&s.name()) {
            continue;
        }
        let orig = s.changes().to_vec();
        let mut out = Vec::with_capacity(orig.len());
        for (i, &(t, l)) in orig.iter().enumerate() {
            let d: i128 = if max > 0 {
                rng.random_range(-max..=max)
            } else {
                0
            };
            let t = i128::from(t);
            // Bounds: just after the midpoint to the previous edge, just before the
            // midpoint to the next one (0 and +inf at the ends).
            let lo = i
                .checked_sub(1)
                .and_then(|p| orig.get(p))
                .map_or(0, |&(pt, _)| (i128::from(pt) + t) / 2 + 1);
            let hi = orig.get(i + 1).map_or(i128::from(u64::MAX), |&(nt, _)| {
                (t + i128::from(nt)) / 2 - 1
            });
            let nt = if lo > hi { t } else { (t + d).clamp(lo, hi) };
            out.push((Ps::try_from(nt).unwrap_or(Ps::MAX), l));
        }
        rebuild(s, out)?;
    }
    Ok(())
}

/// Asymmetric edge delays (duty-cycle distortion, as RS-422 drivers, receivers and
/// cables make them): every rising edge of the named signals (all if `names` is
/// empty) arrives `rise_ps` later than it would, relative to the falling edges
/// (negative: earlier, i.e. the falling edges late by `-rise_ps`). With `rise_ps > 0`
/// the line is high where it was high both now and `rise_ps` ago, so high pulses
/// lose `rise_ps` and low ones gain it (a high pulse shorter than that vanishes);
/// with `rise_ps < 0` it is high where it was high now or `-rise_ps` ago. The
/// falling edges (rising, for negative `rise_ps`) stay where they were. Deterministic:
/// no seed.
pub fn asymmetry(wave: &mut Waveform, names: &[&str], rise_ps: i64) -> Result<(), ImpairError> {
    for n in names {
        get_mut(wave, n)?;
    }
    let d = rise_ps.unsigned_abs();
    if d == 0 {
        return Ok(());
    }
    for s in wave.signals_mut() {
        if !names.is_empty() && !names.contains(&s.name()) {
            continue;
        }
        let original = s.clone();
        let then = |t: Ps| {
            t.checked_sub(d)
                .map_or(original.initial(), |e| original.level_at(e))
        };
        // The level can change only where the signal or its copy `d` later does.
        let mut times: Vec<Ps> = original
            .changes()
            .iter()
            .flat_map(|&(t, _)| [t, t.saturating_add(d)])
            .collect();
        times.sort_unstable();
        times.dedup();
        let changes: Vec<(Ps, bool)> = times
            .into_iter()
            .map(|t| {
                let (now, before) = (original.level_at(t), then(t));
                (
                    t,
                    if rise_ps > 0 {
                        now && before
                    } else {
                        now || before
                    },
                )
            })
            .collect();
        rebuild(s, changes)?;
    }
    Ok(())
}

/// Inter-channel skew: shifts each named signal by its delay in ps (negative = earlier;
/// times clamp at 0).
pub fn skew(wave: &mut Waveform, delays: &[(&str, i64)]) -> Result<(), ImpairError> {
    for &(name, delay) in delays {
        let s = get_mut(wave, name)?;
        let changes: Vec<(Ps, bool)> = s
            .changes()
            .iter()
            .map(|&(t, l)| (t.saturating_add_signed(delay), l))
            .collect();
        rebuild(s, changes)?;
    }
    Ok(())
}

/// Inverts the signal during each `(start, end)` interval (sorted, non-overlapping).
fn xor_pulses(s: &mut Signal, pulses: &[(Ps, Ps)]) -> Result<(), ImpairError> {
    // Toggle points: the level is inverted between each pulse's start and end.
    let mut toggles: Vec<Ps> = pulses.iter().flat_map(|&(a, b)| [a, b]).collect();
    toggles.sort_unstable();
    let mut times: Vec<Ps> = s.changes().iter().map(|&(t, _)| t).collect();
    times.extend(&toggles);
    times.sort_unstable();
    times.dedup();
    let original = s.clone();
    let changes: Vec<(Ps, bool)> = times
        .into_iter()
        .map(|t| {
            let inverted = toggles.partition_point(|&x| x <= t) % 2 == 1;
            (t, original.level_at(t) ^ inverted)
        })
        .collect();
    rebuild(s, changes)
}

/// Noise burst: `count` random glitches (level inversions) of 1..=`max_width_ps` each,
/// placed at random in `[from, to)` on the named signal.
pub fn noise_burst(
    wave: &mut Waveform,
    name: &str,
    window: (Ps, Ps),
    count: usize,
    max_width_ps: u64,
    seed: u64,
) -> Result<(), ImpairError> {
    let (from, to) = window;
    if to <= from {
        return Err(ImpairError::BadParameter {
            what: "noise window end",
            value: to as f64,
        });
    }
    if max_width_ps == 0 {
        return Err(ImpairError::BadParameter {
            what: "max_width_ps",
            value: 0.0,
        });
    }
    let s = get_mut(wave, name)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pulses: Vec<(Ps, Ps)> = (0..count)
        .map(|_| {
            let start = rng.random_range(from..to);
            let width = rng.random_range(1..=max_width_ps);
            (start, start.saturating_add(width))
        })
        .collect();
    // Merge overlaps so every pulse is one inversion.
    pulses.sort_unstable();
    let mut merged: Vec<(Ps, Ps)> = Vec::with_capacity(pulses.len());
    for (a, b) in pulses {
        match merged.last_mut() {
            Some(last) if a <= last.1 => last.1 = last.1.max(b),
            _ => merged.push((a, b)),
        }
    }
    xor_pulses(s, &merged)
}

/// Stuck or broken channel: from `from_ps` on the signal stays at `level` (an open
/// differential input reads the receiver's fail-safe level, i.e. stuck too).
pub fn stuck_at(
    wave: &mut Waveform,
    name: &str,
    from_ps: Ps,
    level: bool,
) -> Result<(), ImpairError> {
    let s = get_mut(wave, name)?;
    let mut changes: Vec<(Ps, bool)> = s
        .changes()
        .iter()
        .copied()
        .filter(|&(t, _)| t < from_ps)
        .collect();
    changes.push((from_ps, level));
    rebuild(s, changes)
}

/// Clock stop/restart: the signal holds `level` during `[from_ps, to_ps)` and then
/// resumes its original waveform (the edges inside the gap are lost).
pub fn gap(
    wave: &mut Waveform,
    name: &str,
    from_ps: Ps,
    to_ps: Ps,
    level: bool,
) -> Result<(), ImpairError> {
    if to_ps <= from_ps {
        return Err(ImpairError::BadParameter {
            what: "gap end",
            value: to_ps as f64,
        });
    }
    let s = get_mut(wave, name)?;
    let resume = s.level_at(to_ps);
    let mut changes: Vec<(Ps, bool)> = s
        .changes()
        .iter()
        .copied()
        .filter(|&(t, _)| t < from_ps)
        .collect();
    changes.push((from_ps, level));
    changes.push((to_ps, resume));
    changes.extend(s.changes().iter().copied().filter(|&(t, _)| t > to_ps));
    rebuild(s, changes)
}

/// One XY3-100 SPI slave's clock glitch: from the clock pulse that starts at or
/// after `at_ps`, the SCK of data line `line` ([`crate::line::roles::spi_sck`],
/// made from `clk` if the waveform has none yet) sees `edges` extra falling edges
/// (spike pairs in the low time after that pulse, up to the next rising edge: the
/// bit there counts `1 + edges` times) or, negative, misses the next `-edges`
/// pulses (those bits are never sampled). On a frame's last pulse that low time
/// is the gap to the next frame, where NSS is high: the slave samples only the
/// spikes after NSS falls again (a test's rule must count the sampled edges,
/// not `edges`). The shared `clk` and the other slaves are unchanged,
/// so that line's SPI falls out of step with the others
/// (`shared::xy3::step`).
pub fn sck_glitch(
    wave: &mut Waveform,
    clk: &str,
    line: &str,
    at_ps: Ps,
    edges: i32,
) -> Result<(), ImpairError> {
    if edges == 0 || edges.unsigned_abs() > 64 {
        return Err(ImpairError::BadParameter {
            what: "sck_glitch edges",
            value: f64::from(edges),
        });
    }
    let own = crate::line::roles::spi_sck(line);
    if wave.get(&own).is_none() {
        let mut s = get_mut(wave, clk)?.clone();
        s.set_name(own.clone());
        wave.insert(s);
    }
    let s = get_mut(wave, &own)?;
    let changes = s.changes().to_vec();
    // The first rising edge at or after `at_ps`, and the pulse it starts.
    let Some(k) = changes.iter().position(|&(t, l)| l && t >= at_ps) else {
        return Err(ImpairError::BadParameter {
            what: "sck_glitch at_ps (no clock pulse after it)",
            value: at_ps as f64,
        });
    };
    let mut out: Vec<(Ps, bool)> = changes.get(..k).unwrap_or_default().to_vec();
    if edges < 0 {
        // Drop the next `-edges` pulses (a rising edge and its falling edge each).
        let mut dropped = 0;
        let mut rest = changes.get(k..).unwrap_or_default().iter().peekable();
        while let Some(&(t, l)) = rest.next() {
            if dropped < edges.unsigned_abs() && l {
                if rest.peek().is_some_and(|&&(_, l2)| !l2) {
                    rest.next();
                }
                dropped += 1;
                continue;
            }
            out.push((t, l));
        }
        return rebuild(s, out);
    }
    // The pulse's falling edge and the next rising edge bound its low half.
    let (fall, next) = match (changes.get(k + 1), changes.get(k + 2)) {
        (Some(&(f, false)), Some(&(n, true))) => (f, n),
        _ => {
            return Err(ImpairError::BadParameter {
                what: "sck_glitch at_ps (no full clock period after it)",
                value: at_ps as f64,
            })
        }
    };
    let e = u64::from(edges.unsigned_abs());
    let step = (next - fall) / (2 * e + 1);
    if step == 0 {
        return Err(ImpairError::BadParameter {
            what: "sck_glitch edges (too many for the low half)",
            value: f64::from(edges),
        });
    }
    out.extend(changes.get(k..=k + 1).unwrap_or_default().iter().copied());
    for j in 0..e {
        out.push((fall + (2 * j + 1) * step, true));
        out.push((fall + (2 * j + 2) * step, false));
    }
    out.extend(changes.get(k + 2..).unwrap_or_default().iter().copied());
    rebuild(s, out)
}
