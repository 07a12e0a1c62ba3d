//! The protocol-neutral model: one forward frame and one head status that every
//! protocol converts to and from, so the bridge needs 3 + 3 converters instead of 9.
//!
//! # Positions
//! All three protocols carry positions as **offset binary** (0 = one end of the field,
//! `2^(n-1)` = centre, `2^n - 1` = the other end; XY3-100 by our decision, see
//! `xy3-100-notes.md` erratum 7) and at different widths: 16 bits (XY2-100), 18 bits
//! (XY2-100E), 20 bits (XY3-100 24-bit frames, HANS-100 X/Y), 26 bits (XY3-100 32-bit
//! frames). XY3-100 section 5.1 defines the widths as MSB-aligned: a narrower sender
//! zeroes the low bits and a narrower receiver ignores them. [`Position`] therefore
//! stores every value MSB-aligned in 32 bits together with the width it arrived with.
//!
//! Widening is an exact shift. Narrowing **rounds to nearest (ties upward) and
//! saturates at full scale**: truncating would move every narrowed position up to one
//! LSB towards the zero end of the field (a systematic offset of half an LSB on
//! average), and plain rounding would wrap the top codes to 0, i.e. throw the mirror
//! from one end of the field to the other.

use core::num::NonZeroU32;

use heapless::Vec;

/// One of the five axes a scan head can have (XY3-100 names all five; XY2-100 and
/// HANS-100 use X, Y and Z).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Axis {
    /// First deflection axis.
    X = 0,
    /// Second deflection axis.
    Y = 1,
    /// Focus / third axis.
    Z = 2,
    /// First auxiliary axis (XY3-100 only).
    U = 3,
    /// Second auxiliary axis (XY3-100 only).
    W = 4,
}

impl Axis {
    /// All axes in index order.
    pub const ALL: [Axis; 5] = [Axis::X, Axis::Y, Axis::Z, Axis::U, Axis::W];

    /// The axis' index into per-axis arrays (X = 0 … W = 4).
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// Why a raw value cannot become a [`Position`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PositionError {
    /// The width is outside 1..=32 bits.
    BadWidth(u8),
    /// The value does not fit the stated width.
    TooWide {
        /// The offending value.
        value: u32,
        /// The width it was claimed to have.
        bits: u8,
    },
}

impl core::fmt::Display for PositionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadWidth(b) => write!(f, "position width {b} is outside 1..=32 bits"),
            Self::TooWide { value, bits } => {
                write!(f, "position value {value:#x} does not fit {bits} bits")
            }
        }
    }
}

/// A mirror position on one axis, offset binary, kept MSB-aligned in 32 bits together
/// with the width it was received at (see the module docs for the scaling rules).
///
/// The width is kept as a `NonZeroU32` (it is always 1..=32): `Option<Position>` is
/// then no larger than `Position` and both are two plain words without padding, so
/// the frames the bridge moves every output slot copy word by word.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Position {
    aligned: u32,
    bits: NonZeroU32,
}

/// `bits` clamped into 1..=32.
const fn width(bits: u8) -> NonZeroU32 {
    match NonZeroU32::new(if bits > 32 { 32 } else { bits as u32 }) {
        Some(b) => b,
        None => NonZeroU32::MIN,
    }
}

impl Position {
    /// The centre of the field at any width.
    pub const CENTRE: Position = Position {
        aligned: 0x8000_0000,
        bits: NonZeroU32::MIN,
    };

    /// A position from a raw `bits`-wide offset-binary value.
    pub const fn from_raw(value: u32, bits: u8) -> Result<Self, PositionError> {
        if bits == 0 || bits > 32 {
            return Err(PositionError::BadWidth(bits));
        }
        if bits < 32 && value >> bits != 0 {
            return Err(PositionError::TooWide { value, bits });
        }
        Ok(Position {
            aligned: if bits == 32 {
                value
            } else {
                value << (32 - bits)
            },
            bits: width(bits),
        })
    }

    /// A position of this width with MSB-aligned value `aligned`, whose bits below
    /// the width must be zero (for the bridge's per-axis mapping, which works in the
    /// aligned form and keeps that true).
    pub(crate) const fn with_aligned(self, aligned: u32) -> Position {
        Position {
            aligned,
            bits: self.bits,
        }
    }

    /// The width the value arrived with.
    pub const fn bits(self) -> u8 {
        // At most 32.
        self.bits.get() as u8
    }

    /// The value MSB-aligned in 32 bits (full scale = `0xFFFF_FFFF` region).
    pub const fn aligned(self) -> u32 {
        self.aligned
    }

    /// The value at `bits` width (1..=32): exact when widening or keeping the width,
    /// rounded to nearest (ties upward) and saturated at full scale when narrowing.
    /// Widths outside 1..=32 are clamped into that range.
    pub const fn to_raw(self, bits: u8) -> u32 {
        let bits = width(bits).get();
        if bits == 32 {
            return self.aligned;
        }
        Self::round(self.aligned, bits) >> (32 - bits)
    }

    /// `aligned` rounded to `bits` (1..=31) MSB-aligned bits, ties upward, saturated
    /// at full scale. Widening is exact too: the bits below an arrived width are zero,
    /// so adding half an LSB of the wider width and masking changes nothing.
    const fn round(aligned: u32, bits: u32) -> u32 {
        let mask = u32::MAX << (32 - bits);
        if aligned & mask == mask {
            // Full scale: rounding up would wrap to 0 (the other end of the field).
            mask
        } else {
            // No overflow: aligned < mask here and half < one LSB of `bits`.
            aligned.wrapping_add(1 << (31 - bits)) & mask
        }
    }

    /// Re-expresses the position at `bits` width (see [`Position::to_raw`]).
    pub const fn resized(self, bits: u8) -> Position {
        let bits = width(bits);
        Position {
            aligned: if bits.get() == 32 {
                self.aligned
            } else {
                Self::round(self.aligned, bits.get())
            },
            bits,
        }
    }

    /// The mirror image about the centre (used by the bridge's axis inversion):
    /// `2^n - 1 - v` at the position's own width, so 0 and full scale swap exactly.
    pub const fn inverted(self) -> Position {
        // In the MSB-aligned form that is the complement of the top `n` bits.
        let mask = u32::MAX << (32 - self.bits.get());
        Position {
            aligned: !self.aligned & mask,
            bits: self.bits,
        }
    }
}

/// A command carried in the forward direction, in the form its protocol defines.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// An XY3-100 control command: the 20-bit code of a command frame (XY3-100
    /// section 5.1.1). `xy3::Command` types it.
    Xy3(u32),
    /// An XY2-100 enhanced command frame (`111` header): 8-bit command, 8-bit parameter.
    Xy2Enhanced {
        /// Command byte.
        command: u8,
        /// Parameter byte.
        parameter: u8,
    },
}

/// Laser control as HANS-100 carries it in DATA3 (controller -> device extension
/// codes other than 0, HANS-100 spec "meaning of the data", controller -> device).
/// It is the only protocol of the three with laser control on the scanner link.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LaserControl {
    /// Code 1: sixteen remote digital outputs.
    RemoteOutputs(u16),
    /// Code 3: laser power (0..=255) and the MO / PA / red-pointer switches.
    Power {
        /// Laser power, D7..D0.
        power: u8,
        /// Master oscillator on (D8).
        mo: bool,
        /// Power amplifier on (D9).
        pa: bool,
        /// Red pointer diode on (D10).
        red_pointer: bool,
        /// D15..D11, not defined by the spec; kept so a round trip is exact.
        reserved: u8,
    },
    /// Code 4: Q-switch period in 20 ns units (the spec's "50/us").
    QPeriod(u16),
    /// Code 5: standby (simmer) frequency setting in 20 ns units.
    StandbyFrequency(u16),
    /// Code 6: pulse-width mode.
    PulseWidthMode(u16),
    /// Code 9: standby power.
    StandbyPower(u16),
    /// Any other controller -> device code (2, 7, 8, 10..=15) with its 16 data bits.
    Other {
        /// The 4-bit extension code.
        code: u8,
        /// CTRL_DATA1, DATA3 bits 19..4.
        data: u16,
    },
}

/// One forward frame: what a controller asked for in one frame period.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ForwardFrame {
    /// Position per axis, indexed by [`Axis::index`]; `None` where the frame carried
    /// no position for that axis (command frame, missing channel, channel in error).
    pub axes: [Option<Position>; 5],
    /// A command carried by this frame, if any.
    pub command: Option<Command>,
    /// Laser control carried by this frame, if any.
    pub laser: Option<LaserControl>,
}

impl ForwardFrame {
    /// The position on `axis`, if present.
    pub const fn axis(&self, axis: Axis) -> Option<Position> {
        self.axes[axis.index()]
    }
}

/// A set of head alarms (faults that must stop marking), as bit flags.
///
/// Hand-written rather than `bitflags!` because the flags need `defmt::Format`,
/// which the `bitflags` macro's inner type does not implement.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Alarms(pub u32);

impl Alarms {
    /// Supply voltage / power stage fault.
    pub const POWER: Alarms = Alarms(1 << 0);
    /// Over-temperature alarm.
    pub const TEMPERATURE: Alarms = Alarms(1 << 1);
    /// X position not reached / following error on X.
    pub const POSITION_X: Alarms = Alarms(1 << 2);
    /// Y position not reached / following error on Y.
    pub const POSITION_Y: Alarms = Alarms(1 << 3);
    /// Z position not reached / following error on Z.
    pub const POSITION_Z: Alarms = Alarms(1 << 4);
    /// The head reports bad or missing frames from its controller (communication).
    pub const COMMUNICATION: Alarms = Alarms(1 << 5);
    /// Laser source alarm (any HANS-100 code-10 alarm bit).
    pub const LASER: Alarms = Alarms(1 << 6);
    /// Other electrical fault (XY3-100 error code 5, unspecified level faults).
    pub const ELECTRICAL: Alarms = Alarms(1 << 7);
    /// Other mechanical / adjustment fault (XY3-100 codes 3, 6, 7).
    pub const MECHANICAL: Alarms = Alarms(1 << 8);
    /// A vendor-specific error code (XY3-100 codes 100..=255).
    pub const VENDOR: Alarms = Alarms(1 << 9);
    /// The bridge lost the head's status (raised by the bridge, never by a head).
    pub const STATUS_LOST: Alarms = Alarms(1 << 10);
    /// The bridge lost valid input from the controller (raised by the bridge).
    pub const INPUT_LOST: Alarms = Alarms(1 << 11);

    /// No alarm.
    pub const NONE: Alarms = Alarms(0);

    /// Whether every flag of `other` is set.
    pub const fn contains(self, other: Alarms) -> bool {
        self.0 & other.0 == other.0
    }
    /// Whether any flag is set.
    pub const fn any(self) -> bool {
        self.0 != 0
    }
    /// The union of both sets.
    pub const fn union(self, other: Alarms) -> Alarms {
        Alarms(self.0 | other.0)
    }
    /// Sets or clears the flags of `other`.
    pub fn set(&mut self, other: Alarms, on: bool) {
        if on {
            self.0 |= other.0;
        } else {
            self.0 &= !other.0;
        }
    }
}

/// A set of head warnings (marking may continue), as bit flags.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Warnings(pub u32);

impl Warnings {
    /// Over-temperature warning (HANS-100 code 65 DATA2 bit 7).
    pub const TEMPERATURE: Warnings = Warnings(1 << 0);
    /// Low speed, filtered over 10 ms (HANS-100 code 65 DATA1 bit 5).
    pub const LOW_SPEED_FILTERED: Warnings = Warnings(1 << 1);
    /// Low speed, unfiltered (HANS-100 code 65 DATA2 bit 6).
    pub const LOW_SPEED: Warnings = Warnings(1 << 2);
    /// Laser temperature warning (HANS-100 code 10 D2).
    pub const LASER_TEMPERATURE: Warnings = Warnings(1 << 3);
    /// The laser is emitting (HANS-100 code 10 D15).
    pub const LASER_EMISSION: Warnings = Warnings(1 << 4);

    /// No warning.
    pub const NONE: Warnings = Warnings(0);

    /// Whether every flag of `other` is set.
    pub const fn contains(self, other: Warnings) -> bool {
        self.0 & other.0 == other.0
    }
    /// Whether any flag is set.
    pub const fn any(self) -> bool {
        self.0 != 0
    }
    /// Sets or clears the flags of `other`.
    pub fn set(&mut self, other: Warnings, on: bool) {
        if on {
            self.0 |= other.0;
        } else {
            self.0 &= !other.0;
        }
    }
}

/// Number of components XY3-100 reports per-component values for (section 5.2:
/// head, DSP, then DAC, driver, galvo and mirror for each of X, Y, Z, U, W).
pub const COMPONENTS: usize = 22;

/// Longest identification text XY3-100 allows (section 5.2 text packets).
pub const TEXT_MAX: usize = 200;

/// An identification string (7-bit ASCII).
pub type Text = Vec<u8, TEXT_MAX>;

/// What a head says about itself (XY3-100 text packets).
#[derive(Clone, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Identification {
    /// Manufacturer.
    pub vendor: Text,
    /// Model.
    pub model: Text,
    /// Firmware version.
    pub firmware: Text,
    /// Serial number.
    pub serial: Text,
}

/// The head's health and actual values, as far as its protocol reported them.
/// Fields a protocol cannot carry stay `None` / empty.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HeadStatus {
    /// Active alarms.
    pub alarms: Alarms,
    /// Active warnings.
    pub warnings: Warnings,
    /// Actual positions of X, Y, Z (HANS-100 codes 64 and 14).
    pub actual: [Option<Position>; 3],
    /// Actual velocities of X, Y, Z as the head's opaque 12-bit fields (HANS-100
    /// codes 65 and 15 do not define scale or sign).
    pub velocity: [Option<u16>; 3],
    /// Laser alarm/state word (HANS-100 code 10), raw.
    pub laser_state: Option<u16>,
    /// Remote digital inputs (HANS-100 code 2).
    pub remote_inputs: Option<u16>,
    /// Current laser pulse-width mode (HANS-100 code 7).
    pub pulse_width_mode: Option<u16>,
    /// Temperatures per component in 1/100 °C (XY3-100 type 0x05), `None` where not
    /// supported or not reported.
    pub temperatures: [Option<i16>; COMPONENTS],
    /// Error code per component (XY3-100 type 0x07), `None` where not reported.
    pub error_codes: [Option<u8>; COMPONENTS],
    /// Working hours per component (XY3-100 type 0x09), `None` where not supported.
    pub working_hours: [Option<u32>; COMPONENTS],
    /// Frames with a parity error the head counted on X, Y, Z, U, W (XY3-100 type 0x06).
    pub frame_errors: Option<[u32; 5]>,
    /// Identification texts.
    pub identification: Identification,
}

/// A physical input line of a receiver, for fault reports and per-line counters.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Line {
    /// An XY2-100 / XY3-100 data line (one per axis).
    Axis(Axis),
    /// HANS-100 channel 1..=5.
    HansChannel(u8),
    /// The frame structure as a whole (XY2-100 SYNC, XY3-100 SYNC/CLK, a HANS-100 vote).
    Framing,
    /// The head's status line (XY2-100 STATUS, HANS-100 STATUS).
    Status,
    /// The XY3-100 RS485 backchannel.
    Backchannel,
}

/// What went wrong on a line. Receivers report these; the bridge counts them per line
/// and never forwards what failed.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FaultKind {
    /// A frame failed its protocol check (parity, complement, fixed bits, header).
    CheckFailed,
    /// A frame was truncated, overlong or misaligned (framing).
    Framing,
    /// The receiver lost alignment and found it again.
    Resync,
    /// Input was discarded without being decoded (overrun, garbage, a lost DMA
    /// half, buffers of unequal lengths).
    Dropped,
    /// A HANS-100 channel delivered no pattern in a frame period (dead, stuck,
    /// unplugged, not aligned): reported every period it stays so. Nothing was
    /// received, so nothing was discarded (unlike [`FaultKind::Dropped`]).
    Missing,
    /// Channels that passed their checks disagreed (HANS-100 super mode), or a vote
    /// had no majority; the frame was rejected.
    Disagree,
}

/// What a line-level receiver reports, protocol-neutral: the bridge's input.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LineEvent {
    /// One frame period whose every present channel passed its checks.
    Frame(ForwardFrame),
    /// A fault on a line. What failed is never forwarded; whether the frame period is
    /// lost depends on the receiver: XY2-100 / XY3-100 drop the whole period, while the
    /// HANS-100 vote and super modes may still deliver a frame verified on other
    /// channels (as a separate [`LineEvent::Frame`]).
    Fault {
        /// Where.
        line: Line,
        /// What.
        kind: FaultKind,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[rustfmt::skip]
    const RESIZE: &[(u32, u8, u8, u32)] = &[
        // (raw, from bits, to bits, expected raw)
        (0x0000,   16, 20, 0x0_0000),   // zero widens to zero
        (0x8000,   16, 20, 0x8_0000),   // centre stays centre
        (0xFFFF,   16, 20, 0xF_FFF0),   // full scale widens exactly (low bits zero)
        (0xFFFF,   16, 26, 0x3FF_FC00),
        (0x0_0007, 20, 16, 0x0000),     // 7/16 LSB rounds down
        (0x0_0008, 20, 16, 0x0001),     // exactly half rounds up
        (0x8_0000, 20, 16, 0x8000),     // centre narrows exactly
        (0xF_FFF7, 20, 16, 0xFFFF),     // rounds up to full scale
        (0xF_FFF8, 20, 16, 0xFFFF),     // would round to 0x10000: saturates
        (0xF_FFFF, 20, 16, 0xFFFF),     // full scale saturates, never wraps to 0
        (0x3FF_FFFF, 26, 18, 0x3_FFFF), // full scale 26 -> 18
        (0x200_0000, 26, 18, 0x2_0000), // centre 26 -> 18
        (0x000_0080, 26, 18, 0x0_0001), // half an 18-bit LSB rounds up
        (0x000_007F, 26, 18, 0x0_0000),
        (0x3_FFFF,   18, 16, 0xFFFF),
        (0x0_0001,   18, 16, 0x0000),   // quarter LSB rounds down
        (0x0_0002,   18, 16, 0x0001),   // half LSB rounds up
    ];

    #[test]
    fn resize_table() {
        for &(raw, from, to, want) in RESIZE {
            let p = Position::from_raw(raw, from).unwrap();
            assert_eq!(p.to_raw(to), want, "{raw:#x} {from}->{to}");
            assert_eq!(p.resized(to).to_raw(to), want);
            assert_eq!(p.resized(to).bits(), to);
        }
    }

    #[test]
    fn from_raw_rejects_bad_input() {
        assert_eq!(Position::from_raw(0, 0), Err(PositionError::BadWidth(0)));
        assert_eq!(Position::from_raw(0, 33), Err(PositionError::BadWidth(33)));
        assert_eq!(
            Position::from_raw(0x1_0000, 16),
            Err(PositionError::TooWide {
                value: 0x1_0000,
                bits: 16
            })
        );
        assert_eq!(
            Position::from_raw(u32::MAX, 32).unwrap().to_raw(32),
            u32::MAX
        );
    }

    #[test]
    fn inversion_swaps_ends_and_keeps_width() {
        let p = |v, b| Position::from_raw(v, b).unwrap();
        assert_eq!(p(0, 16).inverted(), p(0xFFFF, 16));
        assert_eq!(p(0xFFFF, 16).inverted(), p(0, 16));
        assert_eq!(p(0x8000, 16).inverted(), p(0x7FFF, 16));
        assert_eq!(p(0x3FF_FFFF, 26).inverted(), p(0, 26));
        assert_eq!(p(7, 32).inverted(), p(u32::MAX - 7, 32));
    }

    proptest! {
        #[test]
        fn widening_is_exact_and_reversible(v in any::<u32>(), from in 1u8..=32, extra in 0u8..=16) {
            let v = if from == 32 { v } else { v & ((1 << from) - 1) };
            let to = from.saturating_add(extra).min(32);
            let p = Position::from_raw(v, from).unwrap();
            let wide = p.to_raw(to);
            prop_assert_eq!(Position::from_raw(wide, to).unwrap().to_raw(from), v);
        }

        #[test]
        fn narrowing_error_is_at_most_half_an_lsb(v in any::<u32>(), to in 1u8..32) {
            let p = Position::from_raw(v, 32).unwrap();
            let n = p.to_raw(to);
            prop_assert!(n < (1u64 << to) as u32 || to == 32);
            let back = u64::from(n) << (32 - to);
            let err = (back as i64 - i64::from(v)).unsigned_abs();
            let half = 1u64 << (31 - to);
            let saturated = n == ((1u64 << to) - 1) as u32;
            prop_assert!(err <= half || saturated, "v={v:#x} to={to} n={n:#x}");
        }

        #[test]
        fn inversion_is_an_involution(v in any::<u32>(), bits in 1u8..=32) {
            let v = if bits == 32 { v } else { v & ((1 << bits) - 1) };
            let p = Position::from_raw(v, bits).unwrap();
            prop_assert_eq!(p.inverted().inverted(), p);
        }

        /// The word-level `to_raw` / `resized` / `inverted` agree with the textbook
        /// arithmetic on the raw value (widths 0 and above 32 included: clamped).
        #[test]
        fn word_ops_match_the_raw_value_model(v in any::<u32>(), from in 1u8..=32, to in 0u8..=40) {
            let v = if from == 32 { v } else { v & ((1 << from) - 1) };
            let p = Position::from_raw(v, from).unwrap();
            let to_c = to.clamp(1, 32);
            let want = if to_c >= from {
                u64::from(v) << (to_c - from)
            } else {
                let shift = from - to_c;
                let max = (1u64 << to_c) - 1;
                ((u64::from(v) + (1 << (shift - 1))) >> shift).min(max)
            };
            prop_assert_eq!(u64::from(p.to_raw(to)), want);
            let r = p.resized(to);
            prop_assert_eq!((r.bits(), u64::from(r.to_raw(to_c))), (to_c, want));
            let max = (1u64 << from) - 1;
            prop_assert_eq!(u64::from(p.inverted().to_raw(from)), max - u64::from(v));
            prop_assert_eq!(p.inverted().bits(), from);
        }
    }
}
