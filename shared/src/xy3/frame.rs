//! XY3-100 forward frame codec: one channel's wire word <-> [`Frame`] (XY3-100 §5.1).
//!
//! A wire word is a `u32` holding the frame right-aligned: bit 23 (24-bit frame) or
//! bit 31 (32-bit frame) is the first bit on the line. See the parent module docs for
//! the layout and for what the parity can and cannot detect.

use core::fmt;

/// Widest position field of a 24-bit frame (D19..D0).
const POS24_BITS: u8 = 20;
/// Widest position field of a 32-bit frame (D25..D0).
const POS32_BITS: u8 = 26;
/// Width of a command code (C19..C0) in either frame size.
pub const CODE_BITS: u8 = 20;
/// Width of the ignored bits 29..24 of a 32-bit command frame.
const UNUSED_BITS: u8 = 6;

/// The two frame lengths XY3-100 defines (§5.1); the first bit on the line tells them
/// apart.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameSize {
    /// 24-bit frame (first bit 0): 20 data bits, 2 parity bits.
    Bits24,
    /// 32-bit frame (first bit 1): 26 data bits (or 6 ignored + 20 command bits),
    /// 4 parity bits.
    Bits32,
}

impl FrameSize {
    /// The frame size the first bit on the line announces, so that a streaming
    /// receiver knows how many bits to collect after it (§5.1: 0 = 24, 1 = 32 bits).
    pub const fn from_first_bit(first_bit: bool) -> FrameSize {
        if first_bit {
            FrameSize::Bits32
        } else {
            FrameSize::Bits24
        }
    }

    /// The first bit a frame of this size starts with.
    pub const fn first_bit(self) -> bool {
        matches!(self, FrameSize::Bits32)
    }

    /// Total frame length in bits (24 or 32).
    pub const fn bits(self) -> u8 {
        match self {
            FrameSize::Bits24 => 24,
            FrameSize::Bits32 => 32,
        }
    }

    /// Width of the position field (20 or 26 bits).
    pub const fn position_bits(self) -> u8 {
        match self {
            FrameSize::Bits24 => POS24_BITS,
            FrameSize::Bits32 => POS32_BITS,
        }
    }

    /// Number of parity bits at the end of the frame (2 or 4).
    const fn parity_bits(self) -> u8 {
        match self {
            FrameSize::Bits24 => 2,
            FrameSize::Bits32 => 4,
        }
    }

    /// Mask of the parity-counted field after shifting out the parity bits: 20 bits
    /// (24-bit frames) or 26 bits (32-bit frames, command frames' ignored bits
    /// included).
    const fn counted_mask(self) -> u32 {
        (1u32 << self.position_bits()) - 1
    }
}

/// One decoded XY3-100 forward frame of one channel.
///
/// Fields are plain numbers so that any frame can be written down; [`encode`] rejects
/// fields wider than their place in the word.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Frame {
    /// 24-bit position frame: D19..D0, offset binary.
    Position24(u32),
    /// 32-bit position frame: D25..D0, offset binary.
    Position32(u32),
    /// 24-bit command frame: the 20-bit command code.
    Command24(u32),
    /// 32-bit command frame.
    Command32 {
        /// The 20-bit command code.
        code: u32,
        /// Bits 29..24: without meaning, but counted by the parity. We send 0 and keep
        /// what we received so that a round trip is exact.
        unused: u8,
    },
}

impl Frame {
    /// The size this frame is sent with.
    pub const fn size(&self) -> FrameSize {
        match self {
            Frame::Position24(_) | Frame::Command24(_) => FrameSize::Bits24,
            Frame::Position32(_) | Frame::Command32 { .. } => FrameSize::Bits32,
        }
    }

    /// Whether this is a position frame (second bit 1).
    pub const fn is_position(&self) -> bool {
        matches!(self, Frame::Position24(_) | Frame::Position32(_))
    }
}

/// Why a [`Frame`] cannot be encoded.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// A position value does not fit the frame's position field.
    PositionTooWide {
        /// The offending value.
        value: u32,
        /// The field width (20 or 26).
        bits: u8,
    },
    /// A command code does not fit 20 bits.
    CodeTooWide(u32),
    /// The ignored bits of a 32-bit command frame do not fit 6 bits.
    UnusedTooWide(u8),
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::PositionTooWide { value, bits } => {
                write!(f, "position {value:#x} does not fit {bits} bits")
            }
            Self::CodeTooWide(c) => write!(f, "command code {c:#x} does not fit 20 bits"),
            Self::UnusedTooWide(u) => write!(f, "unused bits {u:#x} do not fit 6 bits"),
        }
    }
}

/// Why a wire word is not a valid frame. Every variant means: do not use this frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// The word has bits set above the frame the receiver collected.
    WordTooWide {
        /// The received word.
        word: u32,
        /// The size the receiver's framing gave.
        size: FrameSize,
    },
    /// The first bit announces the other frame size than the receiver collected.
    SizeMismatch {
        /// The size the receiver's framing gave.
        framed: FrameSize,
        /// The size the first bit announces.
        announced: FrameSize,
    },
    /// The parity bits do not match the count of ones in the data bits.
    Parity {
        /// Parity computed from the received data bits.
        expected: u8,
        /// Parity bits received.
        got: u8,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::WordTooWide { word, size } => {
                write!(f, "word {word:#x} wider than {} bits", size.bits())
            }
            Self::SizeMismatch { framed, announced } => write!(
                f,
                "received {} bits but first bit announces {}",
                framed.bits(),
                announced.bits()
            ),
            Self::Parity { expected, got } => {
                write!(f, "parity mismatch: expected {expected:#x}, got {got:#x}")
            }
        }
    }
}

/// The parity of a counted field: its number of ones, keeping the low 2 or 4 bits.
const fn parity(counted: u32, size: FrameSize) -> u32 {
    counted.count_ones() & ((1 << size.parity_bits()) - 1)
}

/// Assembles a word from its fields; `counted` must already fit its field.
const fn assemble(size: FrameSize, position: bool, counted: u32) -> u32 {
    let top = size.bits() as u32 - 1;
    let size_bit = (size.first_bit() as u32) << top;
    let mode_bit = (position as u32) << (top - 1);
    size_bit | mode_bit | counted << size.parity_bits() | parity(counted, size)
}

/// Checks that `value` fits `bits` bits.
const fn fits(value: u32, bits: u8) -> bool {
    value >> bits == 0
}

/// Encodes a frame into its wire word (right-aligned, first bit on the line = bit 23
/// or 31) and returns the word together with its size.
///
/// Each variant's arm names its size as a constant, so the shifts and masks fold
/// (the transmitter encodes up to five of these per frame period).
pub const fn encode(frame: &Frame) -> Result<(u32, FrameSize), EncodeError> {
    match *frame {
        Frame::Position24(value) => position_word(value, FrameSize::Bits24),
        Frame::Position32(value) => position_word(value, FrameSize::Bits32),
        Frame::Command24(code) => {
            if !fits(code, CODE_BITS) {
                return Err(EncodeError::CodeTooWide(code));
            }
            let size = FrameSize::Bits24;
            Ok((assemble(size, false, code), size))
        }
        Frame::Command32 { code, unused } => {
            if !fits(code, CODE_BITS) {
                return Err(EncodeError::CodeTooWide(code));
            }
            if unused >> UNUSED_BITS != 0 {
                return Err(EncodeError::UnusedTooWide(unused));
            }
            let size = FrameSize::Bits32;
            Ok((
                assemble(size, false, (unused as u32) << CODE_BITS | code),
                size,
            ))
        }
    }
}

/// The word of a position frame of `size`.
#[inline(always)]
const fn position_word(value: u32, size: FrameSize) -> Result<(u32, FrameSize), EncodeError> {
    let bits = size.position_bits();
    if !fits(value, bits) {
        return Err(EncodeError::PositionTooWide { value, bits });
    }
    Ok((assemble(size, true, value), size))
}

/// The word of a position frame of `size` holding the low
/// [`FrameSize::position_bits`] of `value` (bits above are dropped). For a hot path
/// that computes `value` in a field of that width (the head encoder, per axis and
/// frame): with a constant `size` the layout folds to a shift, an OR of the size and
/// mode bits and a count of ones, and the mask folds away.
#[inline(always)]
pub const fn position_bits_word(value: u32, size: FrameSize) -> u32 {
    assemble(size, true, value & size.counted_mask())
}

/// Decodes one channel's wire word of the size the receiver's framing gave (the number
/// of clocks inside the SYNC-low window, or [`FrameSize::from_first_bit`] for a
/// streaming receiver).
///
/// Checks, in this order: no bits above the frame, first bit agrees with `size`,
/// parity. A frame that fails any check is rejected, never partly used.
pub const fn decode(word: u32, size: FrameSize) -> Result<Frame, DecodeError> {
    let top = size.bits() as u32 - 1;
    if size.bits() < 32 && word >> size.bits() != 0 {
        return Err(DecodeError::WordTooWide { word, size });
    }
    let announced = FrameSize::from_first_bit(word >> top & 1 == 1);
    if !matches!(
        (announced, size),
        (FrameSize::Bits24, FrameSize::Bits24) | (FrameSize::Bits32, FrameSize::Bits32)
    ) {
        return Err(DecodeError::SizeMismatch {
            framed: size,
            announced,
        });
    }
    let position = word >> (top - 1) & 1 == 1;
    let counted = word >> size.parity_bits() & size.counted_mask();
    let got = word & ((1 << size.parity_bits()) - 1);
    let expected = parity(counted, size);
    if got != expected {
        // Both values are < 16, the casts cannot truncate.
        return Err(DecodeError::Parity {
            expected: expected as u8,
            got: got as u8,
        });
    }
    let code = counted & ((1 << CODE_BITS) - 1);
    Ok(match (size, position) {
        (FrameSize::Bits24, true) => Frame::Position24(counted),
        (FrameSize::Bits32, true) => Frame::Position32(counted),
        (FrameSize::Bits24, false) => Frame::Command24(code),
        (FrameSize::Bits32, false) => Frame::Command32 {
            code,
            // 6 bits after the shift, the cast cannot truncate.
            unused: (counted >> CODE_BITS) as u8,
        },
    })
}
