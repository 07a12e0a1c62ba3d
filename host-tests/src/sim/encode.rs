//! Records -> waveforms: the one path `generate` and `encode` share.
//!
//! Words come from the `shared` codecs, waveforms from [`crate::line`]:
//! - XY2-100 / XY3-100: each frame through [`serial::xy2_waveform`] /
//!   [`serial::xy3_waveform`], placed at its `t_ns` (or back to back: XY2-100 20 bit
//!   times, XY3-100 one idle bit between frames, or every `--frame-period-ns`);
//! - HANS-100: frames packed MSB first into one bitstream ([`hans::Frame::write_at`],
//!   the layout of the transmit ring) played at 12.5 MHz by
//!   [`drive::bitstream_to_signal`], the same stream on `ch1`..`ch5`; frames are always
//!   back to back (the line never pauses), so input `t_ns` are not used;
//! - backchannel: head, type, length and payload bytes as 8N1 UART
//!   ([`uart::uart_encode`]) at each packet's `t_ns` or back to back.
//!
//! Records that say `error` become frames the receiver must reject again (XY2-100 /
//! XY3-100: a centre position with the parity bit inverted; HANS-100: a centre frame
//! with DATA1 D19 equal to its complement), so `decode | encode` keeps errors in
//! place. Backchannel error records are not sent.

use shared::{hans, xy2, xy3};

use super::jsonl::{BackRecord, Channel, ForwardRecord, HansRecord};
use super::{names, Protocol, SimError};
use crate::line::drive::{bitstream_to_signal, HANS_BIT_RATE_HZ};
use crate::line::serial::{self, FrameTiming, FrameWord, Idle, Lane};
use crate::line::{roles, uart};
use crate::wave::{Ps, Waveform, PS_PER_S};

/// Timing of a generated forward (XY2-100 / XY3-100) waveform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardTiming {
    /// Bit clock in Hz.
    pub bit_rate_hz: f64,
    /// Frame start-to-start period in ns for records without `t_ns`; `None` = back to
    /// back.
    pub frame_period_ns: Option<f64>,
    /// Start of the first frame in ns for records without `t_ns`.
    pub start_ns: f64,
}

/// A waveform and the start time (ns) of every frame or packet in it.
#[derive(Debug, Clone, PartialEq)]
pub struct Encoded {
    /// The signals, under the default names of [`names`].
    pub wave: Waveform,
    /// Start of each record that was sent, in ns.
    pub starts_ns: Vec<u64>,
}

fn no_frames() -> SimError {
    SimError::BadOption {
        option: "--frames",
        message: "the input has no frames".to_owned(),
    }
}

fn json_err(line: usize, message: impl Into<String>) -> SimError {
    SimError::Json {
        line,
        message: message.into(),
    }
}

/// Appends `src` to `dst` from time `from` on (`dst` must end by then): levels at
/// `from` and every later change. Signals new to `dst` are added whole.
fn append(dst: &mut Waveform, src: &Waveform, from: Ps) -> Result<(), SimError> {
    for s in src.signals() {
        match dst.get_mut(s.name()) {
            Some(d) => {
                d.push(from, s.level_at(from))?;
                for &(t, l) in s.changes().iter().filter(|&&(t, _)| t > from) {
                    d.push(t, l)?;
                }
            }
            None => dst.add(s.clone())?,
        }
    }
    Ok(())
}

fn ns_to_ps(ns: u64) -> Ps {
    ns.saturating_mul(1000)
}

fn ps_to_ns(ps: f64) -> u64 {
    (ps / 1000.0).round().max(0.0) as u64
}

/// All records carry `t_ns` (`Some(times)`) or none does (`None`); mixed is an error.
fn explicit_times(times: &[(usize, Option<u64>)]) -> Result<Option<Vec<u64>>, SimError> {
    let given = times.iter().filter(|(_, t)| t.is_some()).count();
    if given == 0 {
        return Ok(None);
    }
    if let Some((line, _)) = times.iter().find(|(_, t)| t.is_none()) {
        return Err(json_err(
            *line,
            "no \"t_ns\" although other lines have one (give it on every line or none)",
        ));
    }
    Ok(Some(times.iter().filter_map(|(_, t)| *t).collect()))
}

/// XY2-100 word of one channel.
fn xy2_word(ch: &Channel, config: &xy2::LinkConfig) -> Result<u32, String> {
    let frame = match *ch {
        Channel::Pos { pos, bits: 16 } => xy2::Frame::Position16(pos as u16),
        Channel::Pos { pos, bits: 18 } => xy2::Frame::Position18(pos),
        Channel::Pos { bits, .. } => {
            return Err(format!("XY2-100 positions have 16 or 18 bits, not {bits}"))
        }
        Channel::Cmd {
            frame_bits: Some(_),
            ..
        } => return Err("\"frame_bits\" is for XY3-100 commands".to_owned()),
        Channel::Cmd { cmd, .. } => {
            if cmd > 0xFFFF {
                return Err(format!(
                    "XY2-100 command {cmd:#x} is wider than command << 8 | parameter"
                ));
            }
            xy2::Frame::Command {
                command: (cmd >> 8) as u8,
                parameter: cmd as u8,
            }
        }
        Channel::Error(_) => {
            let centre = match config.mode {
                xy2::Mode::Standard16 => xy2::Frame::Position16(0x8000),
                xy2::Mode::Extended18 => xy2::Frame::Position18(0x2_0000),
            };
            let word = xy2::encode(centre, config).map_err(|e| e.to_string())?;
            return Ok(word ^ 1);
        }
    };
    xy2::encode(frame, config).map_err(|e| e.to_string())
}

/// The XY3-100 frame size of a record: agreed by its positions and sized commands.
fn xy3_size(rec: &ForwardRecord, lanes: &[&str]) -> Result<xy3::FrameSize, String> {
    let mut size = None;
    for lane in lanes {
        let s = match rec.channel(lane) {
            Some(Channel::Pos { bits: 20, .. }) => Some(xy3::FrameSize::Bits24),
            Some(Channel::Pos { bits: 26, .. }) => Some(xy3::FrameSize::Bits32),
            Some(Channel::Pos { bits, .. }) => {
                return Err(format!(
                    "channel {lane}: XY3-100 positions have 20 or 26 bits, not {bits}"
                ))
            }
            Some(Channel::Cmd {
                frame_bits: Some(32),
                ..
            }) => Some(xy3::FrameSize::Bits32),
            Some(Channel::Cmd {
                frame_bits: Some(_),
                ..
            }) => Some(xy3::FrameSize::Bits24),
            _ => None,
        };
        match (size, s) {
            (Some(a), Some(b)) if a != b => {
                return Err("channels disagree on the frame size (24 / 32 bits)".to_owned())
            }
            (None, Some(b)) => size = Some(b),
            _ => {}
        }
    }
    Ok(size.unwrap_or(xy3::FrameSize::Bits24))
}

/// XY3-100 word of one channel in a frame of `size`.
fn xy3_word(ch: &Channel, size: xy3::FrameSize) -> Result<u32, String> {
    use xy3::{Frame, FrameSize};
    let frame = match (ch, size) {
        (Channel::Pos { pos, .. }, FrameSize::Bits24) => Frame::Position24(*pos),
        (Channel::Pos { pos, .. }, FrameSize::Bits32) => Frame::Position32(*pos),
        (Channel::Cmd { cmd, .. }, FrameSize::Bits24) => Frame::Command24(*cmd),
        (Channel::Cmd { cmd, .. }, FrameSize::Bits32) => Frame::Command32 {
            code: *cmd,
            unused: 0,
        },
        (Channel::Error(_), FrameSize::Bits24) => Frame::Position24(0x8_0000),
        (Channel::Error(_), FrameSize::Bits32) => Frame::Position32(0x200_0000),
    };
    let (word, _) = xy3::encode(&frame).map_err(|e| e.to_string())?;
    Ok(if matches!(ch, Channel::Error(_)) {
        word ^ 1
    } else {
        word
    })
}

/// XY2-100 or XY3-100 records -> `clk`, `sync` and one line per channel present in
/// the first record (every record must have the same channels).
pub fn forward(
    protocol: Protocol,
    records: &[(usize, ForwardRecord)],
    xy2_config: &xy2::LinkConfig,
    timing: &ForwardTiming,
) -> Result<Encoded, SimError> {
    let all: &[&'static str] = match protocol {
        Protocol::Xy2 => &names::XY2_DATA,
        _ => &names::XY3_DATA,
    };
    let Some((first_line, first)) = records.first() else {
        return Err(no_frames());
    };
    let lanes: Vec<&'static str> = all
        .iter()
        .copied()
        .filter(|l| first.channel(l).is_some())
        .collect();
    if lanes.is_empty() {
        return Err(json_err(*first_line, "the frame has no channel"));
    }
    for (line, rec) in records {
        let extra = ["x", "y", "z", "u", "w"]
            .iter()
            .find(|l| rec.channel(l).is_some() != lanes.contains(l));
        if let Some(l) = extra {
            return Err(json_err(
                *line,
                format!("channel {l} present here but not on line {first_line} or vice versa (or not a {protocol} channel)"),
            ));
        }
    }
    let times: Vec<(usize, Option<u64>)> = records.iter().map(|(l, r)| (*l, r.t_ns)).collect();
    let explicit = explicit_times(&times)?;
    let t_bit = PS_PER_S / crate::line::positive("bit_rate_hz", timing.bit_rate_hz)?;

    let mut wave = Waveform::new();
    let mut starts_ns = Vec::with_capacity(records.len());
    let mut next_start = timing.start_ns * 1000.0;
    let mut prev_end: f64 = 0.0;
    let mut progress = Progress::new("encode", records.len());
    for (i, (line, rec)) in records.iter().enumerate() {
        let words: Vec<FrameWord> = match protocol {
            Protocol::Xy2 => lanes
                .iter()
                .map(|l| {
                    rec.channel(l)
                        .ok_or_else(|| format!("channel {l} missing"))
                        .and_then(|c| xy2_word(c, xy2_config))
                        .map(|value| FrameWord { value, bits: 20 })
                        .map_err(|m| json_err(*line, format!("channel {l}: {m}")))
                })
                .collect::<Result<_, _>>()?,
            _ => {
                let size = xy3_size(rec, &lanes).map_err(|m| json_err(*line, m))?;
                lanes
                    .iter()
                    .map(|l| {
                        rec.channel(l)
                            .ok_or_else(|| format!("channel {l} missing"))
                            .and_then(|c| xy3_word(c, size))
                            .map(|value| FrameWord {
                                value,
                                bits: size.bits(),
                            })
                            .map_err(|m| json_err(*line, format!("channel {l}: {m}")))
                    })
                    .collect::<Result<_, _>>()?
            }
        };
        let nbits = f64::from(words.first().map_or(20, |w| w.bits));
        let start = match &explicit {
            Some(t) => ns_to_ps(t.get(i).copied().unwrap_or(0)) as f64,
            None => next_start,
        };
        if start + 0.5 < prev_end {
            return Err(json_err(
                *line,
                format!(
                    "frame starts at {} ns, before the previous frame ends at {} ns",
                    ps_to_ns(start),
                    ps_to_ns(prev_end)
                ),
            ));
        }
        let lane_words: Vec<Lane<'_>> = lanes
            .iter()
            .zip(&words)
            .map(|(name, w)| Lane {
                name,
                words: std::slice::from_ref(w),
            })
            .collect();
        let t = FrameTiming {
            bit_rate_hz: timing.bit_rate_hz,
            frame_period_ps: None,
            idle: Idle::ClockStopped,
            start_ps: start,
        };
        let (frame, natural) = match protocol {
            Protocol::Xy2 => (serial::xy2_waveform(&lane_words, &t)?, nbits * t_bit),
            _ => (
                serial::xy3_waveform(&lane_words, &t)?,
                (nbits + 1.0) * t_bit,
            ),
        };
        append(&mut wave, &frame, crate::line::ps(start))?;
        starts_ns.push(ps_to_ns(start));
        // XY3-100 needs SYNC high for a while between frames (half a bit at least).
        prev_end = start
            + nbits * t_bit
            + if protocol == Protocol::Xy2 {
                0.0
            } else {
                t_bit / 2.0
            };
        let period = match timing.frame_period_ns {
            Some(p) => p * 1000.0,
            None => natural,
        };
        next_start = start + period.max(nbits * t_bit);
        progress.tick(i + 1);
    }
    rename(&mut wave, roles::CLK, names::CLK);
    rename(&mut wave, roles::SYNC, names::SYNC);
    Ok(Encoded { wave, starts_ns })
}

fn rename(wave: &mut Waveform, from: &str, to: &str) {
    if let Some(s) = wave.get_mut(from) {
        s.set_name(to);
    }
}

/// HANS-100 records -> `ch1`..`ch5` (the same stream on each), back to back from
/// `start_ns`.
pub fn hans(records: &[(usize, HansRecord)], start_ns: f64) -> Result<Encoded, SimError> {
    let n = records.len();
    if n == 0 {
        return Err(no_frames());
    }
    let mut stream = vec![0u8; (n * hans::FRAME_BITS).div_ceil(8)];
    let mut progress = Progress::new("encode", n);
    for (i, (line, rec)) in records.iter().enumerate() {
        let offset = i * hans::FRAME_BITS;
        let (frame, broken) = match rec {
            HansRecord::Frame {
                data: [a, b, c], ..
            } => (
                hans::Frame::new(*a, *b, *c).map_err(|e| json_err(*line, e.to_string()))?,
                false,
            ),
            HansRecord::Error { .. } => (hans::Frame::CENTRE, true),
        };
        frame
            .write_at(&mut stream, offset)
            .map_err(|e| json_err(*line, e.to_string()))?;
        if broken {
            // Stream bit offset + 2 is DATA1 D19; inverting it makes it equal to its
            // complement.
            let bit = offset + 2;
            if let Some(byte) = stream.get_mut(bit / 8) {
                *byte ^= 0x80 >> (bit % 8);
            }
        }
        progress.tick(i + 1);
    }
    let t0 = start_ns * 1000.0;
    let ch1 = bitstream_to_signal(
        names::HANS[0],
        &stream,
        HANS_BIT_RATE_HZ,
        crate::line::ps(t0),
    )?;
    let mut wave = Waveform::new();
    for name in names::HANS {
        let mut s = ch1.clone();
        s.set_name(name);
        wave.add(s)?;
    }
    let frame_ps = hans::FRAME_BITS as f64 * PS_PER_S / HANS_BIT_RATE_HZ;
    let starts_ns = (0..n).map(|i| ps_to_ns(t0 + i as f64 * frame_ps)).collect();
    Ok(Encoded { wave, starts_ns })
}

/// Idle bit times between back-to-back backchannel packets.
pub const BACK_GAP_BITS: u32 = 20;

/// Backchannel records -> the `back` UART line (8N1 at `baud`); error records are
/// skipped (their start is not listed).
pub fn back(
    records: &[(usize, BackRecord)],
    baud: f64,
    start_ns: f64,
) -> Result<Encoded, SimError> {
    let mut packets: Vec<(usize, Option<u64>, Vec<u8>)> = Vec::new();
    for (line, r) in records {
        if let BackRecord::Packet { t_ns, ty, payload } = r {
            let len = u8::try_from(payload.len())
                .map_err(|_| json_err(*line, "payload longer than 255 bytes"))?;
            let mut bytes = vec![xy3::back::wire::HEAD, *ty, len];
            bytes.extend_from_slice(payload);
            packets.push((*line, *t_ns, bytes));
        }
    }
    if packets.is_empty() {
        return Err(no_frames());
    }
    let times: Vec<(usize, Option<u64>)> = packets.iter().map(|(l, t, _)| (*l, *t)).collect();
    let explicit = explicit_times(&times)?;
    let bit = PS_PER_S / crate::line::positive("baud", baud)?;
    let mut wave = Waveform::new();
    wave.add(crate::wave::Signal::new(names::BACK, true))?;
    let mut starts_ns = Vec::with_capacity(packets.len());
    let mut next = start_ns * 1000.0;
    let mut prev_end = 0.0;
    for (i, (line, _, bytes)) in packets.iter().enumerate() {
        let start = match &explicit {
            Some(t) => ns_to_ps(t.get(i).copied().unwrap_or(0)) as f64,
            None => next,
        };
        if start + 0.5 < prev_end {
            return Err(json_err(
                *line,
                format!(
                    "packet starts at {} ns, before the previous one ends at {} ns",
                    ps_to_ns(start),
                    ps_to_ns(prev_end)
                ),
            ));
        }
        let t0 = crate::line::ps(start);
        let sig = uart::uart_encode(names::BACK, bytes, baud, t0, 0)?;
        let mut one = Waveform::new();
        one.add(sig)?;
        append(&mut wave, &one, t0)?;
        starts_ns.push(ps_to_ns(start));
        prev_end = start + (bytes.len() * 10) as f64 * bit;
        next = prev_end + f64::from(BACK_GAP_BITS) * bit;
    }
    Ok(Encoded { wave, starts_ns })
}

/// Progress on stderr for long runs: a line at every 10 % when there are at least
/// [`Progress::MIN_ITEMS`] items.
pub struct Progress {
    what: &'static str,
    total: usize,
    next_tenth: usize,
}

impl Progress {
    /// Below this many items nothing is printed.
    pub const MIN_ITEMS: usize = 200_000;

    /// A reporter for `total` items.
    pub fn new(what: &'static str, total: usize) -> Self {
        Self {
            what,
            total,
            next_tenth: 1,
        }
    }

    /// `done` items are finished.
    pub fn tick(&mut self, done: usize) {
        if self.total < Self::MIN_ITEMS || self.next_tenth > 10 {
            return;
        }
        if done * 10 >= self.next_tenth * self.total {
            eprintln!(
                "{}: {}% ({done} / {})",
                self.what,
                self.next_tenth * 10,
                self.total
            );
            self.next_tenth += 1;
        }
    }
}
