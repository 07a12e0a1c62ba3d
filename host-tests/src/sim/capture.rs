//! Captures -> exactly the buffers the firmware's receive DMA fills (README "DMA
//! buffer layouts"), plus a parallel vector of sample times: the firmware's buffers
//! carry no time, the host tools want one (record `t_ns`, the bridge's clock).
//!
//! One place for the capture side of `decode` and `bridge`, so both feed the `shared`
//! receivers the same buffers:
//! - XY2-100: port words at CLK falling edges ([`sample::xy2_port_samples`]);
//! - XY3-100: SPI-slave bytes per line plus SYNC frame ends ([`sample::xy3_spi`]);
//! - HANS-100: `u16` rings from an oversampling clock with an arbitrary phase
//!   ([`Oversampler`]);
//! - UART lines (XY3-100 backchannel): 8N1 frames ([`uart::uart_decode`]).

use std::path::Path;

use shared::model::Axis;

use super::{names, SimError};
use crate::line::sample::{self, Oversampler, PartialByte, PinMap, SpiCapture};
use crate::line::{roles, uart};
use crate::vcd_io::{self, NameMap, VcdError};
use crate::wave::{Ps, Waveform, PS_PER_S};

/// Reads `roles` from a capture, each under its default file name (`defaults`, same
/// order) unless `--map` renames it. Signals come back named by role. Roles from
/// `optional_from` on may be missing.
pub fn read_capture(
    path: &Path,
    roles: &[&str],
    defaults: &[&str],
    optional_from: usize,
    user: &NameMap,
) -> Result<Waveform, SimError> {
    let mut map = NameMap::new();
    for (role, default) in roles.iter().zip(defaults) {
        map.set(*role, user.resolve(default));
    }
    let mut wanted: Vec<&str> = roles.to_vec();
    loop {
        match vcd_io::read_vcd_file(path, &wanted, &map) {
            Err(VcdError::MissingSignal { role, .. })
                if wanted
                    .iter()
                    .position(|r| *r == role)
                    .is_some_and(|i| i >= optional_from) =>
            {
                wanted.retain(|r| *r != role);
            }
            other => return other.map_err(SimError::from),
        }
    }
}

/// The XY2-100 input pins used for simulation (any distinct bits would do).
pub const XY2_PINS: PinMap = PinMap {
    sync: 0,
    x: 1,
    y: 2,
    z: Some(3),
    status: None,
};

/// An XY2-100 capture as the firmware's TIM1-triggered DMA delivers it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Xy2Input {
    /// Port words, one per CLK falling edge.
    pub words: Vec<u16>,
    /// The time of each word (ps).
    pub times: Vec<Ps>,
    /// Which bit carries which line (`z` only when received).
    pub pins: PinMap,
}

impl Xy2Input {
    /// The receiver's pin map.
    pub fn rx_pins(&self) -> shared::xy2::rx::PinMap {
        shared::xy2::rx::PinMap {
            sync: self.pins.sync,
            x: self.pins.x,
            y: self.pins.y,
            z: self.pins.z,
        }
    }
}

/// Which data lines a capture must or may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lines<'a> {
    /// These lines are required, no others are read (the bridge: what its receiver
    /// takes).
    Exactly(&'a [Axis]),
    /// X and Y (XY2-100) or X (XY3-100) required, the others read when present
    /// (`decode`).
    Present,
}

/// The role and default file name of a data line (`None` for U / W on XY2-100).
fn line_names(axis: Axis, xy2: bool) -> Option<(&'static str, &'static str)> {
    let names: &[&'static str] = if xy2 {
        &names::XY2_DATA
    } else {
        &names::XY3_DATA
    };
    Some((*roles::AXES.get(axis.index())?, *names.get(axis.index())?))
}

/// `clk sync` and the data lines of `lines`: roles, default names and the index
/// from which they are optional.
fn forward_names(lines: Lines<'_>, xy2: bool) -> (Vec<&'static str>, Vec<&'static str>, usize) {
    let (axes, required): (&[Axis], usize) = match lines {
        Lines::Exactly(a) => (a, a.len()),
        Lines::Present if xy2 => (&[Axis::X, Axis::Y, Axis::Z], 2),
        Lines::Present => (&Axis::ALL, 1),
    };
    let (mut r, mut d) = (vec![roles::CLK, roles::SYNC], vec![names::CLK, names::SYNC]);
    for (role, name) in axes.iter().filter_map(|a| line_names(*a, xy2)) {
        r.push(role);
        d.push(name);
    }
    (r, d, 2 + required)
}

/// XY2-100: `clk sync` and the data lines of `lines` (X, Y, optionally Z) -> port
/// words.
pub fn xy2(path: &Path, map: &NameMap, lines: Lines<'_>) -> Result<Xy2Input, SimError> {
    let (r, d, optional_from) = forward_names(lines, true);
    let wave = read_capture(path, &r, &d, optional_from, map)?;
    xy2_from_wave(&wave, LeadIdle::IfSyncLow)
}

/// Whether an XY2-100 capture gets an idle sample (word 0 at t = 0) in front.
///
/// The receiver only trusts a frame whose SYNC rising edge it saw (a low sample, then
/// high ones). The firmware gets samples at CLK edges only, so a line that starts
/// idle with CLK stopped would lose its first frame although it is there whole; the
/// idle sample stands for the line before the first CLK edge (its data bits never
/// reach a decoded word: a frame is the 20 samples after it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeadIdle {
    /// When SYNC is low at t = 0 (a recorded capture shows the line as it was).
    IfSyncLow,
    /// Always (a generated line that idles low before its first frame).
    Always,
}

/// XY2-100 from a waveform with role-named signals (`CLK SYNC X Y`, and `Z` when
/// present) -> port words, with an idle sample in front as `lead` says.
pub fn xy2_from_wave(wave: &Waveform, lead: LeadIdle) -> Result<Xy2Input, SimError> {
    let pins = PinMap {
        z: wave.get(roles::Z).and(XY2_PINS.z),
        ..XY2_PINS
    };
    let (mut words, mut times) = sample::xy2_port_samples(wave, &pins)?;
    let idle = match lead {
        LeadIdle::IfSyncLow => wave.get(roles::SYNC).is_some_and(|s| !s.level_at(0)),
        LeadIdle::Always => true,
    };
    if idle {
        words.insert(0, 0);
        times.insert(0, 0);
    }
    Ok(Xy2Input { words, times, pins })
}

/// An XY3-100 capture as the SPI slaves and the SYNC EXTI deliver it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Xy3Input {
    /// Bytes per line present (order of `present`), frame ends, byte and end times.
    pub spi: SpiCapture,
    /// Lines present: axis, role, JSON key (X always first).
    pub present: Vec<(Axis, &'static str, &'static str)>,
}

impl Xy3Input {
    /// The axes of the lines present, in `spi.bytes` order.
    pub fn axes(&self) -> Vec<Axis> {
        self.present.iter().map(|(a, _, _)| *a).collect()
    }
}

/// XY3-100: `clk sync` and the data lines of `lines` -> SPI bytes.
pub fn xy3(path: &Path, map: &NameMap, lines: Lines<'_>) -> Result<Xy3Input, SimError> {
    let (r, d, optional_from) = forward_names(lines, false);
    let wave = read_capture(path, &r, &d, optional_from, map)?;
    xy3_from_wave(&wave)
}

/// XY3-100 from a waveform with role-named signals (`CLK SYNC X`, and whichever of
/// `Y Z U W` it has) -> SPI bytes.
pub fn xy3_from_wave(wave: &Waveform) -> Result<Xy3Input, SimError> {
    let present: Vec<(Axis, &'static str, &'static str)> = Axis::ALL
        .into_iter()
        .filter_map(|a| line_names(a, false).map(|(role, key)| (a, role, key)))
        .filter(|(_, role, _)| wave.get(role).is_some())
        .collect();
    let lanes: Vec<&str> = present.iter().map(|(_, role, _)| *role).collect();
    let spi = sample::xy3_spi(wave, &lanes, PartialByte::Discard)?;
    Ok(Xy3Input { spi, present })
}

/// HANS-100 channels sampled like the firmware samples them.
#[derive(Debug, Clone, PartialEq)]
pub struct HansInput {
    /// `(channel 1..=5, ring)`: the `u16` words of each sampled channel, MSB first =
    /// earliest sample, all channels at the same instants.
    pub rings: Vec<(u8, Vec<u16>)>,
    /// Sampling clock (Hz).
    pub fs_hz: f64,
    /// Time of the first sample (ps): the clock's arbitrary phase.
    pub start_ps: f64,
    /// The last change of any HANS signal in the capture, sampled or not (ps).
    pub capture_end_ps: Ps,
}

impl HansInput {
    /// Words per channel.
    pub fn words(&self) -> usize {
        self.rings.first().map_or(0, |(_, r)| r.len())
    }

    /// Duration of one `u16` word (ps).
    pub fn word_ps(&self) -> f64 {
        16.0 * PS_PER_S / self.fs_hz
    }

    /// Word `i` of every sampled channel, placed at index `channel - 1` (the shape
    /// [`shared::hans::rx::HansRx::push`] takes); channels not sampled get nothing.
    pub fn chunks(&self, i: usize) -> [&[u16]; 5] {
        let mut chunks: [&[u16]; 5] = [&[]; 5];
        for (ch, ring) in &self.rings {
            let slot = usize::from(ch.saturating_sub(1));
            if let (Some(c), Some(w)) = (chunks.get_mut(slot), ring.get(i..=i)) {
                *c = w;
            }
        }
        chunks
    }
}

/// The HANS-100 channel signals of `channels` (1..=5) as the file names them.
fn hans_names(channels: &[u8]) -> (Vec<&'static str>, Vec<&'static str>) {
    channels
        .iter()
        .filter_map(|&c| {
            let i = usize::from(c.checked_sub(1)?);
            Some((*roles::HANS_CHANNELS.get(i)?, *names::HANS.get(i)?))
        })
        .unzip()
}

/// HANS-100: the `channels` (1..=5, required) sampled by an oversampling clock of
/// `fs_hz` whose phase is drawn from `seed` -> `u16` rings.
pub fn hans(
    path: &Path,
    map: &NameMap,
    channels: &[u8],
    fs_hz: f64,
    seed: u64,
) -> Result<HansInput, SimError> {
    let (mut r, mut d) = hans_names(channels);
    let required = r.len();
    // The others are read too (if present) for the capture's end: silence at the end
    // of a capture is measured against all of its HANS signals.
    let others: Vec<u8> = (1..=5).filter(|c| !channels.contains(c)).collect();
    let (ro, dn) = hans_names(&others);
    r.extend(ro);
    d.extend(dn);
    let wave = read_capture(path, &r, &d, required, map)?;
    let used = r.get(..required).unwrap_or(&[]);
    let (words, start_ps) = oversample(&wave, used, fs_hz, seed)?;
    Ok(HansInput {
        rings: channels.iter().copied().zip(words).collect(),
        fs_hz,
        start_ps,
        capture_end_ps: wave.end_time(),
    })
}

/// Samples the signals `used` of `wave` like the firmware's oversampling SPI slaves,
/// with a clock phase drawn from `seed` ([`oversample_at`]).
pub fn oversample(
    wave: &Waveform,
    used: &[&str],
    fs_hz: f64,
    seed: u64,
) -> Result<(Vec<Vec<u16>>, f64), SimError> {
    oversample_at(wave, used, fs_hz, (seed % 1000) as f64 / 1000.0)
}

/// Samples the signals `used` of `wave` like the firmware's oversampling SPI slaves:
/// a free-running clock of `fs_hz` whose first sample lies `phase` (0..1, clamped)
/// of a sample period after t = 0, `u16` words MSB first = earliest sample, up to
/// 2 us after the signals' last change. Returns the words per signal and the first
/// sample's time (ps).
pub fn oversample_at(
    wave: &Waveform,
    used: &[&str],
    fs_hz: f64,
    phase: f64,
) -> Result<(Vec<Vec<u16>>, f64), SimError> {
    let fs_hz = crate::line::positive("sampling clock (Hz)", fs_hz)?;
    let last = used
        .iter()
        .filter_map(|n| wave.get(n))
        .map(crate::wave::Signal::end_time)
        .max()
        .unwrap_or(0);
    let start_ps = phase.clamp(0.0, 1.0) * PS_PER_S / fs_hz;
    // 2 us of the lines' final levels after the last change: enough for a HANS-100
    // period still waiting for a missing channel to close (two words), too short for
    // the idle level to look like a frame.
    let end = last.saturating_add(2_000_000);
    let words32 = Oversampler { fs_hz, start_ps }.sample(wave, used, end)?;
    // The firmware's rings are u16, MSB first: each u32 is two of them.
    let words = words32
        .iter()
        .map(|ch| {
            ch.iter()
                .flat_map(|w| [(w >> 16) as u16, *w as u16])
                .collect()
        })
        .collect();
    Ok((words, start_ps))
}

/// A UART line (role `role`, default file name `default`) -> 8N1 frames at `baud`.
pub fn uart_line(
    path: &Path,
    map: &NameMap,
    role: &str,
    default: &str,
    baud: f64,
) -> Result<Vec<uart::UartFrame>, SimError> {
    let wave = read_capture(path, &[role], &[default], 1, map)?;
    uart_frames(&wave, role, baud)
}

/// The 8N1 frames of signal `name` of `wave` at `baud`.
pub fn uart_frames(
    wave: &Waveform,
    name: &str,
    baud: f64,
) -> Result<Vec<uart::UartFrame>, SimError> {
    let line = crate::line::signal(wave, name)?;
    Ok(uart::uart_decode(line, baud)?)
}
