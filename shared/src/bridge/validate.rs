//! [`Config::validate`] and its [`ConfigError`]: the rules the configuration types
//! cannot express, each error naming the offending key as written in `bridge.toml`.

use core::fmt;

use super::config::{
    Config, GateSource, HansDecode, HeadSide, Protocol, Timing, ZSource, HANS_RATE_HZ, MAX20,
    MAX_RATE_HZ, MIN_RATE_HZ,
};
use crate::xy2::{Mode, Parity};

/// Why a configuration is rejected; [`ConfigError::key`] names the offending key.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// `head.xy2.enhanced_commands`: 18-bit XY2-100E has no command frames.
    EnhancedCommandsIn18Bit,
    /// `controller.xy2.parity`: the controller's frames must be checked, or a
    /// corrupted frame could be forwarded.
    UncheckedInput,
    /// `output.frame_rate_hz` outside 1 kHz ..= 200 kHz.
    FrameRate(u32),
    /// `output.frame_rate_hz`: a HANS-100 head runs at exactly 100 kHz.
    HansFixedRate(u32),
    /// `output.timing`: HANS-100 output is a continuous 100 kHz stream that cannot
    /// follow the input's clock.
    HansNotSlavable,
    /// `controller.hans.decode`: a channel outside 1..=5.
    HansChannel(u8),
    /// `controller.hans.decode`: the three vote channels are not distinct.
    Vote3NotDistinct([u8; 3]),
    /// `laser.gate`: the MO / PA gate needs a HANS-100 controller.
    GateNeedsHans,
    /// `controller.xy3.lines`: Y is missing; every XY3-100 link has X and Y
    /// (§3.1.1), and a bridge needs both.
    Xy3LinesWithoutY,
    /// `controller.xy3.lines`: `z.source = "input"` takes Z from the controller, but
    /// the Z line is not listed.
    Xy3ZNotDriven,
    /// A number outside its range.
    OutOfRange {
        /// The key.
        key: &'static str,
        /// The value given.
        value: i64,
        /// Smallest allowed value.
        min: i64,
        /// Largest allowed value.
        max: i64,
    },
}

impl ConfigError {
    /// The configuration key the error is about, as written in `bridge.toml`.
    pub const fn key(&self) -> &'static str {
        match self {
            Self::EnhancedCommandsIn18Bit => "head.xy2.enhanced_commands",
            Self::UncheckedInput => "controller.xy2.parity",
            Self::FrameRate(_) | Self::HansFixedRate(_) => "output.frame_rate_hz",
            Self::HansNotSlavable => "output.timing",
            Self::HansChannel(_) | Self::Vote3NotDistinct(_) => "controller.hans.decode",
            Self::GateNeedsHans => "laser.gate",
            Self::Xy3LinesWithoutY | Self::Xy3ZNotDriven => "controller.xy3.lines",
            Self::OutOfRange { key, .. } => key,
        }
    }
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.key())?;
        match self {
            Self::EnhancedCommandsIn18Bit => {
                f.write_str("18-bit XY2-100E cannot carry enhanced commands; set it to false")
            }
            Self::UncheckedInput => {
                f.write_str("controller input parity must be checked (not \"ignore\")")
            }
            Self::FrameRate(hz) => {
                write!(f, "{hz} Hz is outside {MIN_RATE_HZ} ..= {MAX_RATE_HZ} Hz")
            }
            Self::HansFixedRate(hz) => {
                write!(f, "HANS-100 output is fixed at {HANS_RATE_HZ} Hz, not {hz}")
            }
            Self::HansNotSlavable => {
                f.write_str("HANS-100 output cannot be slaved; use \"free_running\"")
            }
            Self::HansChannel(c) => write!(f, "channel {c} is outside 1..=5"),
            Self::Vote3NotDistinct(c) => {
                write!(f, "vote3 channels {c:?} must be three distinct channels")
            }
            Self::GateNeedsHans => f.write_str("\"hans_mo_pa\" needs a HANS-100 controller"),
            Self::Xy3LinesWithoutY => {
                f.write_str("an XY3-100 controller drives X and Y: list \"x\" and \"y\"")
            }
            Self::Xy3ZNotDriven => f.write_str(
                "z.source = \"input\" takes Z from the controller, but \"z\" is not listed; \
                 add it, or set z.source to \"fixed\" or \"none\"",
            ),
            Self::OutOfRange {
                value, min, max, ..
            } => write!(f, "{value} is outside {min} ..= {max}"),
        }
    }
}

fn range(key: &'static str, value: i64, min: i64, max: i64) -> Result<(), ConfigError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ConfigError::OutOfRange {
            key,
            value,
            min,
            max,
        })
    }
}

fn channel(c: u8) -> Result<(), ConfigError> {
    if (1..=5).contains(&c) {
        Ok(())
    } else {
        Err(ConfigError::HansChannel(c))
    }
}

impl HeadSide {
    /// The width the head receives `axis` positions at (X, Y: index 0, 1; Z: 2; U,
    /// W: 3, 4).
    pub const fn width(&self, axis: crate::model::Axis) -> u8 {
        match self.protocol {
            Protocol::Xy2 => match self.xy2.mode {
                Mode::Standard16 => 16,
                Mode::Extended18 => 18,
            },
            Protocol::Xy3 => self.xy3.frame_size.position_bits(),
            Protocol::Hans => match axis {
                crate::model::Axis::Z => crate::hans::neutral::Z_BITS,
                _ => crate::hans::neutral::XY_BITS,
            },
        }
    }
}

impl Config {
    /// Checks every rule the types cannot express; the first violation is returned.
    /// The same code runs on the host (for files) and in the firmware.
    pub fn validate(&self) -> Result<(), ConfigError> {
        use crate::model::Axis;
        let c = &self.controller;
        if c.protocol == Protocol::Xy2 && c.xy2.parity == Parity::Ignore {
            return Err(ConfigError::UncheckedInput);
        }
        if c.protocol == Protocol::Hans {
            match c.hans.decode {
                HansDecode::Normal(ch) => channel(ch)?,
                HansDecode::Vote3(chs) => {
                    for ch in chs {
                        channel(ch)?;
                    }
                    let [a, b, d] = chs;
                    if a == b || a == d || b == d {
                        return Err(ConfigError::Vote3NotDistinct(chs));
                    }
                }
                HansDecode::Vote5 | HansDecode::Super => {}
            }
        }
        if c.protocol == Protocol::Xy3 {
            let lines = c.xy3.lines;
            if !lines.has(Axis::Y) {
                return Err(ConfigError::Xy3LinesWithoutY);
            }
            if self.z.source == ZSource::Input && !lines.has(Axis::Z) {
                return Err(ConfigError::Xy3ZNotDriven);
            }
        }
        let h = &self.head;
        if h.protocol == Protocol::Xy2 && h.xy2.mode == Mode::Extended18 && h.xy2.enhanced_commands
        {
            return Err(ConfigError::EnhancedCommandsIn18Bit);
        }
        let o = &self.output;
        if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&o.frame_rate_hz) {
            return Err(ConfigError::FrameRate(o.frame_rate_hz));
        }
        if h.protocol == Protocol::Hans {
            if o.timing == Timing::Slaved {
                return Err(ConfigError::HansNotSlavable);
            }
            if o.frame_rate_hz != HANS_RATE_HZ {
                return Err(ConfigError::HansFixedRate(o.frame_rate_hz));
            }
        }
        let a = &self.axes;
        for (key, axis, offset) in [
            ("axes.offset_x", Axis::X, a.offset_x),
            ("axes.offset_y", Axis::Y, a.offset_y),
            ("axes.offset_z", Axis::Z, a.offset_z),
        ] {
            // A shift of the whole field or more is certainly a mistake.
            let max = (1i64 << h.width(axis)) - 1;
            range(key, i64::from(offset), -max, max)?;
        }
        range("z.fixed", i64::from(self.z.fixed), 0, i64::from(MAX20))?;
        let f = &self.failsafe;
        range(
            "failsafe.input_timeout_us",
            i64::from(f.input_timeout_us),
            10,
            1_000_000,
        )?;
        range("failsafe.hold_us", i64::from(f.hold_us), 0, 10_000_000)?;
        for (key, v) in [
            ("failsafe.park_x", f.park_x),
            ("failsafe.park_y", f.park_y),
            ("failsafe.park_z", f.park_z),
            ("failsafe.park_u", f.park_u),
            ("failsafe.park_w", f.park_w),
        ] {
            range(key, i64::from(v), 0, i64::from(MAX20))?;
        }
        range(
            "failsafe.recovery_frames",
            i64::from(f.recovery_frames),
            1,
            1_000_000,
        )?;
        if f.status_timeout_us != 0 {
            range(
                "failsafe.status_timeout_us",
                i64::from(f.status_timeout_us),
                1_000,
                10_000_000,
            )?;
        }
        if self.laser.gate == GateSource::HansMoPa && c.protocol != Protocol::Hans {
            return Err(ConfigError::GateNeedsHans);
        }
        Ok(())
    }
}
