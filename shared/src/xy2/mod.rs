//! XY2-100 and XY2-100E: the word-level codec (frames, STATUS, neutral conversions).
//!
//! There is no XY2-100 standard document; `shared/spec/xy2-100-notes.md` collects the
//! public sources and the project's defaults. In short:
//!
//! # Frames (notes, "Frame types")
//! Every frame is 20 bits, sent MSB (bit 19) first; SYNC marks the frame. Here a frame is
//! a `u32` with the 20 bits right-aligned (bit 19 of the frame = bit 19 of the word).
//!
//! | bits 19..17 | frame | bits 16..1 (18..1) | bit 0 |
//! |---|---|---|---|
//! | `001` | 16-bit position | D15..D0 | parity, even |
//! | `1xx` | XY2-100E 18-bit position | D17..D0 in bits 18..1 | parity, odd |
//! | `111` | enhanced command | command (16..9), parameter (8..1) | parity, even |
//!
//! Positions are offset binary (0 = one end, 0x8000 / 0x2_0000 = centre). The 18-bit
//! header overlaps the command header, so a link is configured with a [`Mode`]:
//! [`Mode::Standard16`] (16-bit positions + commands, default; headers `000`, `010`,
//! `011`, `100`, `101`, `110` are reserved and rejected) or [`Mode::Extended18`]
//! (18-bit positions only; bit 19 = 0 is rejected). A link never accepts both.
//!
//! # Parity (our decisions; notes, "Conflicts to handle")
//! [`Parity`] is a per-link setting; "accept either" would accept every word.
//! - [`Parity::WholeFrame`] (default): 16-bit positions and commands make all 20 bits
//!   even; 18-bit positions make all 20 bits **odd**. We read the 18-bit "odd" with the
//!   same scope as the 16-bit "even" so that one policy means one scope for every frame
//!   type, and so the two policies differ, for every frame type, by exactly the header's
//!   ones (a head using the other convention is served by switching the policy).
//!   Beware: since the 18-bit header is a single one, our 18-bit DataOnly (odd over
//!   bits 18..0) equals *even* parity over all 20 bits, so a head that simply applies
//!   the 16-bit whole-frame rule to 18-bit frames needs [`Parity::DataOnly`].
//! - [`Parity::DataOnly`]: the parity bit covers the data bits only (bits 16..1 for
//!   16-bit positions and commands, even; bits 18..1 for 18-bit positions, odd).
//!   Because `001` and `111` hold an odd number of ones and the 18-bit header one, this
//!   is always the complement of the whole-frame bit.
//! - [`Parity::Ignore`]: not checked on decode (the header is still checked); encode
//!   emits whole-frame parity.
//!
//! # Error detection
//! Under [`Parity::WholeFrame`] and [`Parity::DataOnly`] every single-bit error is
//! detected in both modes. A flip of a data or parity bit breaks parity under both
//! policies. A flip of a header bit is rejected by the header check alone: in
//! Standard16 the two valid headers `001` and `111` are two flips apart, so one flip
//! always yields a reserved header; in Extended18 the header is bit 19 only, and
//! clearing it is rejected (under WholeFrame parity breaks too). Under
//! [`Parity::Ignore`] exactly the flips of the bits below the header (16..0 in
//! Standard16, 18..0 in Extended18) go undetected; header flips are still rejected.
//! No 2-bit error is seen by parity; only those that produce a rejected header are
//! caught ([`detected_double_errors`] measures it: 53 of 190 pairs in Standard16 —
//! every pair touching the header except bits 19 + 18, which turns `001` into `111`
//! and back — and 19 of 190 in Extended18, whatever the parity policy).
//!
//! # STATUS (notes, "STATUS")
//! Two of the three field behaviours are codecs here (the third, XY2-100E selectable
//! data, is a pass-through concern):
//! - a level, [`StatusLevel`], with configurable [`Polarity`] (default low = OK);
//! - the SCANLAB-style [`StatusWord`]: two equal bytes, per byte bit 7 supplies OK,
//!   bit 6 temperature OK, bit 3 / 4 position acknowledge X / Y, bits 0, 2, 5 = 1 and
//!   bit 1 = 0 (all OK = `0xFDFD`). **Our decision:** the 20-bit frame carrying it on
//!   the STATUS line uses the standard 16-bit layout (`001`, word, parity per the
//!   link's policy) in either mode, because the sources describe a 16-bit word clocked
//!   like a 16-bit position frame.
//!
//! # Line level
//! [`rx`] turns the input port samples (one per CLK falling edge) into frame periods,
//! [`tx`] fills the output DMA ring with BSRR words, and [`status_line`] handles the
//! STATUS line in both forms and directions; all are sans-IO.
//!
//! # Neutral model
//! See [`AxisItem`], [`Frame::to_model`], [`Frame::from_position`],
//! [`StatusWord::alarms`], [`StatusWord::from_alarms`] and [`Health::alarms`]: a bare
//! level fault maps to [`Alarms::ELECTRICAL`](crate::model::Alarms::ELECTRICAL), any
//! alarm maps to a level fault.

mod frame;
mod neutral;
pub mod rx;
mod status;
pub mod status_line;
pub mod tx;
#[cfg(any(test, feature = "vectors"))]
#[doc(hidden)]
pub mod vectors;

pub use frame::{
    decode, detected_double_errors, encode, position_word, DecodeError, EncodeError, Frame,
    FrameKind, LinkConfig, Mode, Parity, BIT_PAIRS, FRAME_BITS, FRAME_MASK,
};
pub use neutral::AxisItem;
pub use status::{Health, Polarity, StatusError, StatusLevel, StatusWord};

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_line;
