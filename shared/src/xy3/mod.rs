//! XY3-100: forward frames and control commands (this module and [`frame`],
//! [`command`], [`neutral`]), the line-level receiver ([`rx`]) and transmitter
//! ([`tx`]), and the RS485 backchannel ([`back`], receive path in [`back_rx`]).
//!
//! # Forward transmission (XY3-100 §5.1)
//! The controller drives SYNC, CLK and one data line per axis (X, Y, Z, U, W). SYNC
//! works like an SPI chip select: it goes low for one frame. Data are valid on the
//! falling CLK edge, most significant bit first. All data lines share CLK and SYNC, so
//! every channel carries one frame per frame period.
//!
//! Each frame is self-describing. Its first bit gives the length (0: 24 bits, 1: 32
//! bits), its second bit the kind (1: position, 0: command). The remaining bits are a
//! data field followed by parity bits:
//!
//! | frame | bits on the line, first to last | parity counts |
//! |---|---|---|
//! | 24-bit position | `0 1 D19..D0 P1 P0` | D19..D0 (bits 21..2) |
//! | 32-bit position | `1 1 D25..D0 P3..P0` | D25..D0 (bits 29..4) |
//! | 24-bit command | `0 0 C19..C0 P1 P0` | C19..C0 (bits 21..2) |
//! | 32-bit command | `1 0 x5..x0 C19..C0 P3..P0` | x5..x0 and C19..C0 (bits 29..4) |
//!
//! The parity is the number of ones in the counted bits, keeping the low 2 bits (24-bit
//! frames) or the low 4 bits (32-bit frames). The six `x` bits of a 32-bit command
//! frame have no meaning but are counted; we send them as 0 and keep received values in
//! [`Frame::Command32`] so that re-encoding a decoded frame gives the same word.
//!
//! In this crate a wire word is a `u32` holding the frame right-aligned (the first bit
//! on the line is bit 23 or bit 31). The receiver knows the size from its framing (the
//! number of clocks while SYNC was low) and passes it to [`decode`], which checks that
//! the first bit agrees; a streaming receiver can instead use
//! [`FrameSize::from_first_bit`] to know how many bits to collect.
//!
//! ## Positions and resolution
//! Position fields are offset binary (our decision, `xy3-100-notes.md` erratum 7: 0 and
//! full scale are the field ends, `0x80000` / `0x2000000` the centre) and
//! **MSB-aligned**: §5.1 lets a sender with fewer bits zero the low bits and a receiver
//! with fewer bits ignore them. So a 16-bit value `v` travels as `v << 4` in a 24-bit
//! frame and `v << 10` in a 32-bit frame. [`neutral`] maps the fields to
//! [`crate::model::Position`] at 20 or 26 bits and back with the model's rounding.
//!
//! ## Commands (§5.1.1)
//! A command frame carries a 20-bit code, typed by [`Command`]. Commands are meant for
//! the X channel; a controller may repeat them on the other channels and a sink may
//! ignore those copies ([`neutral::apply`] does). Every command is optional for a sink,
//! and a sink ignores unknown codes (the bridge should count them).
//!
//! # What the parity detects
//! Worked out from the layout above and checked exhaustively in the tests.
//! - **Every single-bit error in the data or parity bits** is detected: a data flip
//!   changes the count by ±1, a parity flip changes the parity field by ±1, ±2, ±4 or
//!   ±8; none of these is 0 modulo 4 or 16.
//! - **A flipped first bit** is detected only because the receiver's framing (the
//!   clock count in the SYNC window) disagrees with it ([`DecodeError::SizeMismatch`]).
//!   A receiver that trusts the first bit to decide how many bits to collect instead
//!   sees a frame of the wrong length, which only the SYNC edge can reveal.
//! - **A flipped second bit is not detected.** The kind bit is outside the parity count,
//!   so a position frame becomes a valid command frame whose code is the position's low
//!   20 bits (almost always an unknown code, which a sink ignores, losing one position),
//!   and — worse — a command frame becomes a valid position frame whose value is the
//!   command code (e.g. `0x80000` = mid-field). This is a property of the protocol;
//!   only plausibility checks above this module (rare commands, slew limits) can
//!   catch it.
//! - Two or more errors go unnoticed whenever the count changes by the same amount as
//!   the parity field modulo 4 or 16; in particular **one 0->1 and one 1->0 data flip
//!   are never detected**. Exhaustively over bit pairs, about 62 % of 2-bit errors in
//!   24-bit frames and about 65 % in 32-bit frames are detected (the tests print the
//!   figures).
//! - A data line stuck low reads as the all-zero 24-bit command frame, which has valid
//!   parity (code 0, unknown, ignored): a dead line shows as missing positions, not as
//!   parity errors.

pub mod back;
pub mod back_rx;
pub mod command;
pub mod frame;
pub mod neutral;
pub mod rx;
pub mod step;
pub mod tx;
#[cfg(any(test, feature = "vectors"))]
#[doc(hidden)]
pub mod vectors;

pub use command::{AxisFlags, BackRate, CodeTooWide, Command};
pub use frame::{decode, encode, DecodeError, EncodeError, Frame, FrameSize};

#[cfg(test)]
mod tests;
