//! XY3-100 line receiver (sans-IO): SPI-slave byte rings plus frame end positions in,
//! one [`Period`] per frame period out (layouts item 2, XY3-100 §5.1).
//!
//! # What the firmware delivers
//! One SPI slave per configured data line (SCK = CLK, NSS = SYNC, MOSI = the line,
//! 8-bit, MSB first) writes into its own ring; all rings start together, so byte `i`
//! of every line was shifted in by the same clock edges. At each SYNC rising edge an
//! interrupt records the X ring's total byte count (a wrapping `u32`): the *end
//! position* of the frame that just finished. The bytes between two consecutive end
//! positions are one frame period's bytes: a frame is 24 or 32 bits (§5.1, first bit
//! 0 or 1), so there must be 3 or 4 of them, and [`crate::xy3::decode`] then checks
//! the first bit against that size and the parity.
//!
//! # Contract
//! - Feed bytes with [`Receiver::push_bytes`] (the configured lines in axis order,
//!   equal lengths, any chunking) and end positions with [`Receiver::push_ends`] (in
//!   order, any chunking, before or after the bytes they refer to). Then drain
//!   [`Receiver::poll`] until it returns `None`. The result does not depend on the
//!   chunking or on how the two feeds interleave.
//! - The receiver keeps the last [`WINDOW`] bytes of each line. Poll at least every
//!   `WINDOW / 2` bytes (a DMA half of up to 64 bytes per line is fine). Bytes
//!   overwritten before their end position arrived are reported as
//!   [`RxError::Overrun`], never guessed.
//! - Up to [`MAX_PENDING_ENDS`] end positions may wait for their bytes; more are
//!   dropped and counted (the frames around them then fail the framing check).
//! - The byte count of the first end position is relative to the same origin as the
//!   bytes: start the count at 0 with the first byte pushed (or use
//!   [`Receiver::with_origin`]).
//!
//! # Framing errors and realignment
//! A period with other than 3 or 4 bytes (truncated by a SYNC glitch, extended by
//! extra clock edges, or two frames merged because a SYNC edge was missed) is a
//! framing error on every line; the next period starts at its end position, so the
//! receiver realigns by itself at the next SYNC rising edge. One exception: a period
//! right after one with fewer than 3 bytes is withdrawn too ([`RxError::Remainder`]).
//! A SYNC glitch that cuts a frame in two yields a short period and then the rest of
//! the frame, and the rest of a 32-bit frame cut in its first byte is 3 bytes long:
//! decoded as a 24-bit frame it would pass the checks one time in eight. (The first
//! part of a cut frame needs no such care: 3 bytes of a 32-bit frame start with a 1
//! and fail the size check.) The price is one more lost period after a real
//! truncation or a SYNC glitch between frames.
//!
//! # Partial bytes and bit slips
//! What the H7 SPI slave does with an incomplete byte at NSS release is not
//! documented: RM0433 (§50.4, slave select (SS) pin management) treats the slave's
//! SS as a chip select only, and no slave setting (data size, FIFO threshold,
//! transfer size; SSOM / MIDI act on a master's SS output) defines what becomes of
//! a data frame that SS cuts short. The receiver copes with both kinds; with
//! `controller.xy3.select = "always"` the slaves run without SS (software select
//! held active) and always behave as the keeping kind.
//!
//! If the slave drops the bits, every frame starts on a byte boundary. If it keeps
//! them, a frame with a bit count that is not a multiple of 8 (a glitch clock edge,
//! a truncated frame) leaves `k` bits in the shift register and shifts *every later
//! byte* by `k` bits, while the byte counts per period stay 3 or 4: the counts cannot reveal the
//! slip, only the content can. The receiver therefore tracks a *bit offset* `k`
//! (0..=7) common to all lines: frame `i` is the last `8n - k` bits of its own bytes
//! followed by the first `k` bits of the next byte (which the shift register carried
//! over).
//! - Locked at `k`, each period is decoded at `k`. A period in which two or more lines
//!   (or the only line) fail the frame check is taken as a suspected slip: the lines
//!   that passed are withdrawn ([`RxError::Suspect`]) and the receiver hunts.
//! - Hunting, each period is decoded at all eight offsets; the receiver locks again
//!   when the same single offset decodes every line in [`LOCK_PERIODS`] consecutive
//!   periods, and delivers the period that completed the lock. Until then every
//!   period is [`RxError::Unaligned`]. With the drop-bits behaviour this always finds
//!   offset 0 again, so the receiver never needs the SPI reset. Without SS (select
//!   `"always"`) a session that starts inside a frame starts at another offset,
//!   which the hunt finds the same way.
//! - Residual risk, inherent to a byte-level receiver: a slip whose first shifted
//!   period happens to pass every line's check (for random data about `(1/8)^c` for
//!   24-bit and `(1/32)^c` for 32-bit frames with `c` lines) is delivered before the
//!   next period reveals the slip; and an extra clock edge inside a frame that keeps
//!   its byte count is caught only by the parity (like a burst error, §5.1 parity
//!   limits in the parent module). Counting CLK edges in hardware would close both.
//!
//! # Dead lines
//! A line stuck low (or open, reading the receiver's fail-safe low) delivers zero
//! bytes, and an all-zero 24-bit word is a valid command frame with code 0. The
//! receiver rejects all-zero words ([`RxError::Dead`]) so that a dead line shows as
//! a fault instead of a stream of meaningless commands without a position. A stuck
//! high line fails the checks by itself (24-bit: first bit 1; 32-bit: 26 ones give
//! parity 10, not 15).
//!
//! # Latency
//! Locked at offset 0 (always the case when the SPI drops partial bytes), a period is
//! delivered as soon as its end position and its bytes are in. Locked at another
//! offset or hunting, it also needs the first byte of the next period (which holds
//! its last bits), so it comes about a byte time later; a period followed by a pause
//! waits for the next frame.
//!
//! # Bounded work
//! [`Receiver::poll`] handles one period per call: decoding `c` lines once (locked)
//! or eight times (hunting). Nothing panics and nothing allocates.

use core::fmt;

use heapless::Deque;

use super::frame::{decode, DecodeError, Frame, FrameSize};
use crate::model::{Axis, FaultKind, ForwardFrame, Line, LineEvent};

/// Bytes kept per line (a power of two).
pub const WINDOW: usize = 128;
/// End positions that may wait for their bytes.
pub const MAX_PENDING_ENDS: usize = 32;
/// Consecutive periods that must agree on one bit offset before the receiver locks.
pub const LOCK_PERIODS: u8 = 2;

/// The set of configured data lines (X must be one of them: commands come on X,
/// §5.1.1, and the end positions count X's bytes).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Lines(u8);

impl Lines {
    /// X and Y, the lines every XY3-100 link has (§3.1.1).
    pub const XY: Lines = Lines(0b00011);
    /// X, Y and Z.
    pub const XYZ: Lines = Lines(0b00111);
    /// All five lines.
    pub const ALL: Lines = Lines(0b11111);

    /// A set from the axes present; `None` if X is missing.
    pub fn new(axes: &[Axis]) -> Option<Lines> {
        let bits = axes.iter().fold(0u8, |b, a| b | 1 << a.index());
        (bits & 1 != 0).then_some(Lines(bits))
    }

    /// Whether `axis`'s line is configured.
    pub const fn has(self, axis: Axis) -> bool {
        self.0 & 1 << axis as u8 != 0
    }

    /// The set as a mask, bit [`Axis::index`] per line.
    pub(crate) const fn bits(self) -> u8 {
        self.0
    }

    /// Number of configured lines.
    pub const fn count(self) -> usize {
        self.0.count_ones() as usize
    }

    /// The configured axes in order X..W.
    pub fn axes(self) -> impl Iterator<Item = Axis> {
        Axis::ALL.into_iter().filter(move |a| self.has(*a))
    }

    /// The set without `axis`'s line. X stays: a set without X is not a valid set
    /// (see the type's docs), so `without(Axis::X)` is the set unchanged.
    pub const fn without(self, axis: Axis) -> Lines {
        match axis {
            Axis::X => self,
            _ => Lines(self.0 & !(1 << axis as u8)),
        }
    }
}

/// Why a line has no frame in a period. Every variant means: do not use this line's
/// data for this period.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RxError {
    /// The period held this many bytes instead of 3 or 4 (all lines share it).
    Framing {
        /// Bytes between the two end positions.
        bytes: u32,
    },
    /// The frame failed its check.
    Check(DecodeError),
    /// The line read all zeros: stuck low or open. That word is a well-formed
    /// 24-bit command frame (code 0, which §5.1.1 does not define), so `decode`
    /// accepts it; the receiver does not.
    Dead,
    /// The line passed its check, but enough other lines failed in the same period to
    /// suspect a bit slip, so it is withdrawn too.
    Suspect,
    /// The receiver is hunting for the bit offset after a suspected slip.
    Unaligned,
    /// The period follows one with fewer than 3 bytes, so it may be the rest of a
    /// frame that a SYNC glitch cut in two, not a frame of its own.
    Remainder,
    /// The period's bytes were overwritten before their end position arrived.
    Overrun,
}

impl fmt::Display for RxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Framing { bytes } => write!(f, "{bytes} bytes in a frame period, not 3 or 4"),
            Self::Check(e) => write!(f, "frame check failed: {e}"),
            Self::Dead => f.write_str("line reads all zeros (stuck low or open)"),
            Self::Suspect => f.write_str("withdrawn: other lines suggest a bit slip"),
            Self::Unaligned => f.write_str("hunting for the bit alignment"),
            Self::Remainder => f.write_str("may be the rest of a frame cut by a SYNC glitch"),
            Self::Overrun => f.write_str("bytes overwritten before decoding"),
        }
    }
}

/// Why [`Receiver::push_bytes`] refused its input (nothing was taken).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PushError {
    /// Not one slice per configured line.
    LineCount {
        /// Slices given.
        given: usize,
        /// Lines configured.
        configured: usize,
    },
    /// The slices have different lengths.
    UnequalLengths,
}

impl fmt::Display for PushError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LineCount { given, configured } => {
                write!(f, "{given} byte slices for {configured} configured lines")
            }
            Self::UnequalLengths => f.write_str("byte slices of different lengths"),
        }
    }
}

/// One frame period: a result per configured line (indexed by [`Axis::index`];
/// `None` for lines not configured).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Period {
    /// Per-axis result.
    pub lines: [Option<Result<Frame, RxError>>; 5],
    /// The end position that closed the period.
    pub end: u32,
}

impl Period {
    /// Whether every configured line decoded.
    pub fn all_ok(&self) -> bool {
        self.lines.iter().flatten().all(Result::is_ok)
    }

    /// The neutral events of this period, handed to `emit`: one
    /// [`LineEvent::Frame`] if every configured line decoded (positions per axis, the
    /// command from X, §5.1.1; a command on another line is ignored), otherwise one
    /// fault per failed line and no frame.
    ///
    /// A command frame on X leaves `axes[X]` empty for that period: the controller
    /// sent no X position, so the bridge should hold the last X position (a head does
    /// the same while it executes a command), not treat X as lost.
    pub fn for_each_event(&self, mut emit: impl FnMut(LineEvent)) {
        let mut frame = ForwardFrame::default();
        let mut ok = true;
        for (axis, result) in Axis::ALL.iter().zip(self.lines.iter()) {
            let kind = match result {
                None => continue,
                // Decoded frames always convert; the error arm cannot happen.
                Some(Ok(f)) => match super::neutral::apply(f, *axis, &mut frame) {
                    Ok(_) => continue,
                    Err(_) => FaultKind::CheckFailed,
                },
                Some(Err(RxError::Check(_) | RxError::Dead | RxError::Suspect)) => {
                    FaultKind::CheckFailed
                }
                Some(Err(RxError::Framing { .. } | RxError::Remainder)) => FaultKind::Framing,
                Some(Err(RxError::Unaligned)) => FaultKind::Resync,
                Some(Err(RxError::Overrun)) => FaultKind::Dropped,
            };
            ok = false;
            emit(LineEvent::Fault {
                line: Line::Axis(*axis),
                kind,
            });
        }
        if ok {
            emit(LineEvent::Frame(frame));
        }
    }

    /// [`Period::for_each_event`] collected (at most five events).
    pub fn line_events(&self) -> heapless::Vec<LineEvent, 5> {
        let mut out = heapless::Vec::new();
        // At most one event per line or one frame: five always fit.
        self.for_each_event(|e| {
            let _ = out.push(e);
        });
        out
    }
}

/// Running totals.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RxStats {
    /// Periods reported.
    pub periods: u32,
    /// Periods in which every line decoded.
    pub good: u32,
    /// Frame check failures per axis.
    pub check_failed: [u32; 5],
    /// Periods with a framing error, or withdrawn as a possible remainder.
    pub framing: u32,
    /// Periods lost to overwritten bytes.
    pub overrun: u32,
    /// Suspected bit slips (hunts started).
    pub slips: u32,
    /// Periods spent hunting.
    pub unaligned: u32,
    /// Locks found after a hunt.
    pub relocks: u32,
    /// End positions dropped: queue full, or earlier than the previous one.
    pub bad_ends: u32,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Align {
    Locked(u8),
    Hunting { candidate: u8, streak: u8 },
}

/// The XY3-100 line receiver. See the module docs for the contract.
///
/// No `defmt::Format`: heapless' `Deque` does not implement it, and the state is
/// 700 bytes of rings; log [`Receiver::stats`] instead.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Receiver {
    lines: Lines,
    rings: [[u8; WINDOW]; 5],
    /// Total bytes pushed per line (wrapping), in the end positions' count.
    pushed: u32,
    /// Start of the current period (the previous end position).
    start: u32,
    ends: Deque<u32, MAX_PENDING_ENDS>,
    align: Align,
    /// The previous period had fewer than 3 bytes.
    after_short: bool,
    stats: RxStats,
}

/// Half the `u32` range: differences above it mean "earlier" for wrapping counts.
const HALF: u32 = 1 << 31;

impl Receiver {
    /// A receiver for `lines`, counting bytes from 0.
    pub const fn new(lines: Lines) -> Self {
        Self::with_origin(lines, 0)
    }

    /// A receiver whose first pushed byte has byte count `origin` (e.g. the DMA
    /// counter value when decoding starts).
    pub const fn with_origin(lines: Lines, origin: u32) -> Self {
        Receiver {
            lines,
            rings: [[0; WINDOW]; 5],
            pushed: origin,
            start: origin,
            ends: Deque::new(),
            align: Align::Locked(0),
            after_short: false,
            stats: RxStats {
                periods: 0,
                good: 0,
                check_failed: [0; 5],
                framing: 0,
                overrun: 0,
                slips: 0,
                unaligned: 0,
                relocks: 0,
                bad_ends: 0,
            },
        }
    }

    /// The running totals.
    pub fn stats(&self) -> RxStats {
        self.stats
    }

    /// The bit offset the receiver is locked at, `None` while hunting.
    pub fn offset(&self) -> Option<u8> {
        match self.align {
            Align::Locked(k) => Some(k),
            Align::Hunting { .. } => None,
        }
    }

    /// Appends bytes: one slice per configured line, in axis order, equal lengths.
    pub fn push_bytes(&mut self, lines: &[&[u8]]) -> Result<(), PushError> {
        let configured = self.lines.count();
        if lines.len() != configured {
            return Err(PushError::LineCount {
                given: lines.len(),
                configured,
            });
        }
        let len = lines.first().map_or(0, |l| l.len());
        if lines.iter().any(|l| l.len() != len) {
            return Err(PushError::UnequalLengths);
        }
        let mut src = lines.iter();
        for axis in Axis::ALL {
            if !self.lines.has(axis) {
                continue;
            }
            let (Some(ring), Some(bytes)) = (self.rings.get_mut(axis.index()), src.next()) else {
                continue;
            };
            // Only the last WINDOW bytes can still be decoded.
            let skip = bytes.len().saturating_sub(WINDOW);
            let tail = bytes.get(skip..).unwrap_or_default();
            let at = self.pushed.wrapping_add(skip as u32) as usize % WINDOW;
            // At most WINDOW bytes: up to the ring's end, then the rest from its start
            // (two block copies rather than a modulo per byte).
            let (upto_end, wrapped) = tail.split_at(tail.len().min(WINDOW - at));
            if let Some(dst) = ring.get_mut(at..at + upto_end.len()) {
                dst.copy_from_slice(upto_end);
            }
            if let Some(dst) = ring.get_mut(..wrapped.len()) {
                dst.copy_from_slice(wrapped);
            }
        }
        self.pushed = self.pushed.wrapping_add(len as u32);
        Ok(())
    }

    /// Appends end positions (byte counts at SYNC rising edges, in order).
    pub fn push_ends(&mut self, ends: &[u32]) {
        for &e in ends {
            let last = self.ends.back().copied().unwrap_or(self.start);
            if e.wrapping_sub(last) >= HALF || self.ends.push_back(e).is_err() {
                self.stats.bad_ends = self.stats.bad_ends.saturating_add(1);
            }
        }
    }

    /// The wire word of `axis` for the period `[start, start + n)` at bit offset `k`
    /// (`n` is 3 or 4; the caller checked that the bytes are in the window).
    fn word(&self, axis: usize, n: u32, k: u8) -> u32 {
        let Some(ring) = self.rings.get(axis) else {
            return 0;
        };
        let at = |i: u32| {
            let pos = self.start.wrapping_add(i) as usize % WINDOW;
            ring.get(pos).copied().unwrap_or(0)
        };
        // The period's first four bytes; a 24-bit word at offset k lies inside them.
        let head = u32::from_be_bytes([at(0), at(1), at(2), at(3)]);
        let k = u32::from(k & 7);
        if n == 4 {
            // Bit k of the first byte is the word's first bit; the last k bits come
            // from the top of the fifth byte.
            head << k | u32::from(at(4)) >> (8 - k)
        } else {
            head << k >> 8
        }
    }

    /// Decodes every configured line at offset `k`.
    fn decode_at(&self, n: u32, size: FrameSize, k: u8) -> [Option<Result<Frame, RxError>>; 5] {
        let mut out = [None; 5];
        for (i, slot) in out.iter_mut().enumerate() {
            if self.lines.0 & 1 << i != 0 {
                *slot = Some(match self.word(i, n, k) {
                    0 => Err(RxError::Dead),
                    w => decode(w, size).map_err(RxError::Check),
                });
            }
        }
        out
    }

    /// Decodes the next complete period, if its end position and bytes are there.
    pub fn poll(&mut self) -> Option<Period> {
        let &end = self.ends.front()?;
        let n = end.wrapping_sub(self.start);
        let size = match n {
            3 => Some(FrameSize::Bits24),
            4 => Some(FrameSize::Bits32),
            _ => None,
        };
        // Wait for the bytes (and the carried-bits byte unless locked at offset 0).
        let need_next = u32::from(size.is_some() && self.align != Align::Locked(0));
        let have = self.pushed.wrapping_sub(end);
        if size.is_some() && (have >= HALF || have < need_next) {
            return None;
        }
        self.ends.pop_front();
        let after_short = core::mem::replace(&mut self.after_short, n < 3);
        let lines = match size {
            None => self.framing(Err(RxError::Framing { bytes: n })),
            Some(_) if after_short => self.framing(Err(RxError::Remainder)),
            Some(_) if self.pushed.wrapping_sub(self.start) as usize > WINDOW => {
                self.stats.overrun = self.stats.overrun.saturating_add(1);
                self.fill(Err(RxError::Overrun))
            }
            Some(size) => match self.align {
                Align::Locked(k) => self.locked(n, size, k),
                Align::Hunting { candidate, streak } => self.hunt(n, size, candidate, streak),
            },
        };
        self.start = end;
        self.stats.periods = self.stats.periods.saturating_add(1);
        let period = Period { lines, end };
        if period.all_ok() {
            self.stats.good = self.stats.good.saturating_add(1);
        }
        Some(period)
    }

    fn fill(&self, r: Result<Frame, RxError>) -> [Option<Result<Frame, RxError>>; 5] {
        let mut out = [None; 5];
        for (i, slot) in out.iter_mut().enumerate() {
            if self.lines.0 & 1 << i != 0 {
                *slot = Some(r);
            }
        }
        out
    }

    fn framing(&mut self, error: Result<Frame, RxError>) -> [Option<Result<Frame, RxError>>; 5] {
        self.stats.framing = self.stats.framing.saturating_add(1);
        if let Align::Hunting { candidate, .. } = self.align {
            // Agreement must come from consecutive periods.
            self.align = Align::Hunting {
                candidate,
                streak: 0,
            };
        }
        self.fill(error)
    }

    fn locked(&mut self, n: u32, size: FrameSize, k: u8) -> [Option<Result<Frame, RxError>>; 5] {
        let mut lines = self.decode_at(n, size, k);
        let mut failed = 0;
        for (i, r) in lines.iter().enumerate() {
            if let Some(Err(_)) = r {
                failed += 1;
                if let Some(c) = self.stats.check_failed.get_mut(i) {
                    *c = c.saturating_add(1);
                }
            }
        }
        if failed >= 2 || (failed >= 1 && failed == self.lines.count()) {
            self.stats.slips = self.stats.slips.saturating_add(1);
            self.align = Align::Hunting {
                candidate: k,
                streak: 0,
            };
            for r in lines.iter_mut().flatten() {
                if r.is_ok() {
                    *r = Err(RxError::Suspect);
                }
            }
        }
        lines
    }

    fn hunt(
        &mut self,
        n: u32,
        size: FrameSize,
        candidate: u8,
        streak: u8,
    ) -> [Option<Result<Frame, RxError>>; 5] {
        let mut found = None;
        let mut matches = 0;
        for k in 0..8 {
            if self
                .decode_at(n, size, k)
                .iter()
                .flatten()
                .all(Result::is_ok)
            {
                matches += 1;
                found = Some(k);
            }
        }
        let (candidate, streak) = match found {
            Some(k) if matches == 1 && k == candidate => (k, streak.saturating_add(1)),
            Some(k) if matches == 1 => (k, 1),
            _ => (candidate, 0),
        };
        if streak >= LOCK_PERIODS {
            self.align = Align::Locked(candidate);
            self.stats.relocks = self.stats.relocks.saturating_add(1);
            return self.decode_at(n, size, candidate);
        }
        self.align = Align::Hunting { candidate, streak };
        self.stats.unaligned = self.stats.unaligned.saturating_add(1);
        self.fill(Err(RxError::Unaligned))
    }
}
