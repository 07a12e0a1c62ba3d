//! XY3-100 control commands: the 20-bit codes of command frames, typed (§5.1.1, with
//! the decisions of `xy3-100-notes.md` errata 2 and 3).
//!
//! # Which code is which
//! - Axis commands: `code == base | flags` with `flags` in `0..=0x1F` (bits 4..0) and
//!   `base` one of the six axis-command bases below. Flags 0 mean "all axes".
//! - Rate commands: `code` equal to one of the five rate codes exactly (a rate code
//!   with any low bit set is unknown).
//! - Every other code in `0..=0xFFFFF` is [`Command::Unknown`]; a sink ignores it.
//!
//! The two sets are disjoint (no rate code lies in an axis command's range), so the
//! mapping is a bijection between `0..=0xFFFFF` and the commands [`Command::from_code`]
//! produces: `Command::from_code(c)?.code() == c` for every 20-bit `c`.
//!
//! Codes wider than 20 bits cannot come from a frame; [`Command::from_code`] rejects
//! them. A hand-built `Unknown` holding a wider value or a known code is possible (enum
//! fields cannot be private); the encoder rejects the former, and the latter encodes
//! to the known command's code.

use core::fmt;

use super::frame::CODE_BITS;
use crate::model::Axis;

/// Axis command bases (flags in bits 4..0).
const AUTOCALIB_ON: u32 = 0x8_0000;
const AUTOCALIB_OFF: u32 = 0x4_0000; // erratum 3: takes flags
const CALIB_START: u32 = 0xC_0000;
const REF_START: u32 = 0x2_0000;
const TEMP_COMP_ON: u32 = 0x8_8000;
const TEMP_COMP_OFF: u32 = 0x4_8000; // erratum 2: printed as AUTO_CALIB_OFF
/// Mask of the axis flags in an axis command code.
const FLAGS_MASK: u32 = 0x1F;

/// A set of axes an axis command applies to (§5.1.1 axis flags). The empty set means
/// all axes. Only bits 4..0 can be set (checked on construction).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AxisFlags(u8);

impl AxisFlags {
    /// No flag: the command applies to every axis the sink has.
    pub const ALL_AXES: AxisFlags = AxisFlags(0);
    /// Axis X.
    pub const X: AxisFlags = AxisFlags(0x01);
    /// Axis Y.
    pub const Y: AxisFlags = AxisFlags(0x02);
    /// Axis Z.
    pub const Z: AxisFlags = AxisFlags(0x04);
    /// Axis U.
    pub const U: AxisFlags = AxisFlags(0x08);
    /// Axis W.
    pub const W: AxisFlags = AxisFlags(0x10);

    /// Flags from their bits; `None` if a bit above bit 4 is set.
    pub const fn from_bits(bits: u8) -> Option<AxisFlags> {
        if bits as u32 & !FLAGS_MASK == 0 {
            Some(AxisFlags(bits))
        } else {
            None
        }
    }

    /// The flag bits (0..=0x1F).
    pub const fn bits(self) -> u8 {
        self.0
    }

    /// The union of both sets.
    pub const fn union(self, other: AxisFlags) -> AxisFlags {
        AxisFlags(self.0 | other.0)
    }

    /// The flag of one axis.
    pub const fn of(axis: Axis) -> AxisFlags {
        AxisFlags(1 << axis as u8)
    }

    /// Whether the command applies to `axis` (true for every axis when no flag is set).
    pub const fn applies_to(self, axis: Axis) -> bool {
        self.0 == 0 || self.0 & Self::of(axis).0 != 0
    }
}

/// Backchannel bit rates a controller can select (§5.1.1).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BackRate {
    /// 57600 bit/s, code 0xA0000.
    B57600,
    /// 115200 bit/s, the power-up default, code 0xE0000.
    #[default]
    B115200,
    /// 230400 bit/s, code 0x10000.
    B230400,
    /// 460800 bit/s, code 0x90000.
    B460800,
    /// 921600 bit/s, code 0xD0000 (the spec's `BACK_RATE912`).
    B921600,
}

impl BackRate {
    /// Every rate.
    pub const ALL: [BackRate; 5] = [
        BackRate::B57600,
        BackRate::B115200,
        BackRate::B230400,
        BackRate::B460800,
        BackRate::B921600,
    ];

    /// The bit rate in bit/s.
    pub const fn baud(self) -> u32 {
        match self {
            BackRate::B57600 => 57_600,
            BackRate::B115200 => 115_200,
            BackRate::B230400 => 230_400,
            BackRate::B460800 => 460_800,
            BackRate::B921600 => 921_600,
        }
    }

    /// The command code selecting this rate.
    pub const fn code(self) -> u32 {
        match self {
            BackRate::B57600 => 0xA_0000,
            BackRate::B115200 => 0xE_0000,
            BackRate::B230400 => 0x1_0000,
            BackRate::B460800 => 0x9_0000,
            BackRate::B921600 => 0xD_0000,
        }
    }
}

/// An XY3-100 control command (§5.1.1). See the module docs for the code mapping.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Switch automatic calibration on (0x800XX).
    AutocalibOn(AxisFlags),
    /// Switch automatic calibration off (0x400XX, erratum 3).
    AutocalibOff(AxisFlags),
    /// Start a calibration run (0xC00XX).
    CalibStart(AxisFlags),
    /// Start a reference run (0x200XX).
    RefStart(AxisFlags),
    /// Switch temperature compensation on (0x880XX).
    TempCompOn(AxisFlags),
    /// Switch temperature compensation off (0x480XX, erratum 2).
    TempCompOff(AxisFlags),
    /// Change the backchannel bit rate.
    BackRate(BackRate),
    /// Any other 20-bit code, kept so that it survives a round trip.
    Unknown(u32),
}

/// A command code wider than the 20 bits of a command frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CodeTooWide(pub u32);

impl fmt::Display for CodeTooWide {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "command code {:#x} does not fit 20 bits", self.0)
    }
}

impl Command {
    /// Types a 20-bit command code; codes wider than 20 bits are rejected.
    pub const fn from_code(code: u32) -> Result<Command, CodeTooWide> {
        if code >> CODE_BITS != 0 {
            return Err(CodeTooWide(code));
        }
        // Bits 4..0 only, the cast cannot truncate.
        let flags = AxisFlags((code & FLAGS_MASK) as u8);
        Ok(match code & !FLAGS_MASK {
            AUTOCALIB_ON => Command::AutocalibOn(flags),
            AUTOCALIB_OFF => Command::AutocalibOff(flags),
            CALIB_START => Command::CalibStart(flags),
            REF_START => Command::RefStart(flags),
            TEMP_COMP_ON => Command::TempCompOn(flags),
            TEMP_COMP_OFF => Command::TempCompOff(flags),
            _ => match code {
                0xA_0000 => Command::BackRate(BackRate::B57600),
                0xE_0000 => Command::BackRate(BackRate::B115200),
                0x1_0000 => Command::BackRate(BackRate::B230400),
                0x9_0000 => Command::BackRate(BackRate::B460800),
                0xD_0000 => Command::BackRate(BackRate::B921600),
                _ => Command::Unknown(code),
            },
        })
    }

    /// The command's code (20 bits, unless a hand-built `Unknown` holds more).
    pub const fn code(self) -> u32 {
        match self {
            Command::AutocalibOn(f) => AUTOCALIB_ON | f.0 as u32,
            Command::AutocalibOff(f) => AUTOCALIB_OFF | f.0 as u32,
            Command::CalibStart(f) => CALIB_START | f.0 as u32,
            Command::RefStart(f) => REF_START | f.0 as u32,
            Command::TempCompOn(f) => TEMP_COMP_ON | f.0 as u32,
            Command::TempCompOff(f) => TEMP_COMP_OFF | f.0 as u32,
            Command::BackRate(r) => r.code(),
            Command::Unknown(c) => c,
        }
    }
}
