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
//! The pins are resolved once: a 32-entry table gives the rising word (CLK set, data
//! set or reset) for every pattern of one bit per line, and the CLK, SYNC and data
//! masks are kept as BSRR bits. Heads without U and W use the XY2-100 transmitter's
//! pattern gathering (`xy2::tx::lanes`): the first 8 entries are the X Y Z
//! patterns, each line's next byte is spread by a 256-entry table so eight bit
//! times' indices sit side by side, and two neighbouring indices select one entry
//! of a 64-entry table holding both bits' four words (`lanes::pair_patterns`, 2 KiB
//! per transmitter), copied as one block: per two bits a field extract, two address
//! computations, one load-multiple and one store-multiple (`lanes::fill_pairs`).
//! With U or W the five lines are merged six bit times at a time into 5-bit fields
//! (a 64-entry spreading table), then per bit one field extract, one look-up and
//! two stores. The loop is compiled once per frame size (fully unrolled) and per
//! "U or W driven", each copy out of line. No branches on the data. About 285
//! instructions per 32-bit frame period on X Y Z (260 for 24-bit frames; 320 / 285
//! with the one-bit loop) and 435 on all five lines on the Cortex-M7 (`cargo xtask
//! qemu`), some 135 of them checking and encoding the frames
//! ([`Transmitter::encode`]): the fill of a 32-bit X Y Z period is 149. The
//! bridge's head encoder builds and encodes its frames itself and goes straight to
//! the fill of its layout (`Transmitter::encode_words_for`).

use core::fmt;

use super::frame::{encode, EncodeError, Frame, FrameSize};
use crate::model::Axis;
use crate::xy2::tx::lanes;

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

/// The XY3-100 transmitter: precomputed masks for one pin map and frame size.
///
/// In declaration order (`repr(C)`): the two tables first, so each fill's look-ups
/// index from the transmitter's own address instead of a second base register.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(C)]
pub struct Transmitter {
    /// The rising-edge word (CLK set, data set for ones, reset for zeros) of every
    /// pattern of one bit per line: bit 0 = X, bit 1 = Y, … bit 4 = W. Its first 8
    /// entries (U and W low) are the patterns of X, Y and Z alone.
    lut: [u32; 32],
    /// The words of two bit times of X, Y and Z per pair of patterns (`lut`'s
    /// first 8 entries and the CLK-reset word; `xy2::tx::lanes::pair_patterns`),
    /// for heads without U and W.
    pairs: [[u32; lanes::ENTRY]; 64],
    /// Set bit of CLK (its reset bit is this shifted up 16).
    clk: u32,
    /// Set bit of SYNC.
    sync: u32,
    /// Set bits of every driven data pin.
    data_mask: u32,
    ticks: usize,
    /// Pin per axis, `None` if not driven.
    data: [Option<u8>; 5],
    /// The driven lines, bit [`Axis::index`] per line.
    driven: u8,
    size: FrameSize,
    /// U or W is driven (else their words are always 0 and the encoder skips them).
    wide: bool,
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
                .filter(|(i, _)| v >> i & 1 != 0)
                .filter_map(|(_, p)| *p)
                .fold(0, |m, p| m | set(p));
            *entry = set(pins.clk) | ones | (data_mask ^ ones) << 16;
        }
        Ok(Transmitter {
            clk: set(pins.clk),
            sync: set(pins.sync),
            data: pins.data,
            data_mask,
            driven: pins
                .data
                .iter()
                .enumerate()
                .filter(|(_, p)| p.is_some())
                .fold(0, |m, (i, _)| m | 1 << i),
            pairs: lut.first_chunk::<8>().map_or([[0; lanes::ENTRY]; 64], |p| {
                lanes::pair_patterns(p, set(pins.clk) << 16)
            }),
            lut,
            size: config.size,
            ticks: 2 * config.size.bits() as usize + config.idle_ticks as usize,
            wide: matches!(pins.data, [_, _, _, Some(_), _] | [_, _, _, _, Some(_)]),
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

    /// Whether `axis`' data line has a pin.
    pub fn drives(&self, axis: Axis) -> bool {
        matches!(self.data.get(axis.index()), Some(Some(_)))
    }

    /// The driven lines as a mask, bit [`Axis::index`] per line (one compare for
    /// the bridge's head encoder).
    pub(crate) const fn driven(&self) -> u8 {
        self.driven
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
            *first = self.sync | (self.clk | self.data_mask) << 16;
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
    #[inline]
    pub fn encode(&self, frames: &[Option<Frame>; 5], out: &mut [u32]) -> Result<(), TxError> {
        // In axis order, so the first misfit is the error.
        let words = [
            self.line_word(Axis::X, frames)?,
            self.line_word(Axis::Y, frames)?,
            self.line_word(Axis::Z, frames)?,
            self.line_word(Axis::U, frames)?,
            self.line_word(Axis::W, frames)?,
        ];
        let out = self.slot(out)?;
        self.fill_words(words, out);
        Ok(())
    }

    /// Writes one frame period of already encoded wire words (right-aligned, one per
    /// axis indexed by [`Axis::index`], of the configured size, bits above it
    /// ignored; words of lines without a pin are ignored) into
    /// `out[..ticks_per_frame()]`, for a caller that built and checked the frames
    /// itself (the bridge's head encoder).
    pub fn encode_words(&self, words: [u32; 5], out: &mut [u32]) -> Result<(), TxError> {
        let out = self.slot(out)?;
        self.fill_words(words, out);
        Ok(())
    }

    /// Whether U or W is driven (the bridge's head encoder picks its
    /// [`Self::encode_words_for`] copy by it).
    pub(crate) const fn wide(&self) -> bool {
        self.wide
    }

    /// [`Self::encode_words`] for a caller that already knows the frame size
    /// (`BITS32`: [`FrameSize::Bits32`]) and whether U or W is driven (`WIDE`,
    /// [`Self::wide`]), so it takes the one fill of that layout without asking the
    /// transmitter again. Both must be the transmitter's own: the bridge's head
    /// encoder dispatches on them once per slot, and its tests compare every size and
    /// line set with the checked [`Self::encode`].
    #[inline(always)]
    pub(crate) fn encode_words_for<const BITS32: bool, const WIDE: bool>(
        &self,
        words: [u32; 5],
        out: &mut [u32],
    ) -> Result<(), TxError> {
        let out = self.slot(out)?;
        self.fill_for::<BITS32, WIDE>(words, out);
        Ok(())
    }

    /// [`Self::fill`] for the configured size and lines.
    #[inline(always)]
    fn fill_words(&self, words: [u32; 5], out: &mut [u32]) {
        // One copy of the bit loop per frame size, so it unrolls with constant shifts,
        // and per "U or W driven", so the common X Y Z head skips two idle lines.
        match (self.size, self.wide) {
            (FrameSize::Bits24, false) => self.fill_for::<false, false>(words, out),
            (FrameSize::Bits24, true) => self.fill_for::<false, true>(words, out),
            (FrameSize::Bits32, false) => self.fill_for::<true, false>(words, out),
            (FrameSize::Bits32, true) => self.fill_for::<true, true>(words, out),
        }
    }

    /// [`Self::fill`] of 32-bit frames if `BITS32`, else 24-bit ones: the one place
    /// a frame size's bit, pair and word counts are written down.
    #[inline(always)]
    fn fill_for<const BITS32: bool, const WIDE: bool>(&self, words: [u32; 5], out: &mut [u32]) {
        if BITS32 {
            self.fill::<32, 16, 65, WIDE>(words, out);
        } else {
            self.fill::<24, 12, 49, WIDE>(words, out);
        }
    }

    /// The wire word of `axis`' line (right-aligned); 0 if the line is not driven.
    #[inline(always)]
    fn line_word(&self, axis: Axis, frames: &[Option<Frame>; 5]) -> Result<u32, TxError> {
        let pin = self.data.get(axis.index()).copied().flatten();
        let frame = frames.get(axis.index()).copied().flatten();
        let word = match (pin, frame) {
            (None, None) => return Ok(0),
            (None, Some(_)) => return Err(TxError::NotDriven(axis)),
            (Some(_), None) => return Err(TxError::MissingFrame(axis)),
            (Some(_), Some(f)) if f.size() != self.size => return Err(TxError::WrongSize(axis)),
            (Some(_), Some(f)) => encode(&f).map_err(TxError::Encode)?.0,
        };
        Ok(word)
    }

    /// Writes the set-up word, the `2 * BITS` bit words of the right-aligned `words`,
    /// SYNC's rise and the idle tail; `out` is exactly one frame period (at least
    /// `2 * BITS + 2` words; `PAIRS` is `BITS / 2` and `WORDS` `2 * BITS + 1`, the
    /// bit words and SYNC's rise). Without `WIDE` the U and W words are 0 (not
    /// driven) and the shared three-line loop (`xy2::tx::lanes`) does X, Y and Z,
    /// two bit times per look-up. Out of line, one copy per layout: the same for
    /// every caller, while the frame checks inline.
    #[inline(never)]
    fn fill<const BITS: usize, const PAIRS: usize, const WORDS: usize, const WIDE: bool>(
        &self,
        words: [u32; 5],
        out: &mut [u32],
    ) {
        const { assert!(2 * PAIRS == BITS && WORDS == 2 * BITS + 1) };
        // MSB-aligned: the first bit on the line in bit 31.
        let [a, b, c, d, e] = words.map(|w| w << (32 - BITS));
        let clk_reset = self.clk << 16;
        let Some((setup, rest)) = out.split_first_mut() else {
            return;
        };
        let first = if WIDE {
            let (pairs, _) = rest.as_chunks_mut::<2>();
            let Some(pairs) = pairs.first_chunk_mut::<BITS>() else {
                return;
            };
            wide(&self.lut, clk_reset, [a, b, c, d, e], pairs);
            pairs.first().map_or(0, |p| p[0])
        } else {
            // The word after the bits (SYNC's rise) is written below, so the loop
            // may scratch it.
            let Some(bits) = rest.first_chunk_mut::<WORDS>() else {
                return;
            };
            lanes::fill_pairs::<PAIRS, WORDS>(&self.pairs, [a, b, c], bits);
            bits[0]
        };
        // Set-up word: SYNC falls with bit 0's data in place, CLK still low.
        let first = first & !self.clk;
        *setup = self.sync << 16 | clk_reset | first;
        if let Some((rise, idle)) = rest.get_mut(2 * BITS..).and_then(|t| t.split_first_mut()) {
            *rise = self.sync | self.data_mask << 16;
            // Often nothing (the minimum idle): skip the call of a zero-length fill.
            if !idle.is_empty() {
                idle.fill(0);
            }
        }
    }
}

/// The bit words of five lines (MSB-aligned `lines`), six bit times at a time: each
/// line's next six bits are spread five places apart ([`SPREAD6`]) and the lines
/// merged one place apart, so that bits `5k + 4 ..= 5k` of the merged word are the
/// `lut` index (X in bit 0 … W in bit 4) of the group's bit time `5 - k`; then each
/// bit time is one field extract, one table look-up and the store.
#[inline(always)]
fn wide<const BITS: usize>(
    lut: &[u32; 32],
    clk_reset: u32,
    lines: [u32; 5],
    pairs: &mut [[u32; 2]; BITS],
) {
    for (g, group) in pairs.chunks_mut(6).enumerate() {
        // The group's six bits of a line: bits `31 - 6g ..= 26 - 6g`; the last group
        // of a 32-bit frame has only two, shifted to the top of the field.
        let spread = |w: u32| {
            let six = match 26u32.checked_sub(6 * g as u32) {
                Some(s) => w >> s,
                None => w << (6 * g as u32 - 26),
            };
            SPREAD6.get((six & 63) as usize).copied().unwrap_or(0)
        };
        let merged = lines
            .iter()
            .enumerate()
            .fold(0, |m, (i, &w)| m | spread(w) << i);
        for (pair, k) in group.iter_mut().zip((0..6u32).rev()) {
            let rising = lut.get((merged >> (5 * k) & 31) as usize);
            *pair = [rising.copied().unwrap_or(0), clk_reset];
        }
    }
}

/// Bit `k` of the index at bit `5k` (k < 6).
const SPREAD6: [u32; 64] = lanes::spread_table(6, 5);

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Reset bit of `pin` in the BSRR high half.
    const fn reset(pin: u8) -> u32 {
        1 << (pin + 16)
    }

    /// The waveform table of the module docs, bit by bit, for `words` (right-aligned
    /// wire words, 0 for lines not driven).
    fn reference(tx: &Transmitter, pins: &OutPinMap, words: [u32; 5]) -> Vec<u32> {
        let n = u32::from(tx.size().bits());
        let level = |p: u8, on: bool| if on { set(p) } else { reset(p) };
        let data = |bit: u32| {
            pins.data
                .iter()
                .zip(words)
                .filter_map(|(p, w)| p.map(|p| level(p, w >> (n - 1 - bit) & 1 == 1)))
                .fold(0, |a, m| a | m)
        };
        let mut out = vec![reset(pins.sync) | reset(pins.clk) | data(0)];
        for bit in 0..n {
            out.push(set(pins.clk) | data(bit));
            out.push(reset(pins.clk));
        }
        let data_mask = pins.data.iter().flatten().fold(0, |a, &p| a | set(p));
        out.push(set(pins.sync) | data_mask << 16);
        out.resize(tx.ticks_per_frame(), 0);
        out
    }

    proptest! {
        /// `encode` gives the reference waveform for random frames of both sizes on
        /// random pin maps with 2..=5 lines and random idle lengths.
        #[test]
        fn encode_matches_the_per_bit_reference(
            values in any::<[u32; 5]>(),
            pins in Just([0u8, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15]).prop_shuffle(),
            driven in any::<[bool; 3]>(),
            big in any::<bool>(),
            idle in MIN_IDLE_TICKS..20,
        ) {
            let size = if big { FrameSize::Bits32 } else { FrameSize::Bits24 };
            let mut data = [None; 5];
            for (i, d) in data.iter_mut().enumerate() {
                let on = i < 2 || driven[i - 2];
                *d = on.then_some(pins[2 + i]);
            }
            let map = OutPinMap { clk: pins[0], sync: pins[1], data };
            let tx = Transmitter::new(&TxConfig { pins: map, size, idle_ticks: idle }).unwrap();
            let mut frames = [None; 5];
            let mut words = [0u32; 5];
            for i in 0..5 {
                if data[i].is_some() {
                    let f = match size {
                        FrameSize::Bits24 => Frame::Position24(values[i] >> 12),
                        FrameSize::Bits32 => Frame::Position32(values[i] >> 6),
                    };
                    frames[i] = Some(f);
                    words[i] = encode(&f).unwrap().0;
                }
            }
            let mut out = vec![0xDEAD_BEEF; tx.ticks_per_frame() + 3];
            tx.encode(&frames, &mut out).unwrap();
            prop_assert_eq!(&out[..tx.ticks_per_frame()], &reference(&tx, &map, words)[..]);
            prop_assert!(out[tx.ticks_per_frame()..].iter().all(|&w| w == 0xDEAD_BEEF));
            // The same words given directly, garbage on the lines without a pin.
            let direct = core::array::from_fn(|i| if data[i].is_some() { words[i] } else { values[i] });
            let mut out2 = vec![0x5555_AAAA; tx.ticks_per_frame() + 3];
            tx.encode_words(direct, &mut out2).unwrap();
            prop_assert_eq!(&out2[..tx.ticks_per_frame()], &out[..tx.ticks_per_frame()]);
            prop_assert!(out2[tx.ticks_per_frame()..].iter().all(|&w| w == 0x5555_AAAA));
            let short = tx.ticks_per_frame() - 1;
            prop_assert_eq!(
                tx.encode_words(direct, &mut out2[..short]),
                Err(TxError::BufferTooShort { needed: tx.ticks_per_frame(), got: short })
            );
        }
    }
}
