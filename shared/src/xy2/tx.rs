//! The XY2-100 line transmitter: frames -> BSRR words for the output DMA (layout item 4).
//!
//! # Output
//! A timer ticks at twice the bit clock and each tick DMAs one `u32` into the output
//! port's BSRR (low half sets pins, high half resets them). Every bit takes two ticks:
//!
//! | tick | CLK | SYNC, X, Y, Z |
//! |---|---|---|
//! | first | set (rising edge) | set or reset to the bit's level |
//! | second | reset (falling edge: the receiver samples here) | untouched |
//!
//! so data changes on the rising edge and is stable for half a bit before and after the
//! sampling edge (notes, "Timing"). SYNC goes high with bit 1 and low with bit 20.
//!
//! Each frame occupies a fixed number of ticks, `frame period / tick period`, at least
//! 40: 100 kHz frames at a 2 MHz bit clock (4 MHz ticks) are exactly 40 ticks, 20 bits
//! back to back; 200 kHz at 4 MHz is XY2-200. Ticks after the 40th are idle: CLK, SYNC
//! and data low, so the head sees no clock edge until the next frame (a gated clock).
//! The ring holds two halves of K frames; [`Transmitter::write_half`] fills a half,
//! [`Transmitter::write_frame`] one slot. Every bit's first word sets or resets every
//! line explicitly, so a slot never depends on what the previous slot left behind.
//!
//! # Cost
//! [`Transmitter::new`] precomputes the whole first word of a bit for each of the 8
//! patterns of one bit per data line (CLK and SYNC set, each data pin set or reset),
//! and from them a 64-entry table of the four words of two bit times (2 KiB). The
//! bit loop (`lanes`, shared with the XY3-100 transmitter) gathers the pattern
//! indices of eight bit times of the three lines at once, one look-up per line in a
//! 256-entry spreading table; per two bits it then extracts the 6-bit field of both
//! patterns and copies the table entry as one block (a load-multiple and a
//! store-multiple): no branches on the data, five instructions per two bits. Bit 20
//! additionally flips SYNC from set to reset. A missing Z line has no pin, so its
//! bit selects between identical entries. The frame checks and wire words
//! ([`Transmitter::write_frame`]) inline into the caller; only the fill is a call.
//! The bridge's head encoder (`bridge::head_out`) computes the wire words itself
//! and only fills ([`Transmitter::write_words`]). About 185 instructions per frame
//! of three lines on the Cortex-M7 (`cargo xtask qemu`), some 115 of them filling
//! the 40 words (125 with one look-up and two stores per bit).
//!
//! # Errors
//! A frame the link cannot carry ([`EncodeError`]) is never half-sent: its slot is filled
//! with idle words (the head sees no frame) and the error is returned.

use core::fmt;

use super::frame::{encode, EncodeError, Frame, LinkConfig, FRAME_BITS};
use super::rx::{check_pins, PinError};
use crate::model::Axis;

pub(crate) mod lanes;

/// Ticks the 20 bits of a frame take.
pub const FRAME_TICKS: usize = 2 * FRAME_BITS as usize;

/// Which output port bit drives which line (bit indices 0..15).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OutPinMap {
    /// CLK.
    pub clk: u8,
    /// SYNC.
    pub sync: u8,
    /// X data.
    pub x: u8,
    /// Y data.
    pub y: u8,
    /// Z data, if driven.
    pub z: Option<u8>,
}

/// The frames of one frame period, one per axis.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxFrame {
    /// X frame.
    pub x: Frame,
    /// Y frame.
    pub y: Frame,
    /// Z frame; `None` keeps Z low for the period (an all-zero word, which every
    /// receiver rejects by its header). Ignored without a Z pin.
    pub z: Option<Frame>,
}

/// Why the transmitter cannot be built or could not fill a buffer.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TxError {
    /// The pin map is unusable.
    Pins(PinError),
    /// Fewer ticks per frame than the 40 a frame needs.
    TicksPerFrame {
        /// The configured value.
        ticks: usize,
    },
    /// A slot or half-buffer has the wrong length for the frames given.
    Length {
        /// Words needed.
        expected: usize,
        /// Words given.
        got: usize,
    },
    /// A frame could not be encoded on this link; its slot was filled with idle.
    Encode {
        /// The axis whose frame failed.
        axis: Axis,
        /// Why.
        error: EncodeError,
    },
}

impl fmt::Display for TxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Pins(e) => write!(f, "output pins: {e}"),
            Self::TicksPerFrame { ticks } => {
                write!(f, "{ticks} ticks per frame, at least {FRAME_TICKS} needed")
            }
            Self::Length { expected, got } => {
                write!(f, "buffer of {got} words, {expected} needed")
            }
            Self::Encode { axis, error } => write!(f, "{axis:?} frame: {error}"),
        }
    }
}

/// The transmitter: precomputed masks plus the frame geometry (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Transmitter {
    link: LinkConfig,
    ticks: usize,
    has_z: bool,
    /// The words of two bit times per pair of patterns (`lanes::pair_patterns`):
    /// the first word of a bit sets CLK and SYNC and sets or resets the data lines
    /// (bit 0 of a pattern = X, bit 1 = Y, bit 2 = Z), the second resets CLK (the
    /// sampling edge).
    pairs: [[u32; lanes::ENTRY]; 64],
    /// XORed into bit 20's first word: SYNC reset instead of set.
    sync_drop: u32,
    /// Resets CLK, SYNC and the data lines.
    idle: u32,
}

impl Transmitter {
    /// A transmitter on `pins`, `ticks_per_frame` words per frame (at least 40).
    pub fn new(pins: OutPinMap, ticks_per_frame: usize, link: LinkConfig) -> Result<Self, TxError> {
        check_pins(&[
            Some(pins.clk),
            Some(pins.sync),
            Some(pins.x),
            Some(pins.y),
            pins.z,
        ])
        .map_err(TxError::Pins)?;
        if ticks_per_frame < FRAME_TICKS {
            return Err(TxError::TicksPerFrame {
                ticks: ticks_per_frame,
            });
        }
        let bit = |b: u8| 1u32 << b;
        let lanes = [bit(pins.x), bit(pins.y), pins.z.map_or(0, bit)];
        let data = lanes.iter().fold(0, |a, &m| a | m);
        let high = bit(pins.clk) | bit(pins.sync);
        Ok(Transmitter {
            link,
            ticks: ticks_per_frame,
            has_z: pins.z.is_some(),
            pairs: lanes::pair_patterns(&lanes::patterns(high, lanes), bit(pins.clk) << 16),
            sync_drop: bit(pins.sync) | bit(pins.sync) << 16,
            idle: (high | data) << 16,
        })
    }

    /// Words per frame slot.
    pub const fn ticks_per_frame(&self) -> usize {
        self.ticks
    }

    /// The link's mode and parity policy the frames are encoded with.
    pub const fn link(&self) -> LinkConfig {
        self.link
    }

    /// The idle word (CLK, SYNC and data low).
    pub const fn idle_word(&self) -> u32 {
        self.idle
    }

    /// Encodes `frame` into `slot` (exactly [`Self::ticks_per_frame`] words).
    #[inline(always)]
    pub fn write_frame(&self, slot: &mut [u32], frame: &TxFrame) -> Result<(), TxError> {
        self.check_len(slot, 1)?;
        match self.encode(frame) {
            Ok(words) => {
                self.fill(slot, words);
                Ok(())
            }
            Err(e) => {
                slot.fill(self.idle);
                Err(e)
            }
        }
    }

    /// Writes already encoded 20-bit words (X, Y, Z; Z ignored without a Z pin) into
    /// `slot` unchanged, e.g. to pass frames through. Bits above bit 19 are ignored.
    pub fn write_words(&self, slot: &mut [u32], words: [u32; 3]) -> Result<(), TxError> {
        self.check_len(slot, 1)?;
        self.fill(slot, words);
        Ok(())
    }

    /// Encodes one frame per slot into a half-buffer of `frames.len()` slots. A frame
    /// that fails to encode leaves its slot idle; the others are still written and the
    /// first error is returned.
    pub fn write_half(&self, half: &mut [u32], frames: &[TxFrame]) -> Result<(), TxError> {
        self.check_len(half, frames.len())?;
        let mut result = Ok(());
        for (slot, frame) in half.chunks_exact_mut(self.ticks).zip(frames) {
            if let Err(e) = self.write_frame(slot, frame) {
                result = result.and(Err(e));
            }
        }
        result
    }

    #[inline(always)]
    fn check_len(&self, buf: &[u32], frames: usize) -> Result<(), TxError> {
        let expected = self.ticks.saturating_mul(frames);
        if buf.len() == expected {
            Ok(())
        } else {
            Err(TxError::Length {
                expected,
                got: buf.len(),
            })
        }
    }

    #[inline(always)]
    fn encode(&self, frame: &TxFrame) -> Result<[u32; 3], TxError> {
        let enc = |axis, f| encode(f, &self.link).map_err(|error| TxError::Encode { axis, error });
        let z = match frame.z {
            Some(f) if self.has_z => enc(Axis::Z, f)?,
            _ => 0,
        };
        Ok([enc(Axis::X, frame.x)?, enc(Axis::Y, frame.y)?, z])
    }

    /// Writes the 40 bit words and the idle tail; `slot` has the right length. Out of
    /// line: it is the same for every caller, while the frame checks inline.
    #[inline(never)]
    fn fill(&self, slot: &mut [u32], [x, y, z]: [u32; 3]) {
        let Some((bits, tail)) = slot.split_first_chunk_mut::<FRAME_TICKS>() else {
            return;
        };
        // Often nothing (40-tick frames): skip the call of a zero-length fill.
        if !tail.is_empty() {
            tail.fill(self.idle);
        }
        // MSB-aligned: bit 19, the first on the wire, in bit 31.
        let align = 32 - FRAME_BITS;
        let lines = [x << align, y << align, z << align];
        lanes::fill_pairs::<{ FRAME_BITS as usize / 2 }, FRAME_TICKS>(&self.pairs, lines, bits);
        // Bit 20's first word: SYNC falls.
        if let Some(last) = bits.get_mut(FRAME_TICKS - 2) {
            *last ^= self.sync_drop;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// `fill` gives the words of the per-bit definition in the module docs, for
        /// random words on random pin maps (Z pin or not; bits above 19 ignored).
        #[test]
        fn fill_matches_the_per_bit_reference(
            words in any::<[u32; 3]>(),
            pins in Just([0u8, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15]).prop_shuffle(),
            with_z in any::<bool>(),
            extra in 0usize..5,
        ) {
            let map = OutPinMap {
                clk: pins[0],
                sync: pins[1],
                x: pins[2],
                y: pins[3],
                z: with_z.then_some(pins[4]),
            };
            let tx = Transmitter::new(map, FRAME_TICKS + extra, LinkConfig::default()).unwrap();
            let mut slot = vec![0u32; FRAME_TICKS + extra];
            tx.fill(&mut slot, words);
            let set = |p: u8| 1u32 << p;
            let reset = |p: u8| 1u32 << (p + 16);
            let level = |p: u8, on: bool| if on { set(p) } else { reset(p) };
            for (b, pair) in slot.chunks(2).take(20).enumerate() {
                let i = 19 - b as u32;
                let mut want = set(map.clk) | level(map.sync, i != 0);
                want |= level(map.x, words[0] >> i & 1 == 1) | level(map.y, words[1] >> i & 1 == 1);
                if let Some(z) = map.z {
                    want |= level(z, words[2] >> i & 1 == 1);
                }
                prop_assert_eq!(pair, &[want, reset(map.clk)][..], "bit {}", i);
            }
            for &w in &slot[FRAME_TICKS..] {
                prop_assert_eq!(w, tx.idle_word());
            }
        }
    }
}
