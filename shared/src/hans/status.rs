//! DATA1/DATA2 status extension of a closed-loop galvo (HANS-100 spec, section on data
//! returned from the galvo to the card): the 8-bit code is `DATA1[3:0]` (high nibble)
//! followed by `DATA2[3:0]`, the 32 data bits are `DATA1[19:4]` (high half) and
//! `DATA2[19:4]`.
//!
//! Ambiguities and our decisions:
//! - Velocity scale and sign are not defined: the 12-bit fields stay opaque.
//! - How often status frames are sent and how codes 64 / 65 alternate is not stated:
//!   every frame decodes on its own, in any order.
//! - `DATA2[5]` is reserved: its wire level is kept so a round trip is exact.

use super::ext::{split, ExtError};
use super::Frame;

/// Galvo alarms and warnings of code 65. `true` = active (the wire sends 0 for
/// active, 1 for normal; the conversion happens in the codec).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GalvoAlarms {
    /// `DATA1[7]`: over-temperature alarm (any axis above the alarm threshold).
    pub over_temperature: bool,
    /// `DATA1[6]`: following-error alarm (galvo-wide, not per axis).
    pub following_error: bool,
    /// `DATA1[5]`: low-speed warning, filtered (both axes slow for more than 10 ms).
    pub low_speed_filtered: bool,
    /// `DATA1[4]`: power / sensor / system alarm.
    pub power: bool,
    /// `DATA2[7]`: over-temperature warning (marking continues).
    pub temperature_warning: bool,
    /// `DATA2[6]`: low-speed warning, unfiltered.
    pub low_speed: bool,
    /// `DATA2[5]`: reserved, the raw wire level (normally 1, like an inactive flag).
    pub reserved_level: bool,
    /// `DATA2[4]`: communication alarm (bad or missing frames for 1000 us).
    pub communication: bool,
}

impl GalvoAlarms {
    /// A healthy galvo: nothing active, the reserved bit at its normal wire level 1
    /// (which `Default` does not give: it would send the reserved bit as 0).
    pub const NONE: GalvoAlarms = GalvoAlarms {
        over_temperature: false,
        following_error: false,
        low_speed_filtered: false,
        power: false,
        temperature_warning: false,
        low_speed: false,
        reserved_level: true,
        communication: false,
    };
}

/// A galvo status carried in DATA1 + DATA2 (CTRL_CODE3).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GalvoStatus {
    /// Code 64: actual X / Y positions, the top 16 bits of the galvo's position.
    Position {
        /// `DATA1[19:4]`.
        x: u16,
        /// `DATA2[19:4]`.
        y: u16,
    },
    /// Code 65: actual velocities and alarms.
    Velocity {
        /// `DATA1[19:8]`, opaque 12 bits.
        x: u16,
        /// `DATA2[19:8]`, opaque 12 bits.
        y: u16,
        /// `DATA1[7:4]` and `DATA2[7:4]`.
        alarms: GalvoAlarms,
    },
    /// Any other code with its 32 data bits, kept as received.
    Raw {
        /// CTRL_CODE3.
        code: u8,
        /// CTRL_DATA3: `DATA1[19:4]` in bits 31..16, `DATA2[19:4]` in bits 15..0.
        data: u32,
    },
}

/// CTRL_CODE3 of an actual-position status.
pub const CODE_POSITION: u8 = 64;
/// CTRL_CODE3 of a velocity/alarm status.
pub const CODE_VELOCITY: u8 = 65;

/// Wire bit `n` of a 16-bit CTRL_DATA half, read as an active-low flag.
const fn active_low(d: u16, n: u16) -> bool {
    d & 1 << n == 0
}

/// An active-low flag as wire bit `n`.
fn wire(active: bool, n: u16) -> u16 {
    u16::from(!active) << n
}

impl GalvoStatus {
    /// Decodes DATA1 and DATA2 of a status frame.
    pub fn from_words(data1: u32, data2: u32) -> Result<Self, ExtError> {
        let (c1, d1) = split(data1)?;
        let (c2, d2) = split(data2)?;
        Ok(Self::from_parts(c1 << 4 | c2, d1, d2))
    }

    /// Decodes DATA1 and DATA2 of a status frame (cannot fail: unknown codes are
    /// `Raw`).
    pub fn from_frame(frame: &Frame) -> Self {
        let (w1, w2) = (frame.data1(), frame.data2());
        // Truncations intended: 4 and 16 bits of 20-bit words.
        let code = ((w1 & 0xF) << 4 | (w2 & 0xF)) as u8;
        Self::from_parts(code, (w1 >> 4) as u16, (w2 >> 4) as u16)
    }

    fn from_parts(code: u8, d1: u16, d2: u16) -> Self {
        match code {
            CODE_POSITION => Self::Position { x: d1, y: d2 },
            CODE_VELOCITY => Self::Velocity {
                x: d1 >> 4,
                y: d2 >> 4,
                alarms: GalvoAlarms {
                    over_temperature: active_low(d1, 3),
                    following_error: active_low(d1, 2),
                    low_speed_filtered: active_low(d1, 1),
                    power: active_low(d1, 0),
                    temperature_warning: active_low(d2, 3),
                    low_speed: active_low(d2, 2),
                    reserved_level: d2 & 1 << 1 != 0,
                    communication: active_low(d2, 0),
                },
            },
            code => Self::Raw {
                code,
                data: u32::from(d1) << 16 | u32::from(d2),
            },
        }
    }

    /// Encodes as (DATA1, DATA2). `Raw` is sent as given.
    pub fn to_words(&self) -> Result<(u32, u32), ExtError> {
        let (code, d1, d2) = match *self {
            Self::Position { x, y } => (CODE_POSITION, x, y),
            Self::Velocity { x, y, alarms: a } => {
                for v in [x, y] {
                    if v > 0xFFF {
                        return Err(ExtError::VelocityTooWide(v));
                    }
                }
                let d1 = x << 4
                    | wire(a.over_temperature, 3)
                    | wire(a.following_error, 2)
                    | wire(a.low_speed_filtered, 1)
                    | wire(a.power, 0);
                let d2 = y << 4
                    | wire(a.temperature_warning, 3)
                    | wire(a.low_speed, 2)
                    | u16::from(a.reserved_level) << 1
                    | wire(a.communication, 0);
                (CODE_VELOCITY, d1, d2)
            }
            // Truncations intended: the two 16-bit halves of CTRL_DATA3.
            Self::Raw { code, data } => (code, (data >> 16) as u16, data as u16),
        };
        let w1 = u32::from(d1) << 4 | u32::from(code >> 4);
        let w2 = u32::from(d2) << 4 | u32::from(code & 0xF);
        Ok((w1, w2))
    }
}
