//! `decode`: capture -> the firmware's DMA buffers -> the `shared` receivers -> records.
//!
//! The backchannel works end to end: UART 8N1 frames ([`uart::uart_decode`]) feed the
//! firmware's [`Parser`]. For XY2-100, XY3-100 and HANS-100 the capture is read and
//! turned into exactly the buffers the firmware's DMA fills (port words, SPI bytes plus
//! frame ends, oversampled `u16` words); the line-level receivers that consume them
//! are not merged yet, so these return [`SimError::NotAvailable`] at the marked
//! plug-in points.

use std::collections::BTreeMap;
use std::fmt;

use shared::xy2;
use shared::xy3::back::{Event, Parser};

use super::jsonl::{BackRecord, ForwardRecord, HansRecord};
use super::{names, SimError};
use crate::line::sample::{self, Oversampler, PartialByte, PinMap, SpiCapture};
use crate::line::{roles, uart};
use crate::vcd_io::{self, NameMap, VcdError};
use crate::wave::{Ps, Waveform};

/// What a decode run saw, for the summary on stderr.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Summary {
    /// Accepted frames or packets.
    pub accepted: usize,
    /// Error records by kind.
    pub errors: BTreeMap<String, usize>,
    /// Times the receiver (re)gained sync, the first time included.
    pub resyncs: u32,
    /// Bytes (backchannel) discarded while out of sync.
    pub dropped: u32,
}

impl Summary {
    fn error(&mut self, kind: &str) {
        *self.errors.entry(kind.to_owned()).or_default() += 1;
    }
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let errors: usize = self.errors.values().sum();
        write!(
            f,
            "accepted {}, errors {errors}, resyncs {}, dropped bytes {}",
            self.accepted, self.resyncs, self.dropped
        )?;
        for (kind, n) in &self.errors {
            write!(f, "\n  {kind}: {n}")?;
        }
        Ok(())
    }
}

fn ns(ps: Ps) -> u64 {
    (ps + 500) / 1000
}

/// Reads `roles` from a capture, each under its default file name (`defaults`, same
/// order) unless `--map` renames it. Signals come back named by role. Roles from
/// `optional_from` on may be missing.
pub fn read_capture(
    path: &std::path::Path,
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

/// XY2-100: `clk sync x y` (+ `z`) -> port words -> receiver.
pub fn xy2(
    path: &std::path::Path,
    map: &NameMap,
    config: &xy2::LinkConfig,
) -> Result<(Vec<ForwardRecord>, Summary), SimError> {
    let wave = read_capture(
        path,
        &[roles::CLK, roles::SYNC, roles::X, roles::Y, roles::Z],
        &[
            names::CLK,
            names::SYNC,
            names::XY2_DATA[0],
            names::XY2_DATA[1],
            names::XY2_DATA[2],
        ],
        4,
        map,
    )?;
    let pins = PinMap {
        z: wave.get(roles::Z).and(XY2_PINS.z),
        ..XY2_PINS
    };
    let words = sample::xy2_port_words(&wave, &pins)?;
    // PLUG-IN (shared::xy2::rx): feed `words` (with `pins` and `config`) to the XY2-100
    // receiver and turn its events into records (frame start = time of the frame's
    // first CLK falling edge minus half a bit).
    Err(SimError::NotAvailable {
        what: format!(
            "decode --protocol xy2 ({:?}, {:?}; {} port words read)",
            config.mode,
            config.parity,
            words.len()
        ),
        needs: "the XY2-100 line receiver shared::xy2::rx (not merged yet)",
    })
}

/// XY3-100: `clk sync` + the data lines present -> SPI bytes and frame ends ->
/// receiver.
pub fn xy3(
    path: &std::path::Path,
    map: &NameMap,
) -> Result<(Vec<ForwardRecord>, Summary), SimError> {
    let all = [roles::X, roles::Y, roles::Z, roles::U, roles::W];
    let mut r: Vec<&str> = vec![roles::CLK, roles::SYNC];
    r.extend(all);
    let mut d: Vec<&str> = vec![names::CLK, names::SYNC];
    d.extend(names::XY3_DATA);
    // X is required; the other lines may be absent.
    let wave = read_capture(path, &r, &d, 3, map)?;
    let lanes: Vec<&str> = all.into_iter().filter(|l| wave.get(l).is_some()).collect();
    let cap: SpiCapture = sample::xy3_spi(&wave, &lanes, PartialByte::Discard)?;
    // PLUG-IN (shared::xy3::rx): feed `cap.bytes` and `cap.frame_ends` to the XY3-100
    // receiver and turn its per-channel results into records.
    Err(SimError::NotAvailable {
        what: format!(
            "decode --protocol xy3 ({} frames framed by SYNC)",
            cap.frame_ends.len()
        ),
        needs: "the XY3-100 line receiver shared::xy3::rx (not merged yet)",
    })
}

/// How the HANS-100 receiver combines the channels (`--hans-mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HansMode {
    /// Decode only channel N (1..=5).
    Normal(u8),
    /// Bitwise majority of channels 1..3.
    Vote3,
    /// Bitwise majority of all five.
    Vote5,
    /// Five decoders; a frame counts when any channel verifies.
    Super,
}

impl std::str::FromStr for HansMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "vote3" => Ok(Self::Vote3),
            "vote5" => Ok(Self::Vote5),
            "super" => Ok(Self::Super),
            _ => match s.strip_prefix("normal:").map(str::parse::<u8>) {
                Some(Ok(n @ 1..=5)) => Ok(Self::Normal(n)),
                _ => Err(format!(
                    "`{s}`: expected normal:N (N = 1..5), vote3, vote5 or super"
                )),
            },
        }
    }
}

/// HANS-100: `ch1`..`ch5` sampled like the firmware (oversampling clock of
/// `oversample` x 12.5 MHz with an arbitrary phase from `seed`) -> `u16` rings ->
/// receiver.
pub fn hans(
    path: &std::path::Path,
    map: &NameMap,
    mode: HansMode,
    oversample: u8,
    seed: u64,
) -> Result<(Vec<HansRecord>, Summary), SimError> {
    // Normal mode needs its one channel only; the others need all five.
    let (r, d): (Vec<&str>, Vec<&str>) = match mode {
        HansMode::Normal(n) => {
            let i = usize::from(n.saturating_sub(1));
            (
                roles::HANS_CHANNELS.get(i..=i).unwrap_or(&[]).to_vec(),
                names::HANS.get(i..=i).unwrap_or(&[]).to_vec(),
            )
        }
        _ => (roles::HANS_CHANNELS.to_vec(), names::HANS.to_vec()),
    };
    let wave = read_capture(path, &r, &d, r.len(), map)?;
    let fs = 12.5e6 * f64::from(oversample);
    // Phase: somewhere inside the first sample period, reproducible from the seed.
    let start_ps = (seed % 1000) as f64 / 1000.0 * 1e12 / fs;
    let end = wave.end_time().saturating_add(1_000_000);
    let words32 = Oversampler {
        fs_hz: fs,
        start_ps,
    }
    .sample(&wave, &r, end)?;
    // The firmware's rings are u16, MSB first (layouts item 3): each u32 is two of them.
    let rings: Vec<Vec<u16>> = words32
        .iter()
        .map(|ch| {
            ch.iter()
                .flat_map(|w| [(w >> 16) as u16, *w as u16])
                .collect()
        })
        .collect();
    // PLUG-IN (shared::hans::rx): feed `rings` (mode, fs) to the HANS-100 receiver and
    // turn accepted / rejected frames into records.
    Err(SimError::NotAvailable {
        what: format!(
            "decode --protocol hans ({mode:?}, {} sample words per channel)",
            rings.first().map_or(0, Vec::len)
        ),
        needs: "the HANS-100 line receiver shared::hans::rx (not merged yet)",
    })
}

/// Backchannel: the `back` line -> UART bytes -> [`Parser`] -> records.
///
/// Records: every packet the parser delivers, plus the SYNC packet behind each resync
/// (the parser reports that one as a resync event, the format lists it as a packet);
/// errors for lost sync, for a resync that dropped bytes, and for UART framing errors
/// (the byte is still passed on, as the UART's data register would).
pub fn back(wave: &Waveform, baud: f64) -> Result<(Vec<BackRecord>, Summary), SimError> {
    let line = wave
        .get(names::BACK)
        .ok_or_else(|| crate::line::LineError::MissingSignal {
            name: names::BACK.to_owned(),
            available: wave.names(),
        })?;
    let frames = uart::uart_decode(line, baud)?;
    let mut parser = Parser::new();
    let mut times: Vec<Ps> = Vec::with_capacity(frames.len());
    let mut out = Vec::new();
    let mut sum = Summary::default();
    for f in frames {
        if f.framing_error {
            out.push(BackRecord::Error {
                t_ns: Some(ns(f.time)),
                error: "UART framing error (stop bit low)".to_owned(),
            });
            sum.error("uart framing error");
        }
        times.push(f.time);
        let idx = times.len() - 1;
        let at = |back: usize| ns(times.get(idx.saturating_sub(back)).copied().unwrap_or(0));
        match parser.push(f.value) {
            None => {}
            Some(Event::Packet(p)) => {
                out.push(BackRecord::Packet {
                    t_ns: Some(at(2 + p.payload.len())),
                    ty: p.ty,
                    payload: p.payload.to_vec(),
                });
                sum.accepted += 1;
            }
            Some(Event::Resynced { dropped }) => {
                // This byte is the head of the next packet; the SYNC is the 3 before.
                if dropped > 0 {
                    out.push(BackRecord::Error {
                        t_ns: Some(at(3)),
                        error: format!("resynced after dropping {dropped} bytes"),
                    });
                    sum.error("resync after dropped bytes");
                }
                out.push(BackRecord::Packet {
                    t_ns: Some(at(3)),
                    ty: shared::xy3::back::wire::ty::SYNC,
                    payload: Vec::new(),
                });
                sum.accepted += 1;
            }
            Some(Event::LostSync { reason }) => {
                out.push(BackRecord::Error {
                    t_ns: Some(ns(f.time)),
                    error: format!("lost sync: {reason}"),
                });
                sum.error(match reason {
                    shared::xy3::back::LostSyncReason::MissingHead { .. } => {
                        "lost sync: missing head"
                    }
                    shared::xy3::back::LostSyncReason::BadLength { .. } => "lost sync: bad length",
                });
            }
        }
    }
    let stats = parser.stats();
    sum.resyncs = stats.resyncs;
    sum.dropped = stats.dropped_bytes;
    Ok((out, sum))
}
