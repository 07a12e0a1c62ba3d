//! `decode`: capture -> the firmware's DMA buffers -> the `shared` receivers -> records.
//!
//! - XY2-100: port words at CLK falling edges ([`sample::xy2_port_samples`]) into
//!   [`xy2::rx::Receiver`]; one record per frame period it reports (framing faults
//!   included, as an error on every channel).
//! - XY3-100: SPI-slave bytes plus SYNC frame ends ([`sample::xy3_spi`]) into
//!   [`xy3::rx::Receiver`] in contract-sized chunks; one record per frame period.
//! - Backchannel: UART 8N1 frames into the firmware's [`Parser`].
//! - HANS-100: the capture is oversampled into the firmware's `u16` rings (an arbitrary
//!   sampling phase) and fed to [`hans::rx::HansRx`] in the chosen decode mode.
//!
//! The buffers come from [`capture`] (shared with `bridge`). The firmware's buffers
//! carry no time; the samplers keep a parallel vector of sample times from which each
//! record's `t_ns` (the frame start) is derived.

use std::collections::BTreeMap;
use std::fmt;

use shared::model::FaultKind;
use shared::xy3::back::{Event, Parser};
use shared::{hans, xy2};

use shared::model::Axis;
use shared::xy3;

use super::capture;
use super::jsonl::{BackRecord, Channel, ForwardRecord, HansRecord};
use super::SimError;
use crate::line::sample::SpiCapture;
use crate::line::uart::UartFrame;
use crate::vcd_io::NameMap;
use crate::wave::Ps;

/// What a decode run saw, for the summary on stderr.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Summary {
    /// Accepted frames or packets.
    pub accepted: usize,
    /// Error records by kind.
    pub errors: BTreeMap<String, usize>,
    /// Times the receiver regained sync after losing it (XY2-100 resyncs, XY3-100
    /// relocks; the backchannel parser counts its first sync too).
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

/// Frame start in ns from the first and last sample time of a frame (`bits` samples
/// apart): the first CLK falling edge minus half a bit, the bit time taken from the
/// frame's own samples (so a fast or slow sender clock is followed). With a single
/// sample, `fallback_bit` (ps) is used.
fn frame_start_ns(first: Ps, last: Ps, bits: u32, fallback_bit: Ps) -> u64 {
    let bit = if bits > 0 && last > first {
        (last - first) / u64::from(bits)
    } else {
        fallback_bit
    };
    ns(first.saturating_sub(bit / 2))
}

/// The kind of an XY2-100 channel error, for the summary.
fn xy2_kind(e: &xy2::rx::ChannelError) -> &'static str {
    match e {
        xy2::rx::ChannelError::Decode(xy2::DecodeError::Parity { .. }) => "parity",
        xy2::rx::ChannelError::Decode(xy2::DecodeError::ReservedHeader { .. }) => "reserved header",
        xy2::rx::ChannelError::Decode(xy2::DecodeError::TooWide { .. }) => "word too wide",
        xy2::rx::ChannelError::StuckHigh => "stuck high",
    }
}

fn xy2_channel(r: &Result<xy2::Frame, xy2::rx::ChannelError>, sum: &mut Summary) -> Channel {
    match *r {
        Ok(xy2::Frame::Position16(pos)) => Channel::Pos {
            pos: u32::from(pos),
            bits: 16,
        },
        Ok(xy2::Frame::Position18(pos)) => Channel::Pos { pos, bits: 18 },
        Ok(xy2::Frame::Command { command, parameter }) => Channel::Cmd {
            cmd: u32::from(command) << 8 | u32::from(parameter),
            frame_bits: None,
        },
        Err(e) => {
            sum.error(xy2_kind(&e));
            Channel::Error(e.to_string())
        }
    }
}

/// XY2-100: `clk sync x y` (+ `z`) -> port words -> [`xy2::rx::Receiver`] -> records.
///
/// One record per frame period the receiver reports: a channel per line with its
/// frame or its error. A SYNC pattern of the wrong length (framing fault) gives a
/// record with the fault as the error of every channel. `t_ns` is the frame's first
/// CLK falling edge minus half a bit (the sender's first rising edge). Accepted =
/// periods the bridge would take (every channel decoded, [`xy2::rx::Event::line_events`]).
pub fn xy2(
    path: &std::path::Path,
    map: &NameMap,
    config: &xy2::LinkConfig,
) -> Result<(Vec<ForwardRecord>, Summary), SimError> {
    let input = capture::xy2(path, map, capture::Lines::Present)?;
    let (words, times) = (&input.words, &input.times);
    let mut rx =
        xy2::rx::Receiver::new(input.rx_pins(), *config).map_err(|e| SimError::BadOption {
            option: "--map",
            message: e.to_string(),
        })?;
    let mut out = Vec::new();
    let mut sum = Summary::default();
    // The last bit time seen in a good frame (ps), for periods too short to measure.
    let mut bit: Ps = 500_000;
    let at = |i: usize| times.get(i).copied().unwrap_or(0);
    let mut progress = super::encode::Progress::new("decode", words.len());
    for (i, word) in words.iter().enumerate() {
        let mut events = Vec::new();
        rx.feed(std::slice::from_ref(word), &mut |e| events.push(e));
        for e in events {
            // The period's first sample: 19 high samples before this one (a frame), or
            // the start of the high run (a short SYNC), or 19 back (an overlong one).
            let (first, channels): (usize, Option<Vec<(&str, Channel)>>) = match &e {
                xy2::rx::Event::Frame(p) => {
                    let mut ch = vec![
                        ("x", xy2_channel(&p.x, &mut sum)),
                        ("y", xy2_channel(&p.y, &mut sum)),
                    ];
                    if let Some(z) = &p.z {
                        ch.push(("z", xy2_channel(z, &mut sum)));
                    }
                    let first = i.saturating_sub(19);
                    if i >= 19 {
                        bit = (at(i) - at(first)) / 19;
                    }
                    p.line_events(&mut |le| {
                        if matches!(le, shared::model::LineEvent::Frame(_)) {
                            sum.accepted += 1;
                        }
                    });
                    (first, Some(ch))
                }
                xy2::rx::Event::Framing(fault) => {
                    let (first, kind) = match fault {
                        xy2::rx::FramingFault::Short { high_bits } => (
                            i.saturating_sub(usize::from(*high_bits)),
                            "framing: SYNC too short",
                        ),
                        xy2::rx::FramingFault::Overlong => {
                            (i.saturating_sub(19), "framing: SYNC too long")
                        }
                    };
                    sum.error(kind);
                    let reason = format!("framing: {fault}");
                    let mut ch = vec![
                        ("x", Channel::Error(reason.clone())),
                        ("y", Channel::Error(reason.clone())),
                    ];
                    if input.pins.z.is_some() {
                        ch.push(("z", Channel::Error(reason)));
                    }
                    (first, Some(ch))
                }
                xy2::rx::Event::Resync => (i, None),
            };
            if let Some(ch) = channels {
                let mut rec = ForwardRecord {
                    t_ns: Some(frame_start_ns(at(first), at(i), (i - first) as u32, bit)),
                    ..ForwardRecord::default()
                };
                for (lane, c) in ch {
                    rec.set(lane, c);
                }
                out.push(rec);
            }
        }
        progress.tick(i + 1);
    }
    sum.resyncs = rx.counters().resyncs;
    Ok((out, sum))
}

fn xy3_kind(e: &xy3::rx::RxError) -> &'static str {
    use xy3::rx::RxError;
    match e {
        RxError::Framing { .. } => "framing: not 3 or 4 bytes",
        RxError::Check(xy3::DecodeError::Parity { .. }) => "parity",
        RxError::Check(xy3::DecodeError::SizeMismatch { .. }) => "size mismatch",
        RxError::Check(xy3::DecodeError::WordTooWide { .. }) => "word too wide",
        RxError::Dead => "dead line (all zeros)",
        RxError::Suspect => "withdrawn (suspected bit slip)",
        RxError::Unaligned => "hunting bit alignment",
        RxError::Remainder => "framing: remainder of a cut frame",
        RxError::Overrun => "overrun",
    }
}

fn xy3_channel(r: &Result<xy3::Frame, xy3::rx::RxError>, sum: &mut Summary) -> Channel {
    match *r {
        Ok(xy3::Frame::Position24(pos)) => Channel::Pos { pos, bits: 20 },
        Ok(xy3::Frame::Position32(pos)) => Channel::Pos { pos, bits: 26 },
        Ok(xy3::Frame::Command24(cmd)) => Channel::Cmd {
            cmd,
            frame_bits: None,
        },
        Ok(xy3::Frame::Command32 { code, .. }) => Channel::Cmd {
            cmd: code,
            frame_bits: Some(32),
        },
        Err(e) => {
            sum.error(xy3_kind(&e));
            Channel::Error(e.to_string())
        }
    }
}

/// SPI bytes pushed per call, within the receiver's contract (poll every
/// `WINDOW / 2` bytes).
const XY3_CHUNK: usize = xy3::rx::WINDOW / 2;

/// XY3-100: `clk sync` + the data lines present -> SPI bytes and frame ends ->
/// [`xy3::rx::Receiver`] -> records.
///
/// One record per frame period (SYNC rising edge), a channel per line present with its
/// frame or its error. `t_ns` is the period's first CLK falling edge minus half a bit
/// (the bit time from the first byte's samples); a period without bytes gets the time
/// of its SYNC rising edge. Accepted = periods in which every line decoded.
pub fn xy3(
    path: &std::path::Path,
    map: &NameMap,
) -> Result<(Vec<ForwardRecord>, Summary), SimError> {
    let input = capture::xy3(path, map, capture::Lines::Present)?;
    let present = &input.present;
    let cap: &SpiCapture = &input.spi;
    let lines = xy3::rx::Lines::new(&input.axes()).ok_or_else(|| SimError::BadOption {
        option: "--map",
        message: "XY3-100 needs the X line".to_owned(),
    })?;
    let mut rx = xy3::rx::Receiver::new(lines);
    let mut st = Xy3State {
        cap,
        present,
        out: Vec::new(),
        sum: Summary::default(),
        periods: 0,
        bit: 416_667,
    };
    let total = cap.bytes.first().map_or(0, Vec::len);
    let mut pushed = 0usize;
    let mut progress = super::encode::Progress::new("decode", cap.frame_ends.len());
    for (i, &end) in cap.frame_ends.iter().enumerate() {
        st.push_to(&mut rx, &mut pushed, (end as usize).min(total))?;
        rx.push_ends(&[end]);
        st.drain(&mut rx);
        progress.tick(i + 1);
    }
    st.push_to(&mut rx, &mut pushed, total)?;
    st.drain(&mut rx);
    let (out, mut sum) = (st.out, st.sum);
    sum.resyncs = rx.stats().relocks;
    Ok((out, sum))
}

/// The XY3-100 decode loop's state: the capture and what came out so far.
struct Xy3State<'a> {
    cap: &'a SpiCapture,
    /// Lines present: axis, role, JSON key.
    present: &'a [(Axis, &'a str, &'a str)],
    out: Vec<ForwardRecord>,
    sum: Summary,
    /// Periods polled so far (period k ends at `cap.frame_ends[k]`).
    periods: usize,
    /// The last measured bit time (ps).
    bit: Ps,
}

impl Xy3State<'_> {
    /// Pushes the bytes up to index `to` in contract-sized chunks, draining as it goes.
    fn push_to(
        &mut self,
        rx: &mut xy3::rx::Receiver,
        pushed: &mut usize,
        to: usize,
    ) -> Result<(), SimError> {
        while *pushed < to {
            let n = (to - *pushed).min(XY3_CHUNK);
            let from = *pushed;
            let slices: Vec<&[u8]> = self
                .cap
                .bytes
                .iter()
                .map(|l| l.get(from..from + n).unwrap_or(&[]))
                .collect();
            rx.push_bytes(&slices).map_err(|e| SimError::BadOption {
                option: "--input",
                message: e.to_string(),
            })?;
            *pushed += n;
            self.drain(rx);
        }
        Ok(())
    }

    /// Turns every period the receiver has ready into a record.
    fn drain(&mut self, rx: &mut xy3::rx::Receiver) {
        while let Some(p) = rx.poll() {
            let k = self.periods;
            self.periods += 1;
            let start = match k {
                0 => 0,
                _ => self.cap.frame_ends.get(k - 1).copied().unwrap_or(0) as usize,
            };
            let t_ns = match self.cap.byte_times.get(start) {
                Some(&(first, last)) if (p.end as usize) > start => {
                    if last > first {
                        self.bit = (last - first) / 7;
                    }
                    frame_start_ns(first, last, 7, self.bit)
                }
                _ => ns(self.cap.end_times.get(k).copied().unwrap_or(0)),
            };
            let mut rec = ForwardRecord {
                t_ns: Some(t_ns),
                ..ForwardRecord::default()
            };
            for (axis, _, key) in self.present {
                if let Some(Some(r)) = p.lines.get(axis.index()) {
                    rec.set(key, xy3_channel(r, &mut self.sum));
                }
            }
            let sum = &mut self.sum;
            p.for_each_event(|le| {
                if matches!(le, shared::model::LineEvent::Frame(_)) {
                    sum.accepted += 1;
                }
            });
            self.out.push(rec);
        }
    }
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
/// [`hans::rx::HansRx`] in `mode` -> records.
///
/// The rings go in one word per channel at a time, so every event is known to the
/// word (16 samples) in which its frame period closed; `t_ns` is that word's middle
/// minus one frame time. One record per period: the frame the mode published, or an
/// error naming the faults of a rejected period. Channel faults in a published period
/// (a minority channel that failed or disagreed) and losses of alignment are counted
/// in the summary only.
pub fn hans(
    path: &std::path::Path,
    map: &NameMap,
    mode: HansMode,
    oversample: u8,
    seed: u64,
) -> Result<(Vec<HansRecord>, Summary), SimError> {
    // Normal mode needs its one channel only; the others need all five.
    let channels: Vec<u8> = match mode {
        HansMode::Normal(n) => vec![n],
        _ => (1..=5).collect(),
    };
    let input = capture::hans(path, map, &channels, 12.5e6 * f64::from(oversample), seed)?;
    let (start_ps, capture_end_ps) = (input.start_ps, input.capture_end_ps);
    let rx_mode = match mode {
        HansMode::Normal(channel) => hans::rx::Mode::Normal { channel },
        HansMode::Vote3 => hans::rx::Mode::Vote3 {
            channels: [1, 2, 3],
        },
        HansMode::Vote5 => hans::rx::Mode::Vote5,
        HansMode::Super => hans::rx::Mode::Super,
    };
    let mut rx =
        hans::rx::HansRx::new(12_500_000 * u32::from(oversample), rx_mode).map_err(|e| {
            SimError::BadOption {
                option: "--hans-mode",
                message: e.to_string(),
            }
        })?;
    let words = input.words();
    let word_ps = input.word_ps();
    let frame_ps = hans::FRAME_BITS as f64 * 1e12 / f64::from(hans::rx::BIT_RATE_HZ);
    let mut out = Vec::new();
    let mut sum = Summary::default();
    let mut progress = super::encode::Progress::new("decode", words);
    let mut last_frame_ns: Option<u64> = None;
    for i in 0..words {
        let chunks = input.chunks(i);
        let mut events = Vec::new();
        rx.push(&chunks, &mut |e| events.push(e));
        if events.is_empty() {
            continue;
        }
        // The period closed in this word: the frame ended in it (or up to two words
        // before, when a channel was missing), so it started one frame before; taking
        // the word's middle keeps the error within about half a word (0.2-0.3 us).
        let end_ps = start_ps + (i as f64 + 0.5) * word_ps;
        let t_ns = Some(((end_ps - frame_ps) / 1000.0).round().max(0.0) as u64);
        if let Some(rec) = hans_record(&events, t_ns, &mut sum) {
            silence(&mut out, &mut sum, last_frame_ns, t_ns, frame_ps);
            if matches!(rec, HansRecord::Frame { .. }) {
                last_frame_ns = t_ns;
            }
            out.push(rec);
        }
        progress.tick(i + 1);
    }
    let capture_end = ((capture_end_ps as f64 - frame_ps) / 1000.0).max(0.0) as u64;
    silence(
        &mut out,
        &mut sum,
        last_frame_ns,
        Some(capture_end),
        frame_ps,
    );
    sum.resyncs = (1..=5).filter_map(|c| rx.stats(c)).map(|s| s.resyncs).sum();
    Ok((out, sum))
}

/// A HANS-100 line never pauses, so a stretch without any record after a frame means
/// the used channels went silent (stuck, open, out of sync): the receiver reports
/// nothing for it, so the tool adds one error record at the first missing frame and
/// counts the missing frames. Acquisition before the first frame is not a gap.
fn silence(
    out: &mut Vec<HansRecord>,
    sum: &mut Summary,
    last_frame_ns: Option<u64>,
    now_ns: Option<u64>,
    frame_ps: f64,
) {
    let (Some(last), Some(now)) = (last_frame_ns, now_ns) else {
        return;
    };
    let frame_ns = frame_ps / 1000.0;
    // Since the last frame: the last record's time (errors are not silence).
    let from = match out.last() {
        Some(HansRecord::Error { t_ns: Some(t), .. }) => (*t).max(last),
        _ => last,
    };
    let missing = ((now.saturating_sub(from)) as f64 / frame_ns - 0.5).floor() as u64;
    if missing >= 1 {
        *sum.errors
            .entry("no frame (lines silent)".to_owned())
            .or_default() += missing as usize;
        out.push(HansRecord::Error {
            t_ns: Some(from + frame_ns.round() as u64),
            error: format!("no frame for {missing} frame times (lines silent or out of sync)"),
        });
    }
}

/// A HANS-100 fault kind in words.
fn hans_fault(kind: FaultKind) -> &'static str {
    match kind {
        FaultKind::CheckFailed => "frame check failed",
        FaultKind::Resync => "lost alignment",
        FaultKind::Disagree => "verified channels disagree",
        FaultKind::Missing => "missing (no pattern this period)",
        FaultKind::Dropped => "input dropped",
        FaultKind::Framing => "framing",
    }
}

/// The record of one closed frame period from its receiver events: the frame if the
/// mode published one; else an error naming the faults if the period was rejected
/// (a channel or the vote failed its checks, channels disagreed); `None` for events
/// that are not about a frame (a channel losing alignment, or missing from the
/// period). Every fault is counted.
fn hans_record(
    events: &[hans::rx::RxEvent],
    t_ns: Option<u64>,
    sum: &mut Summary,
) -> Option<HansRecord> {
    let mut frame = None;
    let mut rejected: Vec<String> = Vec::new();
    for e in events {
        match *e {
            hans::rx::RxEvent::Frame(f) => frame = Some(f),
            hans::rx::RxEvent::Fault { channel, kind } => {
                let what = match channel {
                    Some(c) => format!("ch{c}: {}", hans_fault(kind)),
                    None => format!("period: {}", hans_fault(kind)),
                };
                sum.error(&what);
                // A channel missing from a period is no rejected frame: the frame
                // came from the other channels, or the gap shows as silence.
                if !matches!(kind, FaultKind::Resync | FaultKind::Missing) {
                    rejected.push(what);
                }
            }
        }
    }
    match frame {
        Some(f) => {
            sum.accepted += 1;
            Some(HansRecord::Frame {
                t_ns,
                data: f.words(),
            })
        }
        None if !rejected.is_empty() => Some(HansRecord::Error {
            t_ns,
            error: rejected.join("; "),
        }),
        None => None,
    }
}

/// Backchannel: UART frames of the `back` line ([`capture::uart_line`]) ->
/// [`Parser`] -> records.
///
/// Records: every packet the parser delivers, plus the SYNC packet behind each resync
/// (the parser reports that one as a resync event, the format lists it as a packet);
/// errors for lost sync, for a resync that dropped bytes, and for UART framing errors
/// (the byte is still passed on, as the UART's data register would).
pub fn back(frames: Vec<UartFrame>) -> (Vec<BackRecord>, Summary) {
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
    (out, sum)
}
