//! XY3-100 line transmitter (sans-IO): frames in, GPIO BSRR words out (layouts
//! item 4, XY3-100 §5.1).
//!
//! # The waveform
//! A timer ticks at [`Transmitter::tick_hz`] and each tick DMAs one `u32` into the
//! output port's BSRR (low half sets pins, high half resets them). A frame of `N`
//! bits (24 or 32) occupies a fixed number of ticks, [`Transmitter::ticks_per_frame`]
//! `= 2 N + idle_ticks`:
//!
//! | word | CLK | SYNC | data |
//! |---|---|---|---|
//! | 0 | low | falls | bit 0 (set-up for the first edge) |
//! | `2b + 1`, b = 0..N | rises | low | bit `b` |
//! | `2b + 2` | falls: the receiver samples here (§5.1) | low | unchanged |
//! | `2N + 1` | low | rises | all low |
//! | `2N + 2` .. end | idle: nothing changes | high | low |
//!
//! SYNC works as the SPI chip select of §5.1: it goes low one tick before the first
//! rising CLK edge and rises one tick after the last falling edge, so a receiver's
//! select has half a bit of set-up and hold around the bits. The two idle ticks that
//! make this margin are why a frame period is *not* exactly `2 N` ticks: at the
//! nominal 2.4 MHz a 24-bit frame fills the whole 10 us and leaves no room for SYNC to
//! rise. With the minimum `idle_ticks = 2` the bit clock is a little faster than
//! nominal (24-bit frames at 100 kHz: 50 ticks, 5 MHz tick rate, 2.5 MHz bit clock;
//! 32-bit: 66 ticks, 6.6 MHz, 3.3 MHz), which §5.1 allows: only the frame rate is
//! fixed, the receiver clocks on the edges. The firmware may add idle ticks so that
//! the tick rate divides its timer clock (e.g. 32-bit frames with `idle_ticks = 16`:
//! 80 ticks, 8 MHz at 100 kHz).
//!
//! # Frame sizes
//! All lines share CLK and SYNC, so every line of a frame period carries a frame of
//! the same size; the size is configured once ([`TxConfig::size`]) and a frame of the
//! other size is refused. Commands go on X (§5.1.1); the caller may repeat them on
//! other lines.
//!
//! # Cost
//! The pins are resolved once: a 32-entry table gives the BSRR data part for every
//! pattern of one bit per line. Encoding transposes the lines' words eight bits at a
//! time (an 8x8 bit-matrix transpose) and looks each bit time's pattern up, so the
//! cost hardly depends on the number of lines and has no branches on the data.

use core::fmt;

use super::frame::{encode, EncodeError, Frame, FrameSize};
use crate::model::Axis;

/// Idle ticks a frame period needs at least: SYNC set-up before the first rising CLK
/// edge and SYNC rising after the last falling one.
pub const MIN_IDLE_TICKS: u8 = 2;

/// Which output port bit (0..=15) drives which XY3-100 line.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OutPinMap {
    /// CLK.
    pub clk: u8,
    /// SYNC.
    pub sync: u8,
    /// Data line per axis X, Y, Z, U, W (indexed by [`Axis::index`]); `None` = not
    /// driven. X and Y are required.
    pub data: [Option<u8>; 5],
}

/// The transmitter's configuration.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxConfig {
    /// Output pins.
    pub pins: OutPinMap,
    /// Frame size of every line in every period.
    pub size: FrameSize,
    /// Ticks after the bits (at least [`MIN_IDLE_TICKS`]).
    pub idle_ticks: u8,
}

/// Why a [`TxConfig`] is refused.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TxConfigError {
    /// A pin index is above 15.
    PinOutOfRange(u8),
    /// A pin drives two lines.
    PinTwice(u8),
    /// X or Y has no pin.
    MissingLine(Axis),
    /// Fewer idle ticks than [`MIN_IDLE_TICKS`].
    IdleTooShort(u8),
}

impl fmt::Display for TxConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::PinOutOfRange(p) => write!(f, "output pin {p} is not a port bit 0..=15"),
            Self::PinTwice(p) => write!(f, "output pin {p} drives two lines"),
            Self::MissingLine(a) => write!(f, "no output pin for the {a:?} line"),
            Self::IdleTooShort(n) => write!(f, "{n} idle ticks, at least 2 needed"),
        }
    }
}

/// Why a frame period cannot be encoded (nothing useful is written).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TxError {
    /// The output slice is shorter than a frame period.
    BufferTooShort {
        /// Words needed.
        needed: usize,
        /// Words given.
        got: usize,
    },
    /// A driven line has no frame.
    MissingFrame(Axis),
    /// A frame for a line that is not driven.
    NotDriven(Axis),
    /// A frame of the other size than configured.
    WrongSize(Axis),
    /// A frame's fields do not fit the wire.
    Encode(EncodeError),
}

impl fmt::Display for TxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BufferTooShort { needed, got } => {
                write!(f, "output buffer of {got} words, a frame needs {needed}")
            }
            Self::MissingFrame(a) => write!(f, "no frame for the driven {a:?} line"),
            Self::NotDriven(a) => write!(f, "frame for the {a:?} line, which is not driven"),
            Self::WrongSize(a) => write!(f, "{a:?} frame has the other size than configured"),
            Self::Encode(e) => write!(f, "{e}"),
        }
    }
}

/// Set bit of `pin` in the BSRR low half.
const fn set(pin: u8) -> u32 {
    1 << pin
}

/// Reset bit of `pin` in the BSRR high half.
const fn reset(pin: u8) -> u32 {
    1 << (pin + 16)
}

/// The XY3-100 transmitter: precomputed masks for one pin map and frame size.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Transmitter {
    clk: u8,
    sync: u8,
    /// Pin per axis, `None` if not driven.
    data: [Option<u8>; 5],
    /// Set bits of every driven data pin.
    data_mask: u32,
    /// The rising-edge word (CLK set, data set for ones, reset for zeros) of every
    /// pattern of one bit per line: bit 4 = X, bit 3 = Y, … bit 0 = W.
    lut: [u32; 32],
    size: FrameSize,
    ticks: usize,
}

impl Transmitter {
    /// Checks the configuration and precomputes the masks.
    pub fn new(config: &TxConfig) -> Result<Self, TxConfigError> {
        let pins = &config.pins;
        for axis in [Axis::X, Axis::Y] {
            if pins.data.get(axis.index()).copied().flatten().is_none() {
                return Err(TxConfigError::MissingLine(axis));
            }
        }
        if config.idle_ticks < MIN_IDLE_TICKS {
            return Err(TxConfigError::IdleTooShort(config.idle_ticks));
        }
        let mut used = 0u32;
        let all = [Some(pins.clk), Some(pins.sync)];
        for p in all.iter().chain(pins.data.iter()).flatten() {
            if *p > 15 {
                return Err(TxConfigError::PinOutOfRange(*p));
            }
            if used & set(*p) != 0 {
                return Err(TxConfigError::PinTwice(*p));
            }
            used |= set(*p);
        }
        let data_mask = pins.data.iter().flatten().fold(0, |m, &p| m | set(p));
        let mut lut = [0u32; 32];
        for (v, entry) in lut.iter_mut().enumerate() {
            let ones = pins
                .data
                .iter()
                .enumerate()
                .filter(|(i, _)| v >> (4 - i) & 1 != 0)
                .filter_map(|(_, p)| *p)
                .fold(0, |m, p| m | set(p));
            *entry = set(pins.clk) | ones | (data_mask ^ ones) << 16;
        }
        Ok(Transmitter {
            clk: pins.clk,
            sync: pins.sync,
            data: pins.data,
            data_mask,
            lut,
            size: config.size,
            ticks: 2 * config.size.bits() as usize + config.idle_ticks as usize,
        })
    }

    /// Words (ticks) per frame period.
    pub const fn ticks_per_frame(&self) -> usize {
        self.ticks
    }

    /// The configured frame size.
    pub const fn size(&self) -> FrameSize {
        self.size
    }

    /// The tick (DMA request) rate for `frame_rate_hz` frames per second.
    pub const fn tick_hz(&self, frame_rate_hz: u32) -> u64 {
        self.ticks as u64 * frame_rate_hz as u64
    }

    /// Writes one idle frame period (SYNC high, CLK and data low) into
    /// `out[..ticks_per_frame()]`, for when there is nothing to send.
    pub fn idle(&self, out: &mut [u32]) -> Result<(), TxError> {
        let words = self.slot(out)?;
        words.fill(0);
        if let Some(first) = words.first_mut() {
            *first = set(self.sync) | reset(self.clk) | self.data_mask << 16;
        }
        Ok(())
    }

    fn slot<'a>(&self, out: &'a mut [u32]) -> Result<&'a mut [u32], TxError> {
        let got = out.len();
        out.get_mut(..self.ticks).ok_or(TxError::BufferTooShort {
            needed: self.ticks,
            got,
        })
    }

    /// Encodes one frame period into `out[..ticks_per_frame()]`: `frames` holds one
    /// frame per axis (indexed by [`Axis::index`]), present exactly for the driven
    /// lines, all of the configured size.
    pub fn encode(&self, frames: &[Option<Frame>; 5], out: &mut [u32]) -> Result<(), TxError> {
        // Each line's word MSB-aligned (first bit in bit 31); 0 for lines not driven.
        let mut words = [0u32; 5];
        for (((axis, pin), frame), word) in Axis::ALL
            .iter()
            .zip(self.data)
            .zip(frames)
            .zip(words.iter_mut())
        {
            *word = match (pin, frame) {
                (None, None) => continue,
                (None, Some(_)) => return Err(TxError::NotDriven(*axis)),
                (Some(_), None) => return Err(TxError::MissingFrame(*axis)),
                (Some(_), Some(f)) if f.size() != self.size => {
                    return Err(TxError::WrongSize(*axis))
                }
                (Some(_), Some(f)) => encode(f).map_err(TxError::Encode)?.0,
            } << (32 - u32::from(self.size.bits()));
        }
        let out = self.slot(out)?;
        let (clk_set, clk_reset) = (set(self.clk), reset(self.clk));
        let bits = usize::from(self.size.bits());
        let Some((setup, rest)) = out.split_first_mut() else {
            return Ok(());
        };
        // Eight bits (16 words) at a time, on fixed-size chunks so the stores need no
        // bounds checks and the eight rows unroll.
        let (chunks, _) = rest.as_chunks_mut::<16>();
        for (chunk, sh) in chunks.iter_mut().zip([24, 16, 8, 0]).take(bits / 8) {
            self.byte_words(words, sh, chunk, clk_reset);
        }
        // Set-up word: SYNC falls with bit 0's data in place, CLK still low.
        let first = rest.first().map_or(0, |w| w & !clk_set);
        *setup = reset(self.sync) | clk_reset | first;
        if let Some((rise, idle)) = out
            .get_mut(2 * bits + 1..)
            .and_then(|t| t.split_first_mut())
        {
            *rise = set(self.sync) | self.data_mask << 16;
            idle.fill(0);
        }
        Ok(())
    }

    /// The 16 words of bits `sh + 7 .. sh` (MSB first) of every line.
    ///
    /// Transposes the 8x8 bit matrix whose rows are that byte of each line (rows 5..7
    /// empty), so that row `j` of the result holds bit `j` of every line (X in bit 7 …
    /// W in bit 3), then looks each row's pattern up (Hacker's Delight, 2nd ed., §7-3,
    /// transposing an 8x8 bit matrix).
    #[inline(always)]
    fn byte_words(&self, [a, b, c, d, e]: [u32; 5], sh: u32, out: &mut [u32; 16], clk_reset: u32) {
        let byte = |w: u32| w >> sh & 0xFF;
        let mut x = byte(a) << 24 | byte(b) << 16 | byte(c) << 8 | byte(d);
        let mut y = byte(e) << 24;
        let mut t = (x ^ x >> 7) & 0x00AA_00AA;
        x ^= t ^ t << 7;
        t = (y ^ y >> 7) & 0x00AA_00AA;
        y ^= t ^ t << 7;
        t = (x ^ x >> 14) & 0x0000_CCCC;
        x ^= t ^ t << 14;
        t = (y ^ y >> 14) & 0x0000_CCCC;
        y ^= t ^ t << 14;
        t = x & 0xF0F0_F0F0 | y >> 4 & 0x0F0F_0F0F;
        y = x << 4 & 0xF0F0_F0F0 | y & 0x0F0F_0F0F;
        x = t;
        let rows = [x >> 24, x >> 16, x >> 8, x, y >> 24, y >> 16, y >> 8, y];
        let (pairs, _) = out.as_chunks_mut::<2>();
        for (pair, row) in pairs.iter_mut().zip(rows) {
            let rising = self.lut.get((row >> 3 & 31) as usize).copied().unwrap_or(0);
            *pair = [rising, clk_reset];
        }
    }
}
