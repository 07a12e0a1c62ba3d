//! Typed backchannel packets: decoding a (type, payload) pair and encoding a packet
//! with its header into a caller's buffer.

use heapless::Vec;

use super::wire::{check_length, order, ty, LengthRule, HEAD, HEADER_LEN};
use crate::model::{Text, COMPONENTS};

/// Payload of a packet type this code does not know (the length byte allows 255).
pub type RawPayload = Vec<u8, 255>;

/// A component of the scan head, as indexed by the per-component packets
/// (XY3-100 §5.2 component tables; the same order for all three arrays).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Component {
    /// The head as a whole (housing).
    Head = 0,
    /// The central DSP.
    Dsp = 1,
    /// The DAC of the X channel.
    DacX = 2,
    /// The DAC of the Y channel.
    DacY = 3,
    /// The DAC of the Z channel.
    DacZ = 4,
    /// The DAC of the U channel.
    DacU = 5,
    /// The DAC of the W channel.
    DacW = 6,
    /// The driver of the X galvo / actuator.
    DriverX = 7,
    /// The driver of the Y galvo / actuator.
    DriverY = 8,
    /// The driver of the Z galvo / actuator.
    DriverZ = 9,
    /// The driver of the U galvo / actuator.
    DriverU = 10,
    /// The driver of the W galvo / actuator.
    DriverW = 11,
    /// The X galvo / actuator.
    GalvoX = 12,
    /// The Y galvo / actuator.
    GalvoY = 13,
    /// The Z galvo / actuator.
    GalvoZ = 14,
    /// The U galvo / actuator.
    GalvoU = 15,
    /// The W galvo / actuator.
    GalvoW = 16,
    /// The optics of the X channel.
    MirrorX = 17,
    /// The optics of the Y channel.
    MirrorY = 18,
    /// The focus optics (Z channel).
    MirrorZ = 19,
    /// The optics of the U channel.
    MirrorU = 20,
    /// The optics of the W channel.
    MirrorW = 21,
}

impl Component {
    /// The component's index into per-component arrays (0..=21).
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// Meaning of one byte of an ERROR_STATE packet (XY3-100 §5.2).
///
/// The packet itself keeps the raw bytes so a round trip is exact; this is the
/// interpretation. Codes 8..=99 are not defined by the spec; they are kept as
/// [`ErrorCode::Undefined`] and, being nonzero, still count as an error.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// 0: the component works.
    Ok,
    /// 1: temperature error.
    Temperature,
    /// 2: data error.
    Data,
    /// 3: out of range.
    OutOfRange,
    /// 4: power supply.
    PowerSupply,
    /// 5: other electrical error.
    OtherElectrical,
    /// 6: adjustment error.
    Adjustment,
    /// 7: other mechanical error.
    OtherMechanical,
    /// 8..=99: not defined by the spec.
    Undefined(u8),
    /// 100..=255: vendor specific.
    Vendor(u8),
}

impl From<u8> for ErrorCode {
    fn from(c: u8) -> Self {
        match c {
            0 => Self::Ok,
            1 => Self::Temperature,
            2 => Self::Data,
            3 => Self::OutOfRange,
            4 => Self::PowerSupply,
            5 => Self::OtherElectrical,
            6 => Self::Adjustment,
            7 => Self::OtherMechanical,
            8..=99 => Self::Undefined(c),
            _ => Self::Vendor(c),
        }
    }
}

/// Why a (type, payload) pair is not a valid packet.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PacketError {
    /// The payload length is outside the range the type allows.
    BadLength {
        /// Packet type.
        ty: u8,
        /// Payload length found.
        len: usize,
        /// Shortest allowed.
        min: u8,
        /// Longest allowed.
        max: u8,
    },
    /// The payload length is in range but not a whole number of array elements.
    NotMultiple {
        /// Packet type.
        ty: u8,
        /// Payload length found.
        len: usize,
        /// Element size the length must be a multiple of.
        unit: u8,
    },
    /// A text packet that must be 7-bit ASCII holds a byte >= 0x80.
    NotAscii {
        /// Packet type.
        ty: u8,
        /// Index of the first offending byte in the payload.
        index: usize,
        /// The byte.
        byte: u8,
    },
}

impl core::fmt::Display for PacketError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadLength { ty, len, min, max } => write!(
                f,
                "packet type {ty:#04x}: payload length {len} outside {min}..={max}"
            ),
            Self::NotMultiple { ty, len, unit } => write!(
                f,
                "packet type {ty:#04x}: payload length {len} is not a multiple of {unit}"
            ),
            Self::NotAscii { ty, index, byte } => write!(
                f,
                "packet type {ty:#04x}: byte {byte:#04x} at index {index} is not 7-bit ASCII"
            ),
        }
    }
}

/// Why a packet cannot be encoded.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The output buffer is shorter than the packet.
    BufferTooSmall {
        /// Bytes the packet needs.
        needed: usize,
        /// Bytes the buffer has.
        available: usize,
    },
    /// The contents break a rule of the packet type (length, ASCII).
    Invalid(PacketError),
    /// `Some` of the value that means "not supported" on the wire (-32767 for a
    /// temperature, `0xFFFF_FFFF` for working hours): it would come back as `None`.
    ReservedValue {
        /// Packet type.
        ty: u8,
        /// Component index of the offending value.
        index: usize,
    },
    /// [`Packet::Unknown`] carries a type this code knows; use the typed variant.
    KnownType(u8),
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BufferTooSmall { needed, available } => {
                write!(f, "packet needs {needed} bytes, buffer has {available}")
            }
            Self::Invalid(e) => write!(f, "invalid packet: {e}"),
            Self::ReservedValue { ty, index } => write!(
                f,
                "packet type {ty:#04x}: value at index {index} is the reserved 'not supported' code"
            ),
            Self::KnownType(t) => write!(f, "type {t:#04x} is known and needs its typed variant"),
        }
    }
}

impl From<PacketError> for EncodeError {
    fn from(e: PacketError) -> Self {
        Self::Invalid(e)
    }
}

/// Temperature that means "not supported" (XY3-100 §5.2).
pub const TEMPERATURE_NOT_SUPPORTED: i16 = -32767;
/// Working-hours value that means "not supported" (XY3-100 §5.2, erratum 5).
pub const HOURS_NOT_SUPPORTED: u32 = u32::MAX;

/// One backchannel packet, typed (XY3-100 §5.2).
#[derive(Clone, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Packet {
    /// Synchronisation marker (0x41), no payload.
    Sync,
    /// Manufacturer (0x01), 3..=200 bytes of 7-bit ASCII.
    Vendor(Text),
    /// Model (0x02), 3..=200 bytes of 7-bit ASCII.
    Model(Text),
    /// Firmware version (0x03), 3..=200 bytes of 7-bit ASCII.
    Firmware(Text),
    /// Serial number (0x04), 3..=200 bytes of 7-bit ASCII.
    Serial(Text),
    /// Temperatures (0x05) in 1/100 °C by component index, 1..=22 entries; `None`
    /// is "not supported" (-32767 on the wire). Shorter arrays leave the last
    /// components out.
    Temperatures(Vec<Option<i16>, COMPONENTS>),
    /// Parity-error frame counts (0x06) on X, Y, Z, U, W since power-up.
    FrameErrorCount([u32; 5]),
    /// Raw error codes (0x07) by component index, 1..=22 entries; interpret each
    /// with [`ErrorCode::from`].
    ErrorState(Vec<u8, COMPONENTS>),
    /// Debugging data (0x08), 3..=200 bytes, any values.
    Debug(Text),
    /// Working hours (0x09) by component index, 1..=22 entries; `None` is "not
    /// supported" (`0xFFFF_FFFF` on the wire).
    WorkingHours(Vec<Option<u32>, COMPONENTS>),
    /// A type this code does not know, kept as received.
    Unknown {
        /// The type byte.
        ty: u8,
        /// The payload, 0..=255 bytes.
        payload: RawPayload,
    },
}

/// Collects decoded elements into a bounded vector; running out of room reports the
/// length as bad instead of panicking like `heapless::Vec::from_iter` would.
fn bounded<T, const N: usize>(
    t: u8,
    len: usize,
    items: impl Iterator<Item = T>,
) -> Result<Vec<T, N>, PacketError> {
    let mut v = Vec::new();
    for item in items {
        v.push(item).map_err(|_| PacketError::BadLength {
            ty: t,
            len,
            min: 0,
            max: u8::try_from(N).unwrap_or(u8::MAX),
        })?;
    }
    Ok(v)
}

fn text(t: u8, payload: &[u8], ascii: bool) -> Result<Text, PacketError> {
    if ascii {
        if let Some((index, &byte)) = payload.iter().enumerate().find(|(_, b)| !b.is_ascii()) {
            return Err(PacketError::NotAscii { ty: t, index, byte });
        }
    }
    // The length was checked against 3..=200 by the caller, so this cannot fail;
    // the error path still reports the truth instead of panicking.
    Text::from_slice(payload).map_err(|_| PacketError::BadLength {
        ty: t,
        len: payload.len(),
        min: 3,
        max: 200,
    })
}

impl Packet {
    /// The packet's type byte.
    pub fn ty(&self) -> u8 {
        match self {
            Self::Sync => ty::SYNC,
            Self::Vendor(_) => ty::VENDOR,
            Self::Model(_) => ty::MODEL,
            Self::Firmware(_) => ty::FIRMWARE,
            Self::Serial(_) => ty::SERIAL,
            Self::Temperatures(_) => ty::TEMPERATURES,
            Self::FrameErrorCount(_) => ty::FRAME_ERROR_COUNT,
            Self::ErrorState(_) => ty::ERROR_STATE,
            Self::Debug(_) => ty::DEBUG,
            Self::WorkingHours(_) => ty::WORKING_HOURS,
            Self::Unknown { ty, .. } => *ty,
        }
    }

    /// Decodes the payload of a packet of type `t`, checking the type's length rule
    /// and (for the identification texts) that every byte is 7-bit ASCII.
    pub fn decode(t: u8, payload: &[u8]) -> Result<Packet, PacketError> {
        check_length(t, payload.len())?;
        Ok(match t {
            ty::SYNC => Self::Sync,
            ty::VENDOR => Self::Vendor(text(t, payload, true)?),
            ty::MODEL => Self::Model(text(t, payload, true)?),
            ty::FIRMWARE => Self::Firmware(text(t, payload, true)?),
            ty::SERIAL => Self::Serial(text(t, payload, true)?),
            ty::DEBUG => Self::Debug(text(t, payload, false)?),
            ty::TEMPERATURES => Self::Temperatures(bounded(
                t,
                payload.len(),
                payload.chunks_exact(2).map(|c| {
                    let v = order::read_i16([c[0], c[1]]);
                    (v != TEMPERATURE_NOT_SUPPORTED).then_some(v)
                }),
            )?),
            ty::WORKING_HOURS => Self::WorkingHours(bounded(
                t,
                payload.len(),
                payload.chunks_exact(4).map(|c| {
                    let v = order::read_u32([c[0], c[1], c[2], c[3]]);
                    (v != HOURS_NOT_SUPPORTED).then_some(v)
                }),
            )?),
            ty::FRAME_ERROR_COUNT => {
                let mut counts = [0u32; 5];
                for (n, c) in counts.iter_mut().zip(payload.chunks_exact(4)) {
                    *n = order::read_u32([c[0], c[1], c[2], c[3]]);
                }
                Self::FrameErrorCount(counts)
            }
            ty::ERROR_STATE => {
                Self::ErrorState(bounded(t, payload.len(), payload.iter().copied())?)
            }
            _ => Self::Unknown {
                ty: t,
                payload: bounded(t, payload.len(), payload.iter().copied())?,
            },
        })
    }

    /// Payload length this packet encodes to.
    fn payload_len(&self) -> usize {
        match self {
            Self::Sync => 0,
            Self::Vendor(t) | Self::Model(t) | Self::Firmware(t) | Self::Serial(t) => t.len(),
            Self::Debug(t) => t.len(),
            Self::Temperatures(v) => v.len() * 2,
            Self::FrameErrorCount(_) => 20,
            Self::ErrorState(v) => v.len(),
            Self::WorkingHours(v) => v.len() * 4,
            Self::Unknown { payload, .. } => payload.len(),
        }
    }

    /// Checks everything [`Packet::decode`] would check on the way back, so that an
    /// encoded packet always decodes to itself.
    fn validate(&self) -> Result<(), EncodeError> {
        let t = self.ty();
        check_length(t, self.payload_len())?;
        match self {
            Self::Vendor(s) | Self::Model(s) | Self::Firmware(s) | Self::Serial(s) => {
                text(t, s, true)?;
            }
            Self::Temperatures(v) => {
                if let Some(index) = v.iter().position(|x| *x == Some(TEMPERATURE_NOT_SUPPORTED)) {
                    return Err(EncodeError::ReservedValue { ty: t, index });
                }
            }
            Self::WorkingHours(v) => {
                if let Some(index) = v.iter().position(|x| *x == Some(HOURS_NOT_SUPPORTED)) {
                    return Err(EncodeError::ReservedValue { ty: t, index });
                }
            }
            Self::Unknown { ty, .. } if LengthRule::for_type(*ty).is_some() => {
                return Err(EncodeError::KnownType(*ty));
            }
            _ => {}
        }
        Ok(())
    }

    /// Writes the whole packet (head, type, length, payload) to the start of `out`
    /// and returns the number of bytes written. Nothing is written on error.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        self.validate()?;
        let len = self.payload_len();
        let needed = HEADER_LEN + len;
        let available = out.len();
        let Some((header, payload)) = out
            .get_mut(..needed)
            .and_then(|b| b.split_at_mut_checked(HEADER_LEN))
        else {
            return Err(EncodeError::BufferTooSmall { needed, available });
        };
        // `validate` bounded every payload to at most 255 bytes.
        let len_byte = u8::try_from(len).unwrap_or(u8::MAX);
        header.copy_from_slice(&[HEAD, self.ty(), len_byte]);
        // From here on `payload.len() == len`, the sum of the element sizes below,
        // so the equal-length copies cannot panic.
        match self {
            Self::Sync => {}
            Self::Vendor(s) | Self::Model(s) | Self::Firmware(s) | Self::Serial(s) => {
                payload.copy_from_slice(s);
            }
            Self::Debug(s) => payload.copy_from_slice(s),
            Self::Unknown { payload: p, .. } => payload.copy_from_slice(p),
            Self::ErrorState(v) => payload.copy_from_slice(v),
            Self::Temperatures(v) => {
                for (c, t) in payload.chunks_exact_mut(2).zip(v) {
                    c.copy_from_slice(&order::write_i16(t.unwrap_or(TEMPERATURE_NOT_SUPPORTED)));
                }
            }
            Self::WorkingHours(v) => {
                for (c, h) in payload.chunks_exact_mut(4).zip(v) {
                    c.copy_from_slice(&order::write_u32(h.unwrap_or(HOURS_NOT_SUPPORTED)));
                }
            }
            Self::FrameErrorCount(counts) => {
                for (c, n) in payload.chunks_exact_mut(4).zip(counts) {
                    c.copy_from_slice(&order::write_u32(*n));
                }
            }
        }
        Ok(needed)
    }
}
