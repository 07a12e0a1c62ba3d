//! The XY2-100 line receiver: GPIO port samples (DMA layout item 1) -> frame periods.
//!
//! # Input
//! A timer counts the falling edges of CLK and every edge copies the input port (`u16`)
//! into a ring, so the receiver sees **one sample per bit** and nothing between edges.
//! Which port bit carries SYNC, X, Y (and Z) is a runtime [`PinMap`]. The firmware hands
//! the ring over half by half; [`Receiver::feed`] keeps its state between calls, so any
//! chunking of the same samples gives the same events.
//!
//! Because the samples carry no time, the receiver never needs to know the bit rate:
//! a 0.5 MHz, 2 MHz (XY2-100) or 4 MHz (XY2-200) clock, a clock that pauses between
//! frames (gated) or mid-frame while every line holds still, all look the same — the
//! same samples in the same order. No configuration of the clock rate exists.
//!
//! # Framing (notes, "Timing")
//! SYNC is high during bits 1..19 of a frame and low during bit 20 (parity); data
//! changes on the rising edge and is sampled on the falling one. So a frame is, in the
//! samples, a SYNC **rising edge** (low -> high), exactly 19 high samples, and one low
//! sample; that low sample ends the frame and holds bit 0 of every data word. Further
//! low samples (a clock that keeps running between frames) are idle and ignored.
//!
//! Every data line is shifted into a 32-bit register on every sample (three shifts and
//! ORs); only at the end of a frame are the last 20 bits decoded. The SYNC bit drives a
//! counter of consecutive high samples that saturates, so per sample the work is a
//! handful of bit operations and one well-predicted branch, and never grows.
//!
//! # Robustness (our decisions)
//! - A high run of SYNC that is not exactly 19 samples long is a framing fault: too
//!   short (a SYNC glitch, missing clock edges) is reported at the falling edge, too
//!   long (extra clock edges, SYNC stuck high) as soon as the 20th high sample arrives.
//!   Nothing of that frame period is decoded. The receiver then counts itself lost and
//!   resynchronises on the next SYNC rising edge: the next well-formed frame is
//!   preceded by [`Event::Resync`].
//! - At start-up the receiver has not seen a rising edge, so a partial first frame is
//!   dropped silently (joining a running line is not a fault).
//! - Each channel's word goes through [`decode`] with the link's [`LinkConfig`]; in
//!   addition an **all-ones** word is rejected as [`ChannelError::StuckHigh`]: an open
//!   RS-422 input reads its fail-safe level (high) on every sample, and all-ones is a
//!   valid frame in two link settings (command 0xFF/0xFF under whole-frame parity,
//!   18-bit full scale under data-only parity). A broken X line must not become a
//!   stream of valid frames; the cost is that those two words cannot be received.
//!   All-zeros always fails the header check.
//! - What no SYNC-count + parity scheme can catch: two faults in one frame period that
//!   cancel in the SYNC count (e.g. one missing and one extra clock edge, or CLK alone
//!   stopping mid-frame and restarting exactly the same bit position later while SYNC
//!   and data keep running) leave a misaligned word that parity rejects only half the
//!   time. The receiver detects every *single* fault per frame period: one glitch or
//!   dropout on SYNC or CLK (any number of extra CLK edges), one flipped bit per data
//!   line, a stuck line.
//!
//! # Output
//! Events go to a caller sink: [`Event::Frame`] per completed frame period with one
//! `Result` per channel, [`Event::Framing`] and [`Event::Resync`]. [`Event::line_events`]
//! converts them to the bridge's neutral [`LineEvent`]s: a frame period becomes
//! [`LineEvent::Frame`] only if every configured channel decoded, otherwise one
//! [`FaultKind::CheckFailed`] per failed channel and no frame. An enhanced command on X
//! becomes [`ForwardFrame::command`]; commands on Y or Z have no slot in the neutral
//! frame and are dropped (that axis then has no position in this period).

use core::fmt;

use super::frame::{decode, DecodeError, Frame, LinkConfig, FRAME_MASK};
use super::neutral::AxisItem;
use crate::model::{Axis, FaultKind, ForwardFrame, Line, LineEvent};

/// High SYNC samples in a well-formed frame (bits 1..19).
const SYNC_HIGH: u32 = 19;
/// Where the high-run counter saturates. It means "overlong, already reported" or "no
/// rising edge seen yet": either way the run's falling edge reports nothing. Starting
/// here makes a partial first frame silent; saturating keeps a stuck SYNC from ever
/// wrapping the counter back to 19.
const RUN_SATURATED: u32 = SYNC_HIGH + 2;

/// Width of a GPIO port in bits.
pub(super) const PORT_BITS: u8 = 16;

/// Which input port bit carries which XY2-100 signal (bit indices 0..15).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PinMap {
    /// SYNC.
    pub sync: u8,
    /// X data.
    pub x: u8,
    /// Y data.
    pub y: u8,
    /// Z data, if the link has a Z channel.
    pub z: Option<u8>,
}

/// Why a pin map is unusable.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PinError {
    /// A bit index is not below 16.
    OutOfRange {
        /// The offending index.
        bit: u8,
    },
    /// Two signals share a bit.
    Reused {
        /// The shared index.
        bit: u8,
    },
}

impl fmt::Display for PinError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OutOfRange { bit } => write!(f, "pin bit {bit} is outside the 16-bit port"),
            Self::Reused { bit } => write!(f, "pin bit {bit} is mapped to two signals"),
        }
    }
}

/// Checks that the present bit indices are below 16 and distinct.
pub(super) fn check_pins(bits: &[Option<u8>]) -> Result<(), PinError> {
    let mut seen: u32 = 0;
    for &bit in bits.iter().flatten() {
        if bit >= PORT_BITS {
            return Err(PinError::OutOfRange { bit });
        }
        if seen & 1 << bit != 0 {
            return Err(PinError::Reused { bit });
        }
        seen |= 1 << bit;
    }
    Ok(())
}

/// Why one channel's word of a frame period was not accepted.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChannelError {
    /// The word failed the codec's checks.
    Decode(DecodeError),
    /// All 20 bits were 1: indistinguishable from an open (fail-safe high) line.
    StuckHigh,
}

impl fmt::Display for ChannelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Decode(e) => write!(f, "{e}"),
            Self::StuckHigh => f.write_str("all 20 bits high: line open or stuck high"),
        }
    }
}

/// What the channels carried in one well-framed period.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FramePeriod {
    /// X channel.
    pub x: Result<Frame, ChannelError>,
    /// Y channel.
    pub y: Result<Frame, ChannelError>,
    /// Z channel, `None` if the pin map has none.
    pub z: Option<Result<Frame, ChannelError>>,
}

/// How the SYNC pattern was wrong.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FramingFault {
    /// SYNC fell after fewer than 19 high samples.
    Short {
        /// How many high samples there were (1..=18).
        high_bits: u8,
    },
    /// SYNC stayed high for a 20th sample.
    Overlong,
}

impl fmt::Display for FramingFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Short { high_bits } => write!(f, "SYNC high for {high_bits} bits, not 19"),
            Self::Overlong => f.write_str("SYNC high for more than 19 bits"),
        }
    }
}

/// What the receiver reports.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// A frame period with a correct SYNC pattern, one result per channel.
    Frame(FramePeriod),
    /// A SYNC pattern of the wrong length; that period is dropped and the receiver is lost.
    Framing(FramingFault),
    /// The first correct SYNC pattern after a framing fault (sent before its frame).
    Resync,
}

/// Running totals (wrapping).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Frame periods with a correct SYNC pattern.
    pub frames: u32,
    /// Rejected words per channel, X, Y, Z.
    pub check_failures: [u32; 3],
    /// Framing faults.
    pub framing: u32,
    /// Resynchronisations after a framing fault.
    pub resyncs: u32,
}

/// The receiver state machine (see the module docs).
#[derive(Clone, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Receiver {
    link: LinkConfig,
    /// Shift amounts of SYNC, X, Y, Z in the port word (all below 16).
    sync_bit: u32,
    x_bit: u32,
    y_bit: u32,
    /// Z's shift, or X's when there is no Z (the register is then never read).
    z_bit: u32,
    has_z: bool,
    x: u32,
    y: u32,
    z: u32,
    /// Consecutive high SYNC samples since the last rising edge (saturating).
    run: u32,
    lost: bool,
    counters: Counters,
}

impl Receiver {
    /// A receiver for `pins` on a link configured as `link`.
    pub fn new(pins: PinMap, link: LinkConfig) -> Result<Self, PinError> {
        check_pins(&[Some(pins.sync), Some(pins.x), Some(pins.y), pins.z])?;
        Ok(Receiver {
            link,
            sync_bit: u32::from(pins.sync),
            x_bit: u32::from(pins.x),
            y_bit: u32::from(pins.y),
            z_bit: u32::from(pins.z.unwrap_or(pins.x)),
            has_z: pins.z.is_some(),
            x: 0,
            y: 0,
            z: 0,
            run: RUN_SATURATED,
            lost: false,
            counters: Counters::default(),
        })
    }

    /// The running totals.
    pub const fn counters(&self) -> Counters {
        self.counters
    }

    /// Forgets any partial frame (e.g. after a DMA overrun), as at start-up.
    pub fn reset(&mut self) {
        self.run = RUN_SATURATED;
    }

    /// Processes port samples in time order, reporting to `sink`.
    pub fn feed(&mut self, samples: &[u16], sink: &mut impl FnMut(Event)) {
        self.feed_at(samples, &mut |_, e| sink(e));
    }

    /// [`Receiver::feed`], with each event's position: the number of `samples`
    /// consumed when it was decided, i.e. up to and including the sample that
    /// completed it (a frame period's 20th bit, the SYNC edge of a framing fault;
    /// the convention of [`HansRx::push_at`](crate::hans::rx::HansRx::push_at) and
    /// of the XY3-100 end positions). A bridge loop spreads a DMA half's events over its output
    /// slots by this position, so faults take no output slot of their own.
    pub fn feed_at(&mut self, samples: &[u16], sink: &mut impl FnMut(usize, Event)) {
        let (sb, xb, yb, zb) = (self.sync_bit, self.x_bit, self.y_bit, self.z_bit);
        let (mut x, mut y, mut z, mut run) = (self.x, self.y, self.z, self.run);
        // The position is worked out from the iterator only when an event is
        // reported: a counter per sample measurably slowed this loop (QEMU bench).
        let mut it = samples.iter();
        while let Some(&sample) = it.next() {
            let at = || samples.len() - it.as_slice().len();
            let s = u32::from(sample);
            x = x << 1 | (s >> xb & 1);
            y = y << 1 | (s >> yb & 1);
            z = z << 1 | (s >> zb & 1);
            if s >> sb & 1 != 0 {
                run = (run + 1).min(RUN_SATURATED);
                if run == SYNC_HIGH + 1 {
                    let at = at();
                    self.framing(FramingFault::Overlong, &mut |e| sink(at, e));
                }
            } else if run != 0 {
                // SYNC falling edge: this sample is bit 20 if the run was right.
                if run == SYNC_HIGH {
                    let at = at();
                    self.frame_end(x, y, z, &mut |e| sink(at, e));
                } else if run < SYNC_HIGH {
                    // `run` is 1..=18 here, so the narrowing is exact.
                    let high_bits = run as u8;
                    let at = at();
                    self.framing(FramingFault::Short { high_bits }, &mut |e| sink(at, e));
                }
                run = 0;
            }
        }
        (self.x, self.y, self.z, self.run) = (x, y, z, run);
    }

    fn framing(&mut self, fault: FramingFault, sink: &mut impl FnMut(Event)) {
        self.counters.framing = self.counters.framing.wrapping_add(1);
        self.lost = true;
        sink(Event::Framing(fault));
    }

    fn frame_end(&mut self, x: u32, y: u32, z: u32, sink: &mut impl FnMut(Event)) {
        if self.lost {
            self.lost = false;
            self.counters.resyncs = self.counters.resyncs.wrapping_add(1);
            sink(Event::Resync);
        }
        let period = FramePeriod {
            x: self.channel(x, 0),
            y: self.channel(y, 1),
            z: if self.has_z {
                Some(self.channel(z, 2))
            } else {
                None
            },
        };
        self.counters.frames = self.counters.frames.wrapping_add(1);
        sink(Event::Frame(period));
    }

    /// Decodes the last 20 bits of a channel register, counting failures.
    fn channel(&mut self, register: u32, index: usize) -> Result<Frame, ChannelError> {
        let word = register & FRAME_MASK;
        let result = if word == FRAME_MASK {
            Err(ChannelError::StuckHigh)
        } else {
            decode(word, &self.link).map_err(ChannelError::Decode)
        };
        if result.is_err() {
            if let Some(c) = self.counters.check_failures.get_mut(index) {
                *c = c.wrapping_add(1);
            }
        }
        result
    }
}

impl Event {
    /// The event in the bridge's neutral terms (zero to three [`LineEvent`]s).
    pub fn line_events(&self, sink: &mut impl FnMut(LineEvent)) {
        let fault = |kind| LineEvent::Fault {
            line: Line::Framing,
            kind,
        };
        match self {
            Event::Frame(period) => period.line_events(sink),
            Event::Framing(_) => sink(fault(FaultKind::Framing)),
            Event::Resync => sink(fault(FaultKind::Resync)),
        }
    }
}

impl FramePeriod {
    /// A [`LineEvent::Frame`] if every present channel decoded, else one
    /// [`FaultKind::CheckFailed`] per failed channel (see the module docs).
    pub fn line_events(&self, sink: &mut impl FnMut(LineEvent)) {
        let channels = [
            (Axis::X, Some(self.x)),
            (Axis::Y, Some(self.y)),
            (Axis::Z, self.z),
        ];
        // Decoded frames always convert; a failure would still only drop the period.
        let items =
            channels.map(|(axis, r)| (axis, r.map(|r| r.ok().and_then(|f| f.to_model().ok()))));
        let mut failed = false;
        for (axis, item) in items {
            if let Some(None) = item {
                failed = true;
                sink(LineEvent::Fault {
                    line: Line::Axis(axis),
                    kind: FaultKind::CheckFailed,
                });
            }
        }
        if failed {
            return;
        }
        let mut frame = ForwardFrame::default();
        for (axis, item) in items {
            match item.flatten() {
                Some(AxisItem::Position(p)) => {
                    if let Some(slot) = frame.axes.get_mut(axis.index()) {
                        *slot = Some(p);
                    }
                }
                Some(AxisItem::Command(c)) if axis == Axis::X => frame.command = Some(c),
                _ => {}
            }
        }
        sink(LineEvent::Frame(frame));
    }
}
