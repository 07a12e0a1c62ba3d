//! RS-485 driver-enable (DE) timing, judged from the edge times of a UART's TX and
//! DE pins (the HIL test `backchannel_de_timing` captures both with timer input
//! captures; the firmware itself never needs this).
//!
//! On a half-duplex pair the transceiver drives the bus only while DE is asserted. A
//! DE that rises late clips the first start bit on the bus, one that falls early clips
//! the last stop bit, and one held on keeps the pair driven so the far end's reply
//! collides with it. The STM32 USART switches DE itself: it asserts DE a set *lead*
//! (CR1.DEAT) before the first start bit of a message and releases it a set *tail*
//! (CR1.DEDT) after the end of the last stop bit, both counted in sample times (1/16
//! of a bit, 1/8 with 8x oversampling), and keeps it asserted between bytes that
//! follow back to back.
//!
//! [`check`] takes one capture of both pins and the messages sent during it:
//! 1. TX is decoded as 8N1 bytes (LSB first), each frame timed from its own start
//!    edge at the bit time the setup gives; every edge must sit on a bit boundary
//!    (within the tolerance), every stop bit must be high and last a full bit. The
//!    bytes must be the messages' bytes, each message back to back.
//! 2. DE must be low at the start and change exactly twice per message, so it is low
//!    everywhere else in the capture (idle, or receiving).
//! 3. Per message, the DE pulse must lead the first start edge by the configured lead
//!    and end the configured tail after the last stop bit, each within
//!    `[configured - tolerance, configured + one sample + tolerance]`: the USART
//!    switches DE on its sample clock, so a time may come out up to one sample longer
//!    than configured, never shorter.
//!
//! Times inside are capture ticks times 256 (`q8`), so bit times that are not whole
//! ticks add no rounding drift over a frame.

use core::fmt;

/// Data bits per frame (8N1).
const DATA_BITS: i64 = 8;
/// Bit times from a frame's start edge to the end of its stop bit.
const FRAME_BITS: i64 = DATA_BITS + 2;
/// Fewest capture ticks per bit that still resolve the bit grid.
const MIN_TICKS_PER_BIT: i64 = 8;

/// A UART's DE settings and the clock of the capture of its pins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Setup {
    /// UART kernel clock, Hz.
    pub kernel_hz: u32,
    /// Kernel clocks per bit (the baud-rate divider, prescaler included).
    pub kernel_clocks_per_bit: u32,
    /// Samples per bit, 16 or 8 (8x oversampling): the unit of the DE times.
    pub samples_per_bit: u32,
    /// DE lead, samples from DE asserted to the first start edge (CR1.DEAT).
    pub lead_samples: u32,
    /// DE tail, samples from the end of the last stop bit to DE released (CR1.DEDT).
    pub tail_samples: u32,
    /// Clock of the capture timer, Hz: edge times count its ticks.
    pub capture_hz: u32,
    /// Measurement error allowed on any edge, ns (input synchronisers, the skew
    /// between the two pins).
    pub tolerance_ns: u32,
}

/// The edges of one pin in a capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edges<'a> {
    /// Level before the first edge.
    pub initial_high: bool,
    /// Capture-timer ticks of every edge, both directions, strictly increasing.
    pub times: &'a [u32],
}

/// Which pin an error is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pin {
    /// The UART's transmit line.
    Tx,
    /// The transceiver's driver enable.
    De,
}

/// Smallest and largest of a measured time over the messages, ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Span {
    /// Smallest, ns.
    pub min: i64,
    /// Largest, ns.
    pub max: i64,
}

impl Span {
    /// No value yet: the first `add` sets both ends.
    const EMPTY: Self = Self {
        min: i64::MAX,
        max: i64::MIN,
    };

    fn add(&mut self, v: i64) {
        self.min = self.min.min(v);
        self.max = self.max.max(v);
    }
}

/// What a passing capture measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Measured {
    /// DE asserted to the first start edge, over the messages.
    pub lead_ns: Span,
    /// End of the last stop bit to DE released, over the messages.
    pub tail_ns: Span,
    /// The window either time had to fall in, ns.
    pub lead_window_ns: Span,
    /// The window of the tail, ns.
    pub tail_window_ns: Span,
}

/// Why a capture fails the check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DeError {
    /// The setup cannot be checked: a zero clock, samples per bit other than 8 or
    /// 16, fewer than 8 capture ticks per bit, or no message / an empty message.
    BadSetup,
    /// A pin's edge times do not strictly increase at `index` (a capture fault).
    Unordered {
        /// The pin.
        pin: Pin,
        /// Index of the first edge not after the one before it.
        index: usize,
    },
    /// TX was low when the capture started: not idle.
    TxNotIdle,
    /// DE was asserted when the capture started.
    DeAssertedAtStart,
    /// An edge in frame `byte` is `off_ns` from the nearest bit boundary it may
    /// fall on: a glitch, a second edge in one bit time, a short stop bit or another
    /// bit rate.
    TxOffGrid {
        /// Index of the byte on the line.
        byte: usize,
        /// Distance from the boundary, ns (negative: early).
        off_ns: i64,
    },
    /// Frame `byte`'s stop bit was low.
    TxFraming {
        /// Index of the byte on the line.
        byte: usize,
    },
    /// TX carried `got` bytes, the messages hold `expected`.
    TxCount {
        /// Bytes decoded.
        got: usize,
        /// Bytes in the messages.
        expected: usize,
    },
    /// Byte `index` of message `message` went out as `got`.
    TxByte {
        /// Message index.
        message: usize,
        /// Byte index in the message.
        index: usize,
        /// Value on the line.
        got: u8,
        /// Value sent.
        expected: u8,
    },
    /// Byte `index` of message `message` started `gap_ns` after the previous stop
    /// bit: the message was not sent back to back.
    TxGap {
        /// Message index.
        message: usize,
        /// Byte index in the message.
        index: usize,
        /// Idle time before it, ns.
        gap_ns: i64,
    },
    /// DE changed `got` times; one pulse per message and nothing else means
    /// `expected`. More: DE was asserted while idle or receiving; fewer: a message
    /// went out without its pulse, or DE stayed on.
    DeEdges {
        /// DE edges captured.
        got: usize,
        /// Two per message.
        expected: usize,
    },
    /// DE rose only `lead_ns` before message `message`'s first start edge, less
    /// than configured (negative: after it): the bus misses the start of the message.
    DeLate {
        /// Message index.
        message: usize,
        /// Measured lead, ns.
        lead_ns: i64,
    },
    /// DE rose `lead_ns` before message `message`'s first start edge, more than
    /// configured plus a sample.
    DeEarly {
        /// Message index.
        message: usize,
        /// Measured lead, ns.
        lead_ns: i64,
    },
    /// DE fell `tail_ns` after the end of message `message`'s last stop bit, less
    /// than configured (negative: inside the stop bit).
    DeReleasedEarly {
        /// Message index.
        message: usize,
        /// Measured tail, ns.
        tail_ns: i64,
    },
    /// DE fell `tail_ns` after the end of message `message`'s last stop bit, more
    /// than configured plus a sample: the bus stays driven into the reply.
    DeHeld {
        /// Message index.
        message: usize,
        /// Measured tail, ns.
        tail_ns: i64,
    },
}

impl fmt::Display for Pin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Tx => "TX",
            Self::De => "DE",
        })
    }
}

impl fmt::Display for DeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BadSetup => f.write_str("DE timing setup cannot be checked"),
            Self::Unordered { pin, index } => {
                write!(f, "{pin} edge {index} is not after the one before it")
            }
            Self::TxNotIdle => f.write_str("TX was low when the capture started"),
            Self::DeAssertedAtStart => f.write_str("DE was asserted when the capture started"),
            Self::TxOffGrid { byte, off_ns } => {
                write!(f, "TX edge in byte {byte} is {off_ns} ns off the bit grid")
            }
            Self::TxFraming { byte } => write!(f, "TX byte {byte} has a low stop bit"),
            Self::TxCount { got, expected } => {
                write!(f, "TX carried {got} bytes, {expected} were sent")
            }
            Self::TxByte {
                message,
                index,
                got,
                expected,
            } => write!(
                f,
                "message {message} byte {index} went out as {got:#04x}, sent {expected:#04x}"
            ),
            Self::TxGap {
                message,
                index,
                gap_ns,
            } => write!(
                f,
                "message {message} byte {index} started {gap_ns} ns after the previous stop bit"
            ),
            Self::DeEdges { got, expected } => {
                write!(f, "DE changed {got} times, expected {expected}")
            }
            Self::DeLate { message, lead_ns } => write!(
                f,
                "DE rose only {lead_ns} ns before message {message}'s start bit"
            ),
            Self::DeEarly { message, lead_ns } => write!(
                f,
                "DE rose {lead_ns} ns before message {message}'s start bit, more than configured"
            ),
            Self::DeReleasedEarly { message, tail_ns } => write!(
                f,
                "DE fell {tail_ns} ns after message {message}'s stop bit, less than configured"
            ),
            Self::DeHeld { message, tail_ns } => write!(
                f,
                "DE fell {tail_ns} ns after message {message}'s stop bit, more than configured"
            ),
        }
    }
}

/// The setup in q8 capture ticks.
#[derive(Clone, Copy)]
struct Grid {
    bit: i64,
    tolerance: i64,
    lead: (i64, i64),
    tail: (i64, i64),
    capture_hz: i64,
}

impl Grid {
    fn new(s: &Setup) -> Result<Self, DeError> {
        if s.kernel_hz == 0 || s.capture_hz == 0 || !matches!(s.samples_per_bit, 8 | 16) {
            return Err(DeError::BadSetup);
        }
        let capture_hz = i64::from(s.capture_hz);
        // In i128: u32 * u32 * 256 does not fit an i64.
        let q8 = |x: u32, per: u32| {
            let v = i128::from(x) * i128::from(s.capture_hz) * 256 / i128::from(per);
            i64::try_from(v).map_err(|_| DeError::BadSetup)
        };
        let bit = q8(s.kernel_clocks_per_bit, s.kernel_hz)?;
        if bit < MIN_TICKS_PER_BIT * 256 {
            return Err(DeError::BadSetup);
        }
        let sample = bit / i64::from(s.samples_per_bit);
        let tolerance = q8(s.tolerance_ns, 1_000_000_000)?;
        let window = |samples: u32| {
            let t = i64::from(samples) * bit / i64::from(s.samples_per_bit);
            (t - tolerance, t + sample + tolerance)
        };
        Ok(Self {
            bit,
            tolerance,
            lead: window(s.lead_samples),
            tail: window(s.tail_samples),
            capture_hz,
        })
    }

    /// A q8 tick count in ns.
    fn ns(&self, q8: i64) -> i64 {
        let ns = i128::from(q8) * 1_000_000_000 / (i128::from(self.capture_hz) * 256);
        ns as i64
    }

    fn span_ns(&self, (min, max): (i64, i64)) -> Span {
        Span {
            min: self.ns(min),
            max: self.ns(max),
        }
    }
}

/// One decoded TX frame.
struct Byte {
    /// Start edge, q8 ticks.
    start: i64,
    value: u8,
}

impl Byte {
    /// End of the stop bit, q8 ticks.
    fn end(&self, grid: &Grid) -> i64 {
        self.start + FRAME_BITS * grid.bit
    }
}

/// 8N1 frames from TX edges; the line is high before the first edge (checked by the
/// caller) and after every frame (its stop bit), so each frame starts at a falling
/// edge.
struct Frames<'a> {
    edges: &'a [u32],
    next: usize,
    byte: usize,
    grid: Grid,
}

impl Frames<'_> {
    fn at(&self, i: usize) -> i64 {
        i64::from(self.edges[i]) * 256
    }

    fn frame(&mut self) -> Result<Byte, DeError> {
        let g = self.grid;
        let off = |t: i64, boundary: i64| {
            Err(DeError::TxOffGrid {
                byte: self.byte,
                off_ns: g.ns(t - boundary),
            })
        };
        let start = self.at(self.next);
        let mut j = self.next + 1;
        let mut high = false;
        let mut value = 0u8;
        // Bit k (1..=8 data, 9 stop) is read at its middle; every edge before that
        // middle and after the previous one must be the one on boundary k.
        for k in 1..FRAME_BITS {
            let boundary = start + k * g.bit;
            let middle = boundary + g.bit / 2;
            let mut seen = false;
            while j < self.edges.len() && self.at(j) < middle {
                let t = self.at(j);
                if seen || (t - boundary).abs() > g.tolerance {
                    return off(t, boundary);
                }
                seen = true;
                high = !high;
                j += 1;
            }
            if k <= DATA_BITS {
                value |= u8::from(high) << (k - 1);
            } else if !high {
                return Err(DeError::TxFraming { byte: self.byte });
            }
        }
        // The next start edge may not cut the stop bit short.
        let end = start + FRAME_BITS * g.bit;
        if j < self.edges.len() && self.at(j) < end - g.tolerance {
            return off(self.at(j), end);
        }
        self.next = j;
        self.byte += 1;
        Ok(Byte { start, value })
    }
}

impl Iterator for Frames<'_> {
    type Item = Result<Byte, DeError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.next >= self.edges.len() {
            return None;
        }
        let frame = self.frame();
        if frame.is_err() {
            // One error ends the decode.
            self.next = self.edges.len();
        }
        Some(frame)
    }
}

/// Checks a capture of a UART's TX and DE pins against `setup`, the bytes on TX
/// against `messages` (each sent in one go, with idle time between them); see the
/// module docs for the rules.
pub fn check(
    setup: &Setup,
    tx: Edges<'_>,
    de: Edges<'_>,
    messages: &[&[u8]],
) -> Result<Measured, DeError> {
    let grid = Grid::new(setup)?;
    if messages.is_empty() || messages.iter().any(|m| m.is_empty()) {
        return Err(DeError::BadSetup);
    }
    for (pin, edges) in [(Pin::Tx, &tx), (Pin::De, &de)] {
        if let Some(i) = edges.times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(DeError::Unordered { pin, index: i + 1 });
        }
    }
    if !tx.initial_high {
        return Err(DeError::TxNotIdle);
    }
    if de.initial_high {
        return Err(DeError::DeAssertedAtStart);
    }
    let frames = || Frames {
        edges: tx.times,
        next: 0,
        byte: 0,
        grid,
    };
    // (message, index in it, value) of every byte sent, in line order.
    let sent = || {
        messages
            .iter()
            .enumerate()
            .flat_map(|(m, msg)| msg.iter().enumerate().map(move |(i, &v)| (m, i, v)))
    };
    let expected = sent().count();

    // TX: the bytes, each message back to back.
    let mut got = 0;
    let mut prev_end = 0;
    let mut want = sent();
    for byte in frames() {
        let byte = byte?;
        got += 1;
        if let Some((message, index, value)) = want.next() {
            if byte.value != value {
                return Err(DeError::TxByte {
                    message,
                    index,
                    got: byte.value,
                    expected: value,
                });
            }
            if index > 0 && byte.start - prev_end > grid.tolerance {
                return Err(DeError::TxGap {
                    message,
                    index,
                    gap_ns: grid.ns(byte.start - prev_end),
                });
            }
        }
        prev_end = byte.end(&grid);
    }
    if got != expected {
        return Err(DeError::TxCount { got, expected });
    }

    // DE: one pulse per message, low everywhere else.
    if de.times.len() != 2 * messages.len() {
        return Err(DeError::DeEdges {
            got: de.times.len(),
            expected: 2 * messages.len(),
        });
    }
    let de_at = |i: usize| i64::from(de.times[i]) * 256;
    // Every message has a first and a last byte, so both spans get set.
    let mut lead_ns = Span::EMPTY;
    let mut tail_ns = Span::EMPTY;
    for (byte, (message, index, _)) in frames().zip(sent()) {
        let byte = byte?;
        if index == 0 {
            let lead = byte.start - de_at(2 * message);
            let ns = grid.ns(lead);
            within(
                lead,
                grid.lead,
                DeError::DeLate {
                    message,
                    lead_ns: ns,
                },
                DeError::DeEarly {
                    message,
                    lead_ns: ns,
                },
            )?;
            lead_ns.add(ns);
        }
        if index + 1 == messages[message].len() {
            let tail = de_at(2 * message + 1) - byte.end(&grid);
            let ns = grid.ns(tail);
            within(
                tail,
                grid.tail,
                DeError::DeReleasedEarly {
                    message,
                    tail_ns: ns,
                },
                DeError::DeHeld {
                    message,
                    tail_ns: ns,
                },
            )?;
            tail_ns.add(ns);
        }
    }
    Ok(Measured {
        lead_ns,
        tail_ns,
        lead_window_ns: grid.span_ns(grid.lead),
        tail_window_ns: grid.span_ns(grid.tail),
    })
}

/// `Ok` when `t` lies within `window` (both ends included), else the error for the
/// side it is out on.
fn within(t: i64, window: (i64, i64), below: DeError, above: DeError) -> Result<(), DeError> {
    if t < window.0 {
        Err(below)
    } else if t > window.1 {
        Err(above)
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests;
