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

/// XY2-100: `clk sync x y` (+ `z` when `want_z` and the capture has it) -> port words.
pub fn xy2(path: &Path, map: &NameMap, want_z: bool) -> Result<Xy2Input, SimError> {
    let (r, d): (&[&str], &[&str]) = if want_z {
        (
            &[roles::CLK, roles::SYNC, roles::X, roles::Y, roles::Z],
            &[
                names::CLK,
                names::SYNC,
                names::XY2_DATA[0],
                names::XY2_DATA[1],
                names::XY2_DATA[2],
            ],
        )
    } else {
        (
            &[roles::CLK, roles::SYNC, roles::X, roles::Y],
            &[
                names::CLK,
                names::SYNC,
                names::XY2_DATA[0],
                names::XY2_DATA[1],
            ],
        )
    };
    let wave = read_capture(path, r, d, 4, map)?;
    let pins = PinMap {
        z: wave.get(roles::Z).and(XY2_PINS.z),
        ..XY2_PINS
    };
    let (mut words, mut times) = sample::xy2_port_samples(&wave, &pins)?;
    // The receiver only trusts a frame whose SYNC rising edge it saw (a low sample,
    // then high ones). The firmware gets samples at CLK edges only, so a capture that
    // starts with the line idle and CLK stopped would lose its first frame although the
    // capture shows it whole. SYNC low at the capture start counts as one idle sample
    // (its data bits never reach a decoded word: a frame is the 20 samples after it).
    if wave.get(roles::SYNC).is_some_and(|s| !s.level_at(0)) {
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

/// XY3-100: `clk sync x` + whichever of `y z u w` the capture has -> SPI bytes.
pub fn xy3(path: &Path, map: &NameMap) -> Result<Xy3Input, SimError> {
    let all = [roles::X, roles::Y, roles::Z, roles::U, roles::W];
    let mut r: Vec<&str> = vec![roles::CLK, roles::SYNC];
    r.extend(all);
    let mut d: Vec<&str> = vec![names::CLK, names::SYNC];
    d.extend(names::XY3_DATA);
    // X is required; the other lines may be absent.
    let wave = read_capture(path, &r, &d, 3, map)?;
    let present: Vec<(Axis, &'static str, &'static str)> = Axis::ALL
        .into_iter()
        .zip(all)
        .zip(names::XY3_DATA)
        .filter(|((_, role), _)| wave.get(role).is_some())
        .map(|((a, role), key)| (a, role, key))
        .collect();
    let lanes: Vec<&str> = present.iter().map(|(_, role, _)| *role).collect();
    let spi = sample::xy3_spi(&wave, &lanes, PartialByte::Discard)?;
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
/// `oversample` x 12.5 MHz whose phase is drawn from `seed` -> `u16` rings.
pub fn hans(
    path: &Path,
    map: &NameMap,
    channels: &[u8],
    oversample: u8,
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
    let used: Vec<&str> = r.get(..required).unwrap_or(&[]).to_vec();
    let sampled_end = used
        .iter()
        .filter_map(|n| wave.get(n))
        .map(crate::wave::Signal::end_time)
        .max()
        .unwrap_or(0);
    let fs_hz = 12.5e6 * f64::from(oversample);
    // Phase: somewhere inside the first sample period, reproducible from the seed.
    let start_ps = (seed % 1000) as f64 / 1000.0 * PS_PER_S / fs_hz;
    // 2 us of the lines' final levels after the last change: enough for a period
    // still waiting for a missing channel to close (two words), too short for the
    // idle level to look like a frame.
    let end = sampled_end.saturating_add(2_000_000);
    let words32 = Oversampler { fs_hz, start_ps }.sample(&wave, &used, end)?;
    // The firmware's rings are u16, MSB first: each u32 is two of them.
    let rings = channels
        .iter()
        .copied()
        .zip(words32)
        .map(|(c, ch)| {
            (
                c,
                ch.iter()
                    .flat_map(|w| [(w >> 16) as u16, *w as u16])
                    .collect(),
            )
        })
        .collect();
    Ok(HansInput {
        rings,
        fs_hz,
        start_ps,
        capture_end_ps: wave.end_time(),
    })
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
