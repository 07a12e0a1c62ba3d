//! DATA3 extension codes (HANS-100 spec "HANS-100 协议解析"): `DATA3[3:0]` is a 4-bit
//! code, `DATA3[19:4]` its 16 data bits ("D0" of the data is DATA3 bit 4).
//!
//! The code tables differ by direction: [`ControllerExt`] is what a controller sends to
//! the device (CTRL_CODE1), [`DeviceExt`] what a laser, Z galvo or IO board returns on
//! STATUS (CTRL_CODE2). Every one of the 16 codes with any data decodes, and re-encodes
//! to the identical word; codes without a defined meaning are kept raw.

use super::Frame;
use crate::model::LaserControl;

/// Why a value cannot be encoded as an extension word.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ExtError {
    /// A word to decode does not fit 20 bits.
    WordTooWide(u32),
    /// An extension code does not fit its field (4 bits in DATA3, 8 bits for DATA1/2).
    CodeTooWide(u8),
    /// The code-3 reserved bits D15..D11 do not fit 5 bits.
    ReservedTooWide(u8),
    /// A velocity does not fit its 12-bit field.
    VelocityTooWide(u16),
}

impl core::fmt::Display for ExtError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::WordTooWide(w) => write!(f, "HANS-100 word {w:#x} does not fit 20 bits"),
            Self::CodeTooWide(c) => write!(f, "HANS-100 extension code {c} too wide"),
            Self::ReservedTooWide(r) => {
                write!(f, "HANS-100 code-3 reserved bits {r:#x} do not fit 5 bits")
            }
            Self::VelocityTooWide(v) => {
                write!(f, "HANS-100 velocity {v:#x} does not fit 12 bits")
            }
        }
    }
}

/// Splits a 20-bit word into (code, data).
pub(crate) fn split(word: u32) -> Result<(u8, u16), ExtError> {
    if word > super::WORD_MAX {
        return Err(ExtError::WordTooWide(word));
    }
    // Truncations intended: 4 and 16 bits of a checked 20-bit word.
    Ok(((word & 0xF) as u8, (word >> 4) as u16))
}

/// Splits a frame's DATA3 (always 20 bits) into (code, data).
fn split_data3(frame: &Frame) -> (u8, u16) {
    let w = frame.data3();
    // Truncations intended: 4 and 16 bits of a 20-bit word.
    ((w & 0xF) as u8, (w >> 4) as u16)
}

/// Joins a 4-bit code and 16 data bits into a 20-bit word.
pub(crate) fn join(code: u8, data: u16) -> Result<u32, ExtError> {
    if code > 0xF {
        return Err(ExtError::CodeTooWide(code));
    }
    Ok(u32::from(data) << 4 | u32::from(code))
}

/// Forward DATA3 (controller -> device, CTRL_CODE1).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControllerExt {
    /// Code 0: 16-bit Z position (offset binary).
    Z(u16),
    /// Codes 1..=15: laser / IO control; codes without a meaning are
    /// [`LaserControl::Other`].
    Laser(LaserControl),
}

impl ControllerExt {
    /// Decodes a forward DATA3 word.
    pub fn from_data3(word: u32) -> Result<Self, ExtError> {
        let (code, d) = split(word)?;
        Ok(Self::from_parts(code, d))
    }

    /// Decodes a forward frame's DATA3 (cannot fail: every code has a meaning).
    pub fn from_frame(frame: &Frame) -> Self {
        let (code, d) = split_data3(frame);
        Self::from_parts(code, d)
    }

    fn from_parts(code: u8, d: u16) -> Self {
        match code {
            0 => Self::Z(d),
            1 => Self::Laser(LaserControl::RemoteOutputs(d)),
            3 => Self::Laser(LaserControl::Power {
                // Truncations intended: the fields D7..D0 and D15..D11.
                power: d as u8,
                mo: d & 1 << 8 != 0,
                pa: d & 1 << 9 != 0,
                red_pointer: d & 1 << 10 != 0,
                reserved: (d >> 11) as u8,
            }),
            4 => Self::Laser(LaserControl::QPeriod(d)),
            5 => Self::Laser(LaserControl::StandbyFrequency(d)),
            6 => Self::Laser(LaserControl::PulseWidthMode(d)),
            9 => Self::Laser(LaserControl::StandbyPower(d)),
            code => Self::Laser(LaserControl::Other { code, data: d }),
        }
    }

    /// Encodes as a forward DATA3 word. `LaserControl::Other` is sent as given, even
    /// with a code that has a typed meaning (it then decodes as that typed value).
    pub fn to_data3(&self) -> Result<u32, ExtError> {
        let (code, d) = match *self {
            Self::Z(z) => (0, z),
            Self::Laser(l) => match l {
                LaserControl::RemoteOutputs(d) => (1, d),
                LaserControl::Power {
                    power,
                    mo,
                    pa,
                    red_pointer,
                    reserved,
                } => {
                    if reserved > 0x1F {
                        return Err(ExtError::ReservedTooWide(reserved));
                    }
                    let d = u16::from(power)
                        | u16::from(mo) << 8
                        | u16::from(pa) << 9
                        | u16::from(red_pointer) << 10
                        | u16::from(reserved) << 11;
                    (3, d)
                }
                LaserControl::QPeriod(d) => (4, d),
                LaserControl::StandbyFrequency(d) => (5, d),
                LaserControl::PulseWidthMode(d) => (6, d),
                LaserControl::StandbyPower(d) => (9, d),
                LaserControl::Other { code, data } => (code, data),
            },
        };
        join(code, d)
    }
}

/// Laser alarm/state bits of device code 10 (CTRL_DATA2 D15..D0), kept whole so
/// undefined bits D10..D14 survive a round trip. 1 = alarm / state active.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LaserAlarms(pub u16);

impl LaserAlarms {
    /// D0: power supply alarm.
    pub const POWER: u16 = 1 << 0;
    /// D1: temperature alarm.
    pub const TEMPERATURE: u16 = 1 << 1;
    /// D2: temperature warning (not an alarm).
    pub const TEMPERATURE_WARNING: u16 = 1 << 2;
    /// D3: system alarm.
    pub const SYSTEM: u16 = 1 << 3;
    /// D4: seed laser alarm.
    pub const SEED: u16 = 1 << 4;
    /// D5: missing-pulse alarm.
    pub const MISSING_PULSE: u16 = 1 << 5;
    /// D6: back-reflection alarm.
    pub const BACK_REFLECTION: u16 = 1 << 6;
    /// D7: first amplifier alarm.
    pub const FIRST_AMPLIFIER: u16 = 1 << 7;
    /// D8: second amplifier alarm.
    pub const SECOND_AMPLIFIER: u16 = 1 << 8;
    /// D9: communication alarm.
    pub const COMMUNICATION: u16 = 1 << 9;
    /// D15: emission warning (the laser is emitting; not an alarm).
    pub const EMISSION: u16 = 1 << 15;
    /// Bits that are states or warnings rather than alarms (D2, D15).
    pub const NOT_ALARMS: u16 = Self::TEMPERATURE_WARNING | Self::EMISSION;

    /// Whether all bits of `mask` are set.
    pub const fn contains(self, mask: u16) -> bool {
        self.0 & mask == mask
    }

    /// Whether any alarm is active. Undefined bits D10..D14 count as alarms: an
    /// unknown fault reported by the laser must not be ignored.
    pub const fn any_alarm(self) -> bool {
        self.0 & !Self::NOT_ALARMS != 0
    }
}

/// Z galvo alarms of device code 15. `true` = alarm active (the wire sends 0 for
/// alarm, 1 for normal; the conversion happens in the codec).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ZAlarms {
    /// `DATA3[7]`: over-temperature alarm.
    pub over_temperature: bool,
    /// `DATA3[6]`: following-error alarm.
    pub following_error: bool,
    /// `DATA3[5]`: communication (bad or missing frames for 1000 us) alarm.
    pub communication: bool,
    /// `DATA3[4]`: power / sensor / system alarm.
    pub power: bool,
}

/// Returned DATA3 (device -> controller on STATUS, CTRL_CODE2).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DeviceExt {
    /// Code 2: sixteen remote digital inputs.
    RemoteInputs(u16),
    /// Code 7: current laser pulse-width mode.
    PulseWidthMode(u16),
    /// Code 10: laser alarm state.
    LaserAlarms(LaserAlarms),
    /// Code 14: Z actual position (16 bits, offset binary).
    ZActual(u16),
    /// Code 15: Z actual velocity and alarms.
    ZVelocity {
        /// `DATA3[19:8]`, opaque 12 bits (the spec gives no scale or sign).
        velocity: u16,
        /// `DATA3[7:4]`.
        alarms: ZAlarms,
    },
    /// Any other code with its 16 data bits, kept as received.
    Raw {
        /// The 4-bit code.
        code: u8,
        /// CTRL_DATA2, DATA3 bits 19..4.
        data: u16,
    },
}

impl DeviceExt {
    /// Decodes a returned DATA3 word.
    pub fn from_data3(word: u32) -> Result<Self, ExtError> {
        let (code, d) = split(word)?;
        Ok(Self::from_parts(code, d))
    }

    /// Decodes a status frame's DATA3 (cannot fail: unknown codes are `Raw`).
    pub fn from_frame(frame: &Frame) -> Self {
        let (code, d) = split_data3(frame);
        Self::from_parts(code, d)
    }

    fn from_parts(code: u8, d: u16) -> Self {
        match code {
            2 => Self::RemoteInputs(d),
            7 => Self::PulseWidthMode(d),
            10 => Self::LaserAlarms(LaserAlarms(d)),
            14 => Self::ZActual(d),
            15 => Self::ZVelocity {
                velocity: d >> 4,
                // Wire level 0 = alarm.
                alarms: ZAlarms {
                    over_temperature: d & 1 << 3 == 0,
                    following_error: d & 1 << 2 == 0,
                    communication: d & 1 << 1 == 0,
                    power: d & 1 == 0,
                },
            },
            code => Self::Raw { code, data: d },
        }
    }

    /// Encodes as a returned DATA3 word. `Raw` is sent as given.
    pub fn to_data3(&self) -> Result<u32, ExtError> {
        let (code, d) = match *self {
            Self::RemoteInputs(d) => (2, d),
            Self::PulseWidthMode(d) => (7, d),
            Self::LaserAlarms(a) => (10, a.0),
            Self::ZActual(d) => (14, d),
            Self::ZVelocity { velocity, alarms } => {
                if velocity > 0xFFF {
                    return Err(ExtError::VelocityTooWide(velocity));
                }
                let d = velocity << 4
                    | u16::from(!alarms.over_temperature) << 3
                    | u16::from(!alarms.following_error) << 2
                    | u16::from(!alarms.communication) << 1
                    | u16::from(!alarms.power);
                (15, d)
            }
            Self::Raw { code, data } => (code, data),
        };
        join(code, d)
    }
}
