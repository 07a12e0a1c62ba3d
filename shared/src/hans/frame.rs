//! The HANS-100 word-level frame: three 20-bit words <-> the 125-bit line pattern
//! (HANS-100 spec "数据传输协议", sender items 1-2 and figure 1).
//!
//! A pattern is held in a `u128` with the first transmitted bit at bit 124 ("packed
//! MSB-first"); bits 127..125 are always zero. Layout, first bit sent first:
//!
//! | pattern bits | content |
//! |---|---|
//! | 124, 123 | start `0`, its complement `1` |
//! | 122..83 | DATA1 D19..D0, each followed by its complement |
//! | 82..43 | DATA2, same |
//! | 42..3 | DATA3, same |
//! | 2..0 | three stop `1`s, not complemented |

/// Number of bits in one frame on the line (10 us at 12.5 MHz).
pub const FRAME_BITS: usize = 125;

/// Largest value of a 20-bit data word.
pub const WORD_MAX: u32 = 0xF_FFFF;

/// The start pair as sent: `0` then its complement `1`.
const START_PAIR: u8 = 0b01;
/// The three stop bits.
const STOP_BITS: u8 = 0b111;
/// Bit offsets (in the `u128` pattern) of the 40-bit fields of DATA1, DATA2, DATA3.
const WORD_SHIFTS: [u32; 3] = [83, 43, 3];
/// The complement bit of every pair of a 40-bit line field (bit 2i for D_i).
const PAIR_LOW_BITS: u64 = 0x55_5555_5555;
/// The low (complement) bit of the start pair and of every data pair: the odd bits
/// 3..=123 of the pattern.
const PAIRS_AND_START: u128 = 0x0AAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAAA_AAA8;
/// The pattern bits with a fixed value: padding 127..125 and the start bit 124 (0),
/// the stop bits 2..0 (1).
const FIXED: u128 = 0xF << 124 | STOP_BITS as u128;
/// The 125 pattern bits, left-aligned in 128 (used for byte packing).
const ALIGNED_MASK: u128 = !0 << 3;

/// Why three words cannot form a frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// A data word does not fit 20 bits.
    TooWide {
        /// Which word: 1 = DATA1, 2 = DATA2, 3 = DATA3.
        word: u8,
        /// The offending value.
        value: u32,
    },
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::TooWide { word, value } => {
                write!(
                    f,
                    "HANS-100 DATA{word} value {value:#x} does not fit 20 bits"
                )
            }
        }
    }
}

/// Why a pattern or byte string is not a valid frame. The first failing check in
/// transmission order is reported.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// Byte input was not exactly 16 bytes long.
    Length {
        /// The length received.
        got: usize,
    },
    /// The requested bit range does not lie inside the buffer.
    OutOfBuffer {
        /// First bit of the requested frame.
        bit_offset: usize,
        /// Buffer length in bytes.
        buf_bytes: usize,
    },
    /// Bits outside the 125-bit pattern (u128 bits 127..125, or the 3 trailing bits
    /// of the 16-byte form) were not zero.
    Padding {
        /// The three padding bits, the first of them (u128 bit 127, or byte 15 bit 2)
        /// in bit 2.
        got: u8,
    },
    /// The start pair was not `0 1`.
    StartPair {
        /// The two bits as received, first bit in bit 1.
        got: u8,
    },
    /// A data bit was not followed by its complement.
    Complement {
        /// Which word: 1..=3 for DATA1..DATA3.
        word: u8,
        /// Which bit of the word, 19..=0 (D19 is sent first).
        bit: u8,
    },
    /// The three stop bits were not all `1`.
    StopBits {
        /// The three bits as received, first bit in bit 2.
        got: u8,
    },
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Length { got } => write!(f, "HANS-100 frame needs 16 bytes, got {got}"),
            Self::OutOfBuffer {
                bit_offset,
                buf_bytes,
            } => write!(
                f,
                "HANS-100 frame at bit {bit_offset} does not fit a {buf_bytes}-byte buffer"
            ),
            Self::Padding { got } => write!(f, "HANS-100 padding bits {got:#05b} not zero"),
            Self::StartPair { got } => write!(f, "HANS-100 start pair {got:#04b}, want 0b01"),
            Self::Complement { word, bit } => {
                write!(
                    f,
                    "HANS-100 DATA{word} D{bit} not followed by its complement"
                )
            }
            Self::StopBits { got } => write!(f, "HANS-100 stop bits {got:#05b}, want 0b111"),
        }
    }
}

/// One HANS-100 frame: three 20-bit data words. Forward (controller -> head) DATA1 is
/// X, DATA2 is Y and DATA3 is Z or laser control; on STATUS the words carry the
/// extension codes of [`super::status`] and [`super::ext`].
///
/// The fields are private so every `Frame` holds 20-bit words: the width check
/// happens once in [`Frame::new`], and encoding can never fail afterwards.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame {
    data1: u32,
    data2: u32,
    data3: u32,
}

/// Moves bit i of the low 16 bits of `x` to bit 2i (shift-and-mask interleave in
/// 32-bit arithmetic: on the M7 each step is one OR with a shifted operand and one
/// mask whose constant is an immediate; a 64-bit version costs two or three per
/// step, and this runs for every transmitted frame).
fn spread16(x: u32) -> u32 {
    let mut v = x & 0xFFFF;
    v = (v | v << 8) & 0x00FF_00FF;
    v = (v | v << 4) & 0x0F0F_0F0F;
    v = (v | v << 2) & 0x3333_3333;
    (v | v << 1) & 0x5555_5555
}

/// [`spread16`] for the low 4 bits of `x`.
fn spread4(x: u32) -> u32 {
    let mut v = x & 0xF;
    v = (v | v << 2) & 0x33;
    (v | v << 1) & 0x55
}

/// Gathers bits 0, 2, 4, … 62 into bits 0..32 (the inverse of an interleave).
fn gather_even(field: u64) -> u32 {
    let mut v = field & 0x5555_5555_5555_5555;
    v = (v | v >> 1) & 0x3333_3333_3333_3333;
    v = (v | v >> 2) & 0x0F0F_0F0F_0F0F_0F0F;
    v = (v | v >> 4) & 0x00FF_00FF_00FF_00FF;
    v = (v | v >> 8) & 0x0000_FFFF_0000_FFFF;
    // Truncation intended: the gathered bits fit 32 bits.
    (v | v >> 16) as u32
}

/// The 40-bit line field of a 20-bit word: D19 at bit 39, its complement at bit 38,
/// … D0 at bit 1, its complement at bit 0.
fn spread_pairs(x: u32) -> u64 {
    let data = u64::from(spread4(x >> 16)) << 32 | u64::from(spread16(x));
    // The complements are the even bits of the inverted data: `!x` spread is the
    // all-pairs mask minus `x` spread, so one interleave serves both.
    data << 1 | (data ^ 0x55_5555_5555)
}

impl Frame {
    /// The centre of the field on X and Y with DATA3 = code 0, Z centre (`0x8000`):
    /// a harmless first frame for a transmitter that has nothing better yet.
    pub const CENTRE: Frame = Frame {
        data1: 0x8_0000,
        data2: 0x8_0000,
        data3: 0x8_0000,
    };

    /// A frame from three words, each checked to fit 20 bits.
    pub const fn new(data1: u32, data2: u32, data3: u32) -> Result<Frame, EncodeError> {
        if data1 > WORD_MAX {
            return Err(EncodeError::TooWide {
                word: 1,
                value: data1,
            });
        }
        if data2 > WORD_MAX {
            return Err(EncodeError::TooWide {
                word: 2,
                value: data2,
            });
        }
        if data3 > WORD_MAX {
            return Err(EncodeError::TooWide {
                word: 3,
                value: data3,
            });
        }
        Ok(Frame {
            data1,
            data2,
            data3,
        })
    }

    /// DATA1 (forward: X).
    pub const fn data1(&self) -> u32 {
        self.data1
    }

    /// DATA2 (forward: Y).
    pub const fn data2(&self) -> u32 {
        self.data2
    }

    /// DATA3 (forward: Z or laser control, see [`super::ext`]).
    pub const fn data3(&self) -> u32 {
        self.data3
    }

    /// The three words in order DATA1, DATA2, DATA3.
    pub const fn words(&self) -> [u32; 3] {
        [self.data1, self.data2, self.data3]
    }

    /// The 125-bit line pattern, first transmitted bit at bit 124.
    pub fn encode(&self) -> u128 {
        self.pattern()
    }

    /// [`Frame::encode`], inlined so that [`Frame::write_at`]'s shift of the
    /// pattern folds into the placement of the three fields.
    #[inline(always)]
    fn pattern(&self) -> u128 {
        let mut p = u128::from(START_PAIR) << 123 | u128::from(STOP_BITS);
        for (word, shift) in self.words().into_iter().zip(WORD_SHIFTS) {
            p |= u128::from(spread_pairs(word)) << shift;
        }
        p
    }

    /// Decodes an aligned 125-bit pattern (first bit at bit 124), checking the padding,
    /// the start pair, all 60 complement pairs and the stop bits, in that order.
    pub fn decode(pattern: u128) -> Result<Frame, DecodeError> {
        // Every receiver checks every frame, and nearly all of them are valid: one
        // word-wise test of the whole pattern decides, and only a pattern that fails
        // it goes through the checks one by one to name the first failing one.
        // The start pair is a complement pair too (`0` then `1`), so a pair is right
        // at every odd bit 3..=123 where the bit and the one above it differ; bits
        // 127..124 (padding, start bit) are 0 and bits 2..0 (stop) are 1.
        let differ = pattern ^ pattern >> 1;
        let wrong = (!differ & PAIRS_AND_START) | (pattern ^ STOP_BITS as u128) & FIXED;
        if wrong != 0 {
            return Frame::decode_checked(pattern);
        }
        // Truncations intended: the data bits of a valid pattern are its even bits
        // 4..=122, gathered from each 64-bit half (bits 124 and 126 are then zero).
        let low = gather_even(pattern as u64);
        let high = gather_even((pattern >> 64) as u64);
        Ok(Frame {
            // D_i of DATA1 at bit 84 + 2i, gathered bit 10 + i of `high`.
            data1: high >> 10 & WORD_MAX,
            // D_i of DATA2 at bit 44 + 2i: D0..D9 in `low` from bit 22, D10..D19 in
            // `high` from bit 0.
            data2: (low >> 22 | high << 10) & WORD_MAX,
            // D_i of DATA3 at bit 4 + 2i, gathered bit 2 + i of `low`.
            data3: low >> 2 & WORD_MAX,
        })
    }

    /// [`Frame::decode`] check by check, in transmission order, to name the first
    /// failing check of a pattern the word-wise test rejected.
    #[cold]
    #[inline(never)]
    fn decode_checked(pattern: u128) -> Result<Frame, DecodeError> {
        // Truncations below are intended: the values are masked to 2 or 3 bits.
        let padding = (pattern >> FRAME_BITS) as u8;
        if padding != 0 {
            return Err(DecodeError::Padding { got: padding });
        }
        let start = ((pattern >> 123) & 0b11) as u8;
        if start != START_PAIR {
            return Err(DecodeError::StartPair { got: start });
        }
        let mut words = [0u32; 3];
        for ((slot, shift), word) in words.iter_mut().zip(WORD_SHIFTS).zip(1u8..) {
            let field = ((pattern >> shift) as u64) & ((1 << 40) - 1);
            // A pair is bad where data and complement are equal: bit 2i of `bad`
            // for the pair of D_i (checked in place, so only the data bits are
            // gathered, and only once every pair passed).
            let bad = !(field ^ field >> 1) & PAIR_LOW_BITS;
            if bad != 0 {
                // The highest bad pair is the first one on the line.
                let bit = ((63 - bad.leading_zeros()) / 2) as u8;
                return Err(DecodeError::Complement { word, bit });
            }
            *slot = gather_even(field >> 1);
        }
        let stop = (pattern & 0b111) as u8;
        if stop != STOP_BITS {
            return Err(DecodeError::StopBits { got: stop });
        }
        let [data1, data2, data3] = words;
        Ok(Frame {
            data1,
            data2,
            data3,
        })
    }

    /// The pattern as 16 bytes, MSB first; the 3 trailing bits are zero.
    pub fn to_bytes(&self) -> [u8; 16] {
        (self.encode() << 3).to_be_bytes()
    }

    /// Decodes the 16-byte form of [`Frame::to_bytes`] (trailing 3 bits must be zero).
    pub fn from_bytes(bytes: &[u8]) -> Result<Frame, DecodeError> {
        let arr: [u8; 16] = bytes
            .try_into()
            .map_err(|_| DecodeError::Length { got: bytes.len() })?;
        let v = u128::from_be_bytes(arr);
        // Move the padding to the top so `decode` checks it.
        Frame::decode(v.rotate_right(3))
    }

    /// Writes the frame into a packed MSB-first bit stream so that its first bit is
    /// stream bit `bit_offset` (bit 7 of byte 0 is stream bit 0). Only the frame's 125
    /// bits are touched; neighbouring bits in shared boundary bytes keep their value.
    /// The only possible error is [`DecodeError::OutOfBuffer`].
    pub fn write_at(&self, buf: &mut [u8], bit_offset: usize) -> Result<(), DecodeError> {
        let buf_bytes = buf.len();
        let (first, sub, _) = span(buf_bytes, bit_offset)?;
        let out_of_buffer = DecodeError::OutOfBuffer {
            bit_offset,
            buf_bytes,
        };
        // The frame covers the 16 bytes from `first` (shifted right by `sub`), plus
        // the top `sub - 3` bits of a 17th byte when `sub` > 3. The shift and the
        // read-modify-write run on four big-endian u32 words (a variable u128 shift
        // costs several times more on the M7); only the boundary words get partial
        // masks, the middle ones are replaced.
        let value = self.pattern() << 3;
        let head = buf.get_mut(first..first + 16).ok_or(out_of_buffer)?;
        // `sub` < 8: shifting by `(x << 1) << (31 - sub)` brings in the neighbour
        // word's low bits without a 32-bit shift when `sub` is 0.
        let sub = sub as u32;
        let carry = |w: u32| (w << 1) << (31 - sub);
        // Truncations intended: the four 32-bit words of the value, top first.
        let [v0, v1, v2, v3] = [96, 64, 32, 0].map(|k| (value >> k) as u32);
        let new = [
            v0 >> sub,
            v1 >> sub | carry(v0),
            v2 >> sub | carry(v1),
            v3 >> sub | carry(v2),
        ];
        // Bits of the frame in each word: all but the first `sub` of word 0, and in
        // word 3 down to stream bit 125 (bit `3 - sub` of the word, if `sub` < 3).
        let masks = [!0 >> sub, !0, !0, !0u32 << 3u32.saturating_sub(sub)];
        for ((chunk, new), mask) in head.chunks_exact_mut(4).zip(new).zip(masks) {
            let Ok(bytes) = <&mut [u8; 4]>::try_from(chunk) else {
                return Err(out_of_buffer);
            };
            let old = u32::from_be_bytes(*bytes);
            *bytes = (old & !mask | new & mask).to_be_bytes();
        }
        if sub > 3 {
            let tail = buf.get_mut(first + 16).ok_or(out_of_buffer)?;
            // Truncation intended: the low `sub` bits of the value, left-aligned.
            let bits = (v3 as u8) << (8 - sub);
            let mask = 0xF8u8 << (8 - sub);
            *tail = (*tail & !mask) | (bits & mask);
        }
        Ok(())
    }

    /// Reads and decodes the frame whose first bit is stream bit `bit_offset` of a
    /// packed MSB-first bit stream (the inverse of [`Frame::write_at`]).
    pub fn read_at(buf: &[u8], bit_offset: usize) -> Result<Frame, DecodeError> {
        let (first, sub, bytes) = span(buf.len(), bit_offset)?;
        let window = buf
            .get(first..first + bytes)
            .ok_or(DecodeError::OutOfBuffer {
                bit_offset,
                buf_bytes: buf.len(),
            })?;
        let mut value = 0u128;
        for (j, &byte) in window.iter().enumerate() {
            let k = 8 * j as i32 - sub as i32;
            // Place the byte's bit 7 at aligned position 127 - k; bits falling
            // outside 0..128 belong to the neighbours and are shifted out.
            let b = u128::from(byte) << 120;
            value |= if k >= 0 {
                b.checked_shr(k as u32).unwrap_or(0)
            } else {
                b.checked_shl((-k) as u32).unwrap_or(0)
            };
        }
        Frame::decode((value & ALIGNED_MASK) >> 3)
    }
}

/// The byte range a frame starting at `bit_offset` occupies in a `len`-byte buffer:
/// (first byte, bit offset inside it, number of bytes).
fn span(len: usize, bit_offset: usize) -> Result<(usize, usize, usize), DecodeError> {
    let end = bit_offset.checked_add(FRAME_BITS);
    match end {
        Some(end) if end <= len.saturating_mul(8) => {
            let first = bit_offset / 8;
            let sub = bit_offset % 8;
            Ok((first, sub, (sub + FRAME_BITS).div_ceil(8)))
        }
        _ => Err(DecodeError::OutOfBuffer {
            bit_offset,
            buf_bytes: len,
        }),
    }
}

/// Number of frame slots in the HANS-100 transmit ring (layout item 5).
pub const RING_SLOTS: usize = 8;

/// Length of the HANS-100 transmit ring: 8 frames x 125 bits = 1000 bits.
pub const RING_BYTES: usize = 125;

/// Writes `frame` into slot `slot` (0..8) of the transmit ring, touching only that
/// slot's bits 125·slot .. 125·slot+124 (layout item 5).
pub fn write_slot(
    buf: &mut [u8; RING_BYTES],
    slot: usize,
    frame: &Frame,
) -> Result<(), DecodeError> {
    frame.write_at(buf, slot_offset(slot)?)
}

/// Reads and decodes slot `slot` (0..8) of a transmit ring.
pub fn read_slot(buf: &[u8; RING_BYTES], slot: usize) -> Result<Frame, DecodeError> {
    Frame::read_at(buf, slot_offset(slot)?)
}

fn slot_offset(slot: usize) -> Result<usize, DecodeError> {
    if slot < RING_SLOTS {
        Ok(slot * FRAME_BITS)
    } else {
        Err(DecodeError::OutOfBuffer {
            bit_offset: slot.saturating_mul(FRAME_BITS),
            buf_bytes: RING_BYTES,
        })
    }
}

/// Sets slot `slot` (0..8) of the transmit ring to zero bits, touching only that
/// slot's bits (a bit-level write: slots 3 and 4, 7 and 0 share no byte, but the
/// ring's halves of 62.5 bytes split slots 3 / 4 inside byte 62, where the other
/// slot may hold a frame just written). Zero bits carry no start marker: a
/// receiver decodes no frame from a blanked slot (the ring guard,
/// `bridge::slot_guard`).
pub fn blank_slot(buf: &mut [u8; RING_BYTES], slot: usize) -> Result<(), DecodeError> {
    let start = slot_offset(slot)?;
    let end = start + FRAME_BITS;
    let (first, last) = (start / 8, (end - 1) / 8);
    // The slot's bits in its first and last bytes (MSB first: stream bit 8i is
    // bit 7 of byte i); the bytes between are wholly its own. Whole bytes and two
    // masks, not a mask per byte: the guard blanks a slot every 10 us at P0.
    let head = 0xFFu8 >> (start % 8);
    let tail = 0xFFu8 << (7 - (end - 1) % 8);
    match buf.get_mut(first..=last) {
        Some([a, middle @ .., b]) => {
            *a &= !head;
            middle.fill(0);
            *b &= !tail;
            Ok(())
        }
        // Unreachable: `slot_offset` checked the slot, and a slot spans 16 bytes.
        _ => Err(DecodeError::OutOfBuffer {
            bit_offset: start,
            buf_bytes: RING_BYTES,
        }),
    }
}
