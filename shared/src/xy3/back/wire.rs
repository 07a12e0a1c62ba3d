//! Wire-level constants shared by the codec and the parser: the head byte, the type
//! identifiers, the per-type length rules and the byte order of multi-byte fields.

use super::packet::PacketError;

/// First byte of every packet (XY3-100 §5.2).
pub const HEAD: u8 = 0x48;
/// Bytes before the payload: head, type, length.
pub const HEADER_LEN: usize = 3;
/// Longest packet on the wire: header plus a 255-byte payload.
pub const MAX_PACKET_LEN: usize = HEADER_LEN + 255;

/// Type identifiers (XY3-100 §5.2; `FIRMWARE` per erratum 4 of our notes).
pub mod ty {
    /// Synchronisation packet, no payload.
    pub const SYNC: u8 = 0x41;
    /// Manufacturer name.
    pub const VENDOR: u8 = 0x01;
    /// Model name.
    pub const MODEL: u8 = 0x02;
    /// Firmware version (printed as a second `MODEL` in the text, erratum 4).
    pub const FIRMWARE: u8 = 0x03;
    /// Serial number.
    pub const SERIAL: u8 = 0x04;
    /// Temperatures per component.
    pub const TEMPERATURES: u8 = 0x05;
    /// Parity-error frame counts per axis.
    pub const FRAME_ERROR_COUNT: u8 = 0x06;
    /// Error codes per component.
    pub const ERROR_STATE: u8 = 0x07;
    /// Free-form debugging data.
    pub const DEBUG: u8 = 0x08;
    /// Working hours per component.
    pub const WORKING_HOURS: u8 = 0x09;
}

/// Which payload lengths a known packet type allows.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LengthRule {
    /// Shortest allowed payload.
    pub min: u8,
    /// Longest allowed payload.
    pub max: u8,
    /// The payload length must be a multiple of this (element size of arrays).
    pub unit: u8,
}

impl LengthRule {
    /// The rule for a type, `None` for types this code does not know (any length
    /// 0..=255 is then acceptable, so the format can be extended).
    pub const fn for_type(t: u8) -> Option<LengthRule> {
        let (min, max, unit) = match t {
            ty::SYNC => (0, 0, 1),
            ty::VENDOR | ty::MODEL | ty::FIRMWARE | ty::SERIAL | ty::DEBUG => (3, 200, 1),
            ty::TEMPERATURES => (2, 44, 2),
            ty::FRAME_ERROR_COUNT => (20, 20, 1),
            ty::ERROR_STATE => (1, 22, 1),
            ty::WORKING_HOURS => (4, 88, 4),
            _ => return None,
        };
        Some(LengthRule { min, max, unit })
    }

    /// Whether `len` satisfies the rule.
    pub const fn allows(self, len: usize) -> bool {
        len >= self.min as usize
            && len <= self.max as usize
            && len.is_multiple_of(self.unit as usize)
    }
}

/// Checks a payload length for type `t` (unknown types: at most 255 bytes).
pub fn check_length(t: u8, len: usize) -> Result<(), PacketError> {
    let rule = LengthRule::for_type(t).unwrap_or(LengthRule {
        min: 0,
        max: u8::MAX,
        unit: 1,
    });
    if len < usize::from(rule.min) || len > usize::from(rule.max) {
        return Err(PacketError::BadLength {
            ty: t,
            len,
            min: rule.min,
            max: rule.max,
        });
    }
    if !len.is_multiple_of(usize::from(rule.unit)) {
        return Err(PacketError::NotMultiple {
            ty: t,
            len,
            unit: rule.unit,
        });
    }
    Ok(())
}

/// The byte order of multi-byte payload fields, kept here and nowhere else.
///
/// The spec (XY3-100 §5.2) refers to C structs in a header we do not have, so the
/// order is unstated; we use little-endian (notes, erratum 6). Switching to
/// big-endian means changing the `from_le_bytes` / `to_le_bytes` calls below only.
pub mod order {
    /// Reads an `i16` from two payload bytes.
    pub const fn read_i16(b: [u8; 2]) -> i16 {
        i16::from_le_bytes(b)
    }
    /// Bytes of an `i16` as sent.
    pub const fn write_i16(v: i16) -> [u8; 2] {
        v.to_le_bytes()
    }
    /// Reads a `u32` from four payload bytes.
    pub const fn read_u32(b: [u8; 4]) -> u32 {
        u32::from_le_bytes(b)
    }
    /// Bytes of a `u32` as sent.
    pub const fn write_u32(v: u32) -> [u8; 4] {
        v.to_le_bytes()
    }
}
