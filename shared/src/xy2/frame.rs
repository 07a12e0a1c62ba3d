//! The 20-bit forward frame: fields <-> wire word, with the per-link frame width and
//! parity policy (see the module docs of [`crate::xy2`] for the layout and decisions).

use core::fmt;

/// Number of bits in one frame.
pub const FRAME_BITS: u32 = 20;
/// The bits a frame word may use (right-aligned, bit 19 is sent first).
pub const FRAME_MASK: u32 = (1 << FRAME_BITS) - 1;
/// Number of distinct bit pairs in a frame, the denominator of
/// [`detected_double_errors`].
pub const BIT_PAIRS: u32 = FRAME_BITS * (FRAME_BITS - 1) / 2;

/// Header (bits 19..17) of a standard 16-bit position frame.
const HEADER_POSITION16: u32 = 0b001;
/// Header (bits 19..17) of an enhanced command frame.
const HEADER_COMMAND: u32 = 0b111;
/// Largest 18-bit position value.
const MAX_POSITION18: u32 = (1 << 18) - 1;

/// How a link interprets frame headers. The 18-bit header (bit 19 = 1) overlaps the
/// command header `111`, so a receiver cannot tell them apart: it is a link setting.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// XY2-100: 16-bit positions (`001`) and enhanced commands (`111`); the other six
    /// headers are reserved.
    #[default]
    Standard16,
    /// XY2-100E: 18-bit positions only (bit 19 = 1); a word with bit 19 = 0 is an error.
    Extended18,
}

/// Which bits the parity bit (bit 0) covers, per link. Never "accept either": that
/// would accept every word.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Parity {
    /// All 20 bits (header, data, parity): even for 16-bit positions and commands, odd
    /// for 18-bit positions.
    #[default]
    WholeFrame,
    /// The data bits and the parity bit, header excluded: even for 16-bit positions and
    /// commands (bits 16..0), odd for 18-bit positions (bits 18..0).
    DataOnly,
    /// Not checked on decode; encode emits [`Parity::WholeFrame`] parity.
    Ignore,
}

/// The per-link settings of the word codec.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkConfig {
    /// Header interpretation.
    pub mode: Mode,
    /// Parity scope.
    pub parity: Parity,
}

/// The kinds of frame, for error reports.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameKind {
    /// 16-bit position (`001`).
    Position16,
    /// 18-bit XY2-100E position (bit 19 = 1).
    Position18,
    /// Enhanced command (`111`).
    Command,
}

/// One decoded XY2-100 / XY2-100E frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Frame {
    /// Standard 16-bit position, offset binary (0x8000 = centre).
    Position16(u16),
    /// XY2-100E 18-bit position, offset binary (0x2_0000 = centre); must fit 18 bits.
    Position18(u32),
    /// Enhanced command frame.
    Command {
        /// Command byte (bits 16..9).
        command: u8,
        /// Parameter byte (bits 8..1).
        parameter: u8,
    },
}

impl Frame {
    /// The frame's kind.
    pub const fn kind(self) -> FrameKind {
        match self {
            Frame::Position16(_) => FrameKind::Position16,
            Frame::Position18(_) => FrameKind::Position18,
            Frame::Command { .. } => FrameKind::Command,
        }
    }
}

/// Why a frame cannot be encoded.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The link's mode cannot carry this kind of frame (18-bit positions need
    /// [`Mode::Extended18`], 16-bit positions and commands need [`Mode::Standard16`]).
    WrongMode {
        /// The frame's kind.
        kind: FrameKind,
        /// The link's mode.
        mode: Mode,
    },
    /// An 18-bit position value does not fit 18 bits.
    ValueTooWide {
        /// The offending value.
        value: u32,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::WrongMode { kind, mode } => {
                write!(f, "a {kind:?} frame cannot be sent on a {mode:?} link")
            }
            Self::ValueTooWide { value } => {
                write!(f, "position {value:#x} does not fit 18 bits")
            }
        }
    }
}

/// Why a word is not a valid frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// Bits above bit 19 are set: the word was not assembled from one 20-bit frame.
    TooWide {
        /// The offending word.
        word: u32,
    },
    /// The header (bits 19..17) is not defined in the link's mode: any header other
    /// than `001` and `111` in [`Mode::Standard16`], bit 19 = 0 in [`Mode::Extended18`].
    ReservedHeader {
        /// Bits 19..17 of the word.
        header: u8,
        /// The link's mode.
        mode: Mode,
    },
    /// The parity bit does not match the link's policy.
    Parity {
        /// The offending word.
        word: u32,
        /// The policy it was checked against.
        policy: Parity,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooWide { word } => write!(f, "word {word:#x} is wider than 20 bits"),
            Self::ReservedHeader { header, mode } => {
                write!(f, "header {header:03b} is reserved in {mode:?} mode")
            }
            Self::Parity { word, policy } => {
                write!(f, "parity error in {word:#07x} ({policy:?} policy)")
            }
        }
    }
}

/// The parity bit (0 or 1) a frame of `kind` needs under `policy`, computed from bits
/// 19..1 of `word` (bit 0 is ignored). [`Parity::Ignore`] emits whole-frame parity.
const fn parity_bit(word: u32, kind: FrameKind, policy: Parity) -> u32 {
    let scope = match (policy, kind) {
        (Parity::WholeFrame | Parity::Ignore, _) => 0xF_FFFE,
        (Parity::DataOnly, FrameKind::Position18) => 0x7_FFFE,
        (Parity::DataOnly, FrameKind::Position16 | FrameKind::Command) => 0x1_FFFE,
    };
    let ones = (word & scope).count_ones() & 1;
    match kind {
        // Even: the bit makes the number of ones in the scope even.
        FrameKind::Position16 | FrameKind::Command => ones,
        // Odd: the bit makes it odd.
        FrameKind::Position18 => ones ^ 1,
    }
}

/// Encodes `frame` as a right-aligned 20-bit word for a link configured as `config`.
pub fn encode(frame: Frame, config: &LinkConfig) -> Result<u32, EncodeError> {
    match (frame, config.mode) {
        (Frame::Position16(v), Mode::Standard16) => Ok(position16_word(v, config.parity)),
        (Frame::Command { command, parameter }, Mode::Standard16) => {
            let body = HEADER_COMMAND << 17 | u32::from(command) << 9 | u32::from(parameter) << 1;
            Ok(body | parity_bit(body, FrameKind::Command, config.parity))
        }
        (Frame::Position18(v), Mode::Extended18) if v > MAX_POSITION18 => {
            Err(EncodeError::ValueTooWide { value: v })
        }
        // As for 16-bit positions, the scopes differ in the parity bit alone.
        (Frame::Position18(v), Mode::Extended18) => {
            Ok(position_word::<18, true>(v) ^ u32::from(config.parity == Parity::DataOnly))
        }
        (f, mode) => Err(EncodeError::WrongMode {
            kind: f.kind(),
            mode,
        }),
    }
}

/// The word of a 16-bit position frame; infallible, so the STATUS word (which always
/// uses this layout) needs no error path.
pub(super) fn position16_word(value: u16, parity: Parity) -> u32 {
    // The two scopes differ by the header's one bit, i.e. in the parity bit alone.
    position_word::<16, true>(u32::from(value)) ^ u32::from(parity == Parity::DataOnly)
}

/// The word of a position frame of `BITS` (16 or 18) bits holding `value`, with the
/// parity of the whole frame (`WHOLE`, also what [`Parity::Ignore`] emits) or of the
/// data bits only. Bits of `value` above `BITS` are dropped; a caller that computes
/// `value` in a field of that width loses nothing, and the mask then folds away.
///
/// This is the one place the position layout is written down; it is built for the
/// hot path (the head encoder calls it per axis and frame): the value's bits lie in
/// every parity scope, so the parity bit is the value's parity XOR a constant (the
/// header's one set bit if the scope counts it, and 1 for the odd parity of 18-bit
/// positions), computed in a few XOR folds instead of a count.
#[inline(always)]
pub fn position_word<const BITS: u32, const WHOLE: bool>(value: u32) -> u32 {
    let value = value & ((1 << BITS) - 1);
    let (header, odd) = if BITS == 18 {
        (1 << 19, 1)
    } else {
        (HEADER_POSITION16 << 17, 0)
    };
    let flip = WHOLE as u32 ^ odd;
    // Parity of `value` by halving folds; for a constant `BITS` these are four or
    // five XORs with shifted operands and no constants.
    let mut folded = value;
    let mut half = 16;
    while half > 0 {
        if half < BITS {
            folded ^= folded >> half;
        }
        half >>= 1;
    }
    // The header lies above the value and `flip` in bit 0: one XOR sets both.
    (value << 1 | (folded & 1)) ^ (header | flip)
}

/// Decodes a right-aligned 20-bit word received on a link configured as `config`.
/// Checks, in order: width, header, parity.
pub fn decode(word: u32, config: &LinkConfig) -> Result<Frame, DecodeError> {
    if word & !FRAME_MASK != 0 {
        return Err(DecodeError::TooWide { word });
    }
    let header = word >> 17;
    let (kind, frame) = match (config.mode, header) {
        (Mode::Standard16, HEADER_POSITION16) => (
            FrameKind::Position16,
            // Bits 16..1: the mask makes the narrowing exact.
            Frame::Position16((word >> 1 & 0xFFFF) as u16),
        ),
        (Mode::Standard16, HEADER_COMMAND) => (
            FrameKind::Command,
            Frame::Command {
                command: (word >> 9 & 0xFF) as u8,
                parameter: (word >> 1 & 0xFF) as u8,
            },
        ),
        (Mode::Extended18, 0b100..=0b111) => (
            FrameKind::Position18,
            Frame::Position18(word >> 1 & MAX_POSITION18),
        ),
        (mode, _) => {
            return Err(DecodeError::ReservedHeader {
                // `word` fits 20 bits, so the header fits 3.
                header: (header & 0b111) as u8,
                mode,
            });
        }
    };
    if config.parity != Parity::Ignore && word & 1 != parity_bit(word, kind, config.parity) {
        return Err(DecodeError::Parity {
            word,
            policy: config.parity,
        });
    }
    Ok(frame)
}

/// How many of the [`BIT_PAIRS`] possible 2-bit errors of `word` `decode` rejects
/// under `config`: an exhaustive measure of the link's double-error detection, for
/// the project's notes (parity alone never sees an even number of flips; only the
/// header checks do).
pub fn detected_double_errors(word: u32, config: &LinkConfig) -> u32 {
    let mut detected = 0;
    for i in 0..FRAME_BITS {
        for j in (i + 1)..FRAME_BITS {
            if decode(word ^ (1 << i) ^ (1 << j), config).is_err() {
                detected += 1;
            }
        }
    }
    detected
}
