//! `generate`: test patterns -> records (then [`super::encode`] makes the waveform),
//! and the impairment options shared by `generate` and `encode`.
//!
//! Patterns give X/Y in `[-1, 1]`, mapped to offset binary at the protocol's width
//! (-1 -> 0, 0 -> centre, 1 -> full scale); Z (and XY3-100 U, W) stay at the centre.
//! - `circle`: one turn of radius 0.9 over the run;
//! - `raster`: about sqrt(N) lines, X sweeping, Y stepping;
//! - `steps`: X and Y jump between -1, -0.5, 0, 0.5, 1 (so 0, centre and full scale
//!   all occur), ten holds per run;
//! - `random`: uniform over the full range (seeded).
//!
//! The backchannel (`xy3-back`) gets a cycle of head-status packets (error state,
//! temperatures, frame error counts, vendor, working hours) sent through the same
//! [`Sender`] as the firmware's, which puts the SYNC packets in.

use std::f64::consts::TAU;

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use shared::xy3::back::{Packet, Sender, SEND_BUF_LEN};
use shared::xy3::{Command, FrameSize};
use shared::{hans, xy2};

use super::jsonl::{BackRecord, Channel, ForwardRecord, HansRecord};
use super::{names, Protocol, SimError};
use crate::impair;
use crate::wave::{Ps, Waveform};

/// The test patterns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Pattern {
    /// A circle.
    Circle,
    /// A raster scan.
    Raster,
    /// Step responses between five levels.
    Steps,
    /// Random positions.
    Random,
}

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GenOptions {
    /// The pattern.
    pub pattern: Pattern,
    /// Number of frames (backchannel: packets, SYNCs not counted).
    pub frames: usize,
    /// Seed of the random pattern.
    pub seed: u64,
    /// XY2-100 frame width.
    pub xy2_mode: xy2::Mode,
    /// XY3-100 frame size.
    pub xy3_size: FrameSize,
    /// Every N-th frame carries a command on X (0: never).
    pub command_every: usize,
    /// Backchannel baud rate (for the SYNC interval).
    pub baud: f64,
}

/// Pattern points in `[-1, 1]^2`.
pub fn points(pattern: Pattern, n: usize, seed: u64) -> Vec<(f64, f64)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let lines = ((n as f64).sqrt().ceil() as usize).max(2);
    let per_line = n.div_ceil(lines).max(2);
    let hold = (n / 10).max(1);
    const LEVELS: [f64; 5] = [-1.0, -0.5, 0.0, 0.5, 1.0];
    (0..n)
        .map(|i| match pattern {
            Pattern::Circle => {
                let a = TAU * i as f64 / n.max(1) as f64;
                (0.9 * a.cos(), 0.9 * a.sin())
            }
            Pattern::Raster => {
                let (line, j) = (i / per_line, i % per_line);
                (
                    -0.9 + 1.8 * j as f64 / (per_line - 1) as f64,
                    -0.9 + 1.8 * line as f64 / (lines - 1) as f64,
                )
            }
            Pattern::Steps => {
                let k = i / hold;
                let x = LEVELS.get(k % 5).copied().unwrap_or(0.0);
                let y = LEVELS.get(4 - k % 5).copied().unwrap_or(0.0);
                (x, y)
            }
            Pattern::Random => (rng.random_range(-1.0..=1.0), rng.random_range(-1.0..=1.0)),
        })
        .collect()
}

/// `u` in `[-1, 1]` as offset binary of `bits` bits.
pub fn scale(u: f64, bits: u8) -> u32 {
    let max = ((1u64 << bits) - 1) as f64;
    ((u.clamp(-1.0, 1.0) + 1.0) / 2.0 * max).round() as u32
}

fn centre(bits: u8) -> u32 {
    1 << (bits - 1)
}

fn is_command(opts: &GenOptions, i: usize) -> bool {
    opts.command_every > 0 && i % opts.command_every == opts.command_every - 1
}

/// XY2-100 or XY3-100 frames (line numbers are 1-based frame indices).
pub fn forward_records(protocol: Protocol, opts: &GenOptions) -> Vec<(usize, ForwardRecord)> {
    let (lanes, bits): (&[&str], u8) = match (protocol, opts.xy2_mode, opts.xy3_size) {
        (Protocol::Xy2, xy2::Mode::Standard16, _) => (&names::XY2_DATA, 16),
        (Protocol::Xy2, xy2::Mode::Extended18, _) => (&names::XY2_DATA, 18),
        (_, _, FrameSize::Bits24) => (&names::XY3_DATA, 20),
        (_, _, FrameSize::Bits32) => (&names::XY3_DATA, 26),
    };
    // XY2-100: an arbitrary enhanced command (0x50) with the frame index as parameter;
    // XY3-100: temperature compensation on, all axes (harmless, §5.1.1). XY2-100E has
    // no command frame, so 18-bit runs get none.
    let command = |i: usize| match protocol {
        Protocol::Xy2 if bits == 16 => Some(Channel::Cmd {
            cmd: 0x5000 | (i & 0xFF) as u32,
            frame_bits: None,
        }),
        Protocol::Xy2 => None,
        _ => Some(Channel::Cmd {
            cmd: Command::TempCompOn(shared::xy3::AxisFlags::ALL_AXES).code(),
            frame_bits: (bits == 26).then_some(32),
        }),
    };
    points(opts.pattern, opts.frames, opts.seed)
        .into_iter()
        .enumerate()
        .map(|(i, (x, y))| {
            let mut rec = ForwardRecord::default();
            for lane in lanes {
                let pos = match *lane {
                    "x" => scale(x, bits),
                    "y" => scale(y, bits),
                    _ => centre(bits),
                };
                rec.set(lane, Channel::Pos { pos, bits });
            }
            if is_command(opts, i) {
                if let Some(c) = command(i) {
                    rec.set("x", c);
                }
            }
            (i + 1, rec)
        })
        .collect()
}

/// HANS-100 frames: DATA1 = X, DATA2 = Y (20 bits), DATA3 = Z at the centre (code 0).
pub fn hans_records(opts: &GenOptions) -> Result<Vec<(usize, HansRecord)>, SimError> {
    let z = hans::ControllerExt::Z(0x8000)
        .to_data3()
        .map_err(|e| SimError::BadOption {
            option: "--protocol hans",
            message: e.to_string(),
        })?;
    Ok(points(opts.pattern, opts.frames, opts.seed)
        .into_iter()
        .enumerate()
        .map(|(i, (x, y))| {
            (
                i + 1,
                HansRecord::Frame {
                    t_ns: None,
                    data: [scale(x, 20), scale(y, 20), z],
                },
            )
        })
        .collect())
}

/// The payload of the i-th generated status packet: (type, payload).
fn status_payload(i: usize, rng: &mut ChaCha8Rng, random: bool) -> (u8, Vec<u8>) {
    use shared::xy3::back::wire::ty;
    let v = if random {
        rng.random_range(0..1000u32)
    } else {
        i as u32
    };
    match i % 5 {
        0 => {
            let mut codes = vec![0u8; 7];
            if let Some(c) = codes.get_mut(v as usize % 7) {
                *c = (v % 8) as u8;
            }
            (ty::ERROR_STATE, codes)
        }
        1 => {
            let t: [i16; 3] = [2500 + (v % 100) as i16, 3100, -32767];
            (
                ty::TEMPERATURES,
                t.iter().flat_map(|x| x.to_le_bytes()).collect(),
            )
        }
        2 => (
            ty::FRAME_ERROR_COUNT,
            [v, 0, 1, 0, 0]
                .iter()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
        ),
        3 => (ty::VENDOR, b"bridge-sim head".to_vec()),
        _ => (
            ty::WORKING_HOURS,
            [v, u32::MAX].iter().flat_map(|x| x.to_le_bytes()).collect(),
        ),
    }
}

/// Backchannel packets as the head's sender emits them (SYNCs included).
pub fn back_records(opts: &GenOptions) -> Result<Vec<(usize, BackRecord)>, SimError> {
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let mut sender = Sender::default();
    let mut buf = [0u8; SEND_BUF_LEN];
    let mut out = Vec::new();
    // Elapsed line time in bits, to give the sender its clock.
    let mut bits: u64 = 0;
    for i in 0..opts.frames {
        let (t, payload) = status_payload(i, &mut rng, opts.pattern == Pattern::Random);
        let packet = Packet::decode(t, &payload).map_err(|e| SimError::BadOption {
            option: "generate",
            message: format!("internal packet {t:#04x}: {e}"),
        })?;
        let now_us = (bits as f64 / opts.baud * 1e6) as u64;
        let n = sender
            .send(now_us, &packet, &mut buf)
            .map_err(|e| SimError::BadOption {
                option: "generate",
                message: format!("internal packet {t:#04x}: {e}"),
            })?;
        let mut rest = buf.get(..n).unwrap_or(&[]);
        // Split the sender's output into packets: head, type, length, payload.
        while let [_, ty, len, tail @ ..] = rest {
            let len = usize::from(*len);
            let (payload, next) = tail.split_at(len.min(tail.len()));
            out.push((
                out.len() + 1,
                BackRecord::Packet {
                    t_ns: None,
                    ty: *ty,
                    payload: payload.to_vec(),
                },
            ));
            bits += (3 + len as u64) * 10 + u64::from(super::encode::BACK_GAP_BITS);
            rest = next;
        }
    }
    Ok(out)
}

/// Line impairments (applied in this order: rate offset, skew, jitter, noise, stuck,
/// broken, gaps). Signal names are the file's default names (`clk`, `x`, `ch3`, ...).
#[derive(Debug, Clone, Default, PartialEq, clap::Args)]
pub struct ImpairOpts {
    /// Bit-rate offset of the sender in ppm (positive = fast), e.g. 20000 for +2 %.
    #[arg(long, value_name = "PPM", allow_hyphen_values = true)]
    pub rate_offset_ppm: Option<f64>,
    /// Edge jitter: every edge of every signal moves by up to +-NS (uniform, seeded).
    #[arg(long, value_name = "NS")]
    pub jitter_ns: Option<f64>,
    /// Delays one signal by NS (negative: earlier); repeatable.
    #[arg(long, value_name = "SIGNAL=NS", allow_hyphen_values = true)]
    pub skew: Vec<String>,
    /// A noise burst: COUNT glitches of 1 ps..WIDTH_NS between FROM_US and TO_US;
    /// repeatable.
    #[arg(long, value_name = "SIGNAL,FROM_US,TO_US,COUNT,WIDTH_NS")]
    pub noise: Vec<String>,
    /// A stuck channel: SIGNAL stays at LEVEL (0 or 1) from FROM_US on; repeatable.
    #[arg(long, value_name = "SIGNAL,FROM_US,LEVEL")]
    pub stuck: Vec<String>,
    /// A broken (open) channel from FROM_US on: reads as the line receiver's
    /// fail-safe level, high; repeatable.
    #[arg(long, value_name = "SIGNAL,FROM_US")]
    pub broken: Vec<String>,
    /// A clock gap: SIGNAL holds LEVEL (default 0) from FROM_US to TO_US, then resumes
    /// (the edges inside are lost); repeatable.
    #[arg(long, value_name = "SIGNAL,FROM_US,TO_US[,LEVEL]")]
    pub gap: Vec<String>,
}

fn bad(option: &'static str, message: impl Into<String>) -> SimError {
    SimError::BadOption {
        option,
        message: message.into(),
    }
}

/// Splits `s` at commas into exactly `min..=max` fields.
fn fields<'a>(
    option: &'static str,
    s: &'a str,
    min: usize,
    max: usize,
) -> Result<Vec<&'a str>, SimError> {
    let f: Vec<&str> = s.split(',').map(str::trim).collect();
    if f.len() < min || f.len() > max {
        return Err(bad(option, format!("`{s}` has {} fields", f.len())));
    }
    Ok(f)
}

fn num(option: &'static str, s: &str) -> Result<f64, SimError> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| bad(option, format!("`{s}` is not a number")))
}

fn us(option: &'static str, s: &str) -> Result<Ps, SimError> {
    let v = num(option, s)?;
    if v < 0.0 {
        return Err(bad(option, format!("time `{s}` is negative")));
    }
    Ok((v * 1e6).round() as Ps)
}

fn level(option: &'static str, s: &str) -> Result<bool, SimError> {
    match s {
        "0" => Ok(false),
        "1" => Ok(true),
        _ => Err(bad(option, format!("level `{s}` is not 0 or 1"))),
    }
}

impl ImpairOpts {
    /// Applies the impairments to `wave`; random ones draw from `seed`.
    pub fn apply(&self, wave: &mut Waveform, seed: u64) -> Result<(), SimError> {
        if let Some(ppm) = self.rate_offset_ppm {
            impair::rate_offset_ppm(wave, ppm)?;
        }
        for s in &self.skew {
            let (name, ns) = s
                .split_once('=')
                .ok_or_else(|| bad("--skew", format!("`{s}` is not SIGNAL=NS")))?;
            let delay = (num("--skew", ns)? * 1000.0).round() as i64;
            impair::skew(wave, &[(name.trim(), delay)])?;
        }
        if let Some(j) = self.jitter_ns {
            if !(j >= 0.0 && j.is_finite()) {
                return Err(bad("--jitter-ns", format!("{j} is not a width")));
            }
            impair::jitter(wave, &[], (j * 1000.0).round() as u64, seed)?;
        }
        for (k, s) in self.noise.iter().enumerate() {
            let f = fields("--noise", s, 5, 5)?;
            let [name, from, to, count, width] = f.as_slice() else {
                return Err(bad("--noise", format!("`{s}`: five fields expected")));
            };
            let count = count
                .parse::<usize>()
                .map_err(|_| bad("--noise", format!("count `{count}` is not a whole number")))?;
            let width = (num("--noise", width)? * 1000.0).round().max(0.0) as u64;
            impair::noise_burst(
                wave,
                name,
                (us("--noise", from)?, us("--noise", to)?),
                count,
                width,
                seed.wrapping_add(k as u64 + 1),
            )?;
        }
        for s in &self.stuck {
            let f = fields("--stuck", s, 3, 3)?;
            let [name, from, l] = f.as_slice() else {
                return Err(bad("--stuck", format!("`{s}`: three fields expected")));
            };
            impair::stuck_at(wave, name, us("--stuck", from)?, level("--stuck", l)?)?;
        }
        for s in &self.broken {
            let f = fields("--broken", s, 2, 2)?;
            let [name, from] = f.as_slice() else {
                return Err(bad("--broken", format!("`{s}`: two fields expected")));
            };
            impair::stuck_at(wave, name, us("--broken", from)?, true)?;
        }
        for s in &self.gap {
            let f = fields("--gap", s, 3, 4)?;
            let (name, from, to) = match f.as_slice() {
                [n, a, b, ..] => (*n, *a, *b),
                _ => {
                    return Err(bad(
                        "--gap",
                        format!("`{s}`: three or four fields expected"),
                    ))
                }
            };
            let l = match f.get(3) {
                Some(l) => level("--gap", l)?,
                None => false,
            };
            impair::gap(wave, name, us("--gap", from)?, us("--gap", to)?, l)?;
        }
        Ok(())
    }
}
