//! Converting waveforms to exactly the DMA buffers the firmware hands to `shared`, and
//! back (see the DMA layouts, to be documented in `shared/src/layout.rs`):
//!
//! - [`sample`] — XY2-100 port words at CLK falling edges, XY3-100 SPI-slave bytes plus
//!   frame end positions, HANS-100 oversampled `u32` words;
//! - [`drive`] — BSRR words (XY2/XY3 out) and a 12.5 MHz bitstream (HANS out) to waveforms;
//! - [`uart`] — 8N1 UART bytes to a waveform and back (XY3-100 backchannel);
//! - [`serial`] — a generator of XY2-100 / XY3-100 CLK/SYNC/data waveforms from already
//!   encoded frame words.
//!
//! Signals are looked up by *role* name ([`roles`]); read captures with
//! [`crate::vcd_io::read_vcd_roles`] to rename file signals to roles.
//!
//! Times are computed in `f64` picoseconds and rounded once per edge, so long runs at
//! non-integer periods (e.g. 2.4 MHz) do not accumulate rounding drift.

pub mod drive;
pub mod sample;
pub mod serial;
pub mod uart;

use std::fmt;

use crate::wave::{Ps, Signal, Waveform};

/// Standard signal (role) names used by the line converters.
pub mod roles {
    /// Bit clock (XY2-100 CLOCK / XY3-100 CLK).
    pub const CLK: &str = "CLK";
    /// Frame sync (XY2-100 SYNC, active high; XY3-100 SYNC, active low).
    pub const SYNC: &str = "SYNC";
    /// X data line.
    pub const X: &str = "X";
    /// Y data line.
    pub const Y: &str = "Y";
    /// Z data line.
    pub const Z: &str = "Z";
    /// U data line (XY3-100).
    pub const U: &str = "U";
    /// W data line (XY3-100).
    pub const W: &str = "W";
    /// The data lines in axis order (indexed by `Axis::index`).
    pub const AXES: [&str; 5] = [X, Y, Z, U, W];
    /// Status line (head -> controller).
    pub const STATUS: &str = "STATUS";
    /// HANS-100 channel names, CH1..CH5.
    pub const HANS_CHANNELS: [&str; 5] = ["CH1", "CH2", "CH3", "CH4", "CH5"];
    /// UART line (XY3-100 backchannel).
    pub const UART: &str = "UART";

    /// The SCK input of one XY3-100 data line's SPI slave when it differs from the
    /// shared [`CLK`] (`CLK.X` for line `X`): each slave has its own SCK pin fed
    /// from one clock bus, so a glitch can clock one slave and not the others
    /// (`crate::impair::sck_glitch`). A waveform without it clocks the slave on
    /// [`CLK`].
    pub fn spi_sck(line: &str) -> String {
        format!("{CLK}.{line}")
    }
}

/// Errors of the line converters.
#[derive(Debug, Clone, PartialEq)]
pub enum LineError {
    /// A signal the conversion needs is not in the waveform.
    MissingSignal {
        /// The missing name.
        name: String,
        /// Names the waveform has.
        available: Vec<String>,
    },
    /// A numeric parameter is out of range.
    BadParameter {
        /// Which parameter.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// A pin map uses a bit index outside the port or uses one bit twice.
    BadPinMap {
        /// The offending bit index.
        bit: u8,
    },
    /// The data lanes given to a generator disagree (frame count or frame length).
    LaneMismatch {
        /// Frame index where they disagree.
        frame: usize,
    },
    /// A data lane's name is `CLK`, `SYNC` or used by another lane.
    BadLaneName {
        /// The name.
        name: String,
    },
    /// A frame word's bit count is not allowed (XY2: 20; XY3: 24 or 32; max 32).
    BadWordLength {
        /// Frame index.
        frame: usize,
        /// The bit count.
        bits: u8,
    },
    /// The frame does not fit in the configured frame period.
    FramePeriodTooShort {
        /// Needed period in picoseconds.
        needed_ps: f64,
        /// Configured period in picoseconds.
        period_ps: f64,
    },
}

impl fmt::Display for LineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::MissingSignal { name, available } => write!(
                f,
                "signal `{name}` missing; the waveform has: {}",
                available.join(", ")
            ),
            Self::BadParameter { what, value } => {
                write!(f, "parameter {what} = {value} is out of range")
            }
            Self::BadPinMap { bit } => {
                write!(f, "pin map bit {bit} is outside the port or used twice")
            }
            Self::LaneMismatch { frame } => {
                write!(
                    f,
                    "data lanes disagree in frame count or length at frame {frame}"
                )
            }
            Self::BadLaneName { name } => {
                write!(
                    f,
                    "data lane name `{name}` clashes with CLK, SYNC or another lane"
                )
            }
            Self::BadWordLength { frame, bits } => {
                write!(f, "frame {frame}: {bits}-bit word is not allowed here")
            }
            Self::FramePeriodTooShort {
                needed_ps,
                period_ps,
            } => write!(
                f,
                "frame needs {needed_ps:.0} ps but the frame period is {period_ps:.0} ps"
            ),
        }
    }
}

impl std::error::Error for LineError {}

/// Looks up a signal or reports which ones exist.
pub(crate) fn signal<'a>(wave: &'a Waveform, name: &str) -> Result<&'a Signal, LineError> {
    wave.get(name).ok_or_else(|| LineError::MissingSignal {
        name: name.to_owned(),
        available: wave.names(),
    })
}

/// Checks a positive, finite parameter.
pub(crate) fn positive(what: &'static str, value: f64) -> Result<f64, LineError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(LineError::BadParameter { what, value })
    }
}

/// Rounds an `f64` picosecond time to [`Ps`] (negative clamps to 0).
pub(crate) fn ps(t: f64) -> Ps {
    // `as` saturates for out-of-range floats, which is the clamping wanted here.
    t.round().max(0.0) as Ps
}

/// Checks that bit indices are below `width` and distinct.
pub(crate) fn check_bits(bits: &[u8], width: u8) -> Result<(), LineError> {
    for (i, &b) in bits.iter().enumerate() {
        if b >= width || bits.get(..i).is_some_and(|prev| prev.contains(&b)) {
            return Err(LineError::BadPinMap { bit: b });
        }
    }
    Ok(())
}
