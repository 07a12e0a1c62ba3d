//! The bridge configuration: one [`Config`] for both sides, the translation policy,
//! output timing, fail-safe policy and laser handling, with [`Config::validate`].
//!
//! The rules the types cannot express are checked by [`Config::validate`]
//! (`validate.rs`). Every field has a default ([`Default`]), so a configuration file only states what
//! differs. With the `serde` feature the types (de)serialise with unknown keys
//! rejected; the file form and every key are documented in the repository's
//! `bridge.toml`. Keys below are named as they appear in that file (`head.xy2.mode`).
//!
//! # Units
//! - Absolute positions in the configuration (`z.fixed`, `failsafe.park_*`) are
//!   **20-bit offset binary** (0 = one end of the field, `0x80000` = centre,
//!   `0xFFFFF` = the other end), resized to the head's width with the model's rules.
//!   They are head coordinates: the axis map does not apply to them.
//! - Offsets (`axes.offset_*`) are signed counts of **the head's own LSB** on that
//!   axis (16 or 18 bits for XY2-100, 20 or 26 for XY3-100, 20 for HANS-100 X / Y
//!   and 16 for its Z). That makes an offset exact at any width; the price is that it
//!   must be re-entered when the head protocol or width changes.
//! - Times are microseconds, rates hertz.

use crate::model::Axis;
use crate::xy2::{Mode, Parity, Polarity};
use crate::xy3::rx::Lines;
use crate::xy3::{BackRate, FrameSize};

/// The three protocols the bridge speaks.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum Protocol {
    /// XY2-100 / XY2-100E.
    #[default]
    Xy2,
    /// XY3-100.
    Xy3,
    /// HANS-100.
    Hans,
}

/// How an XY2-100 STATUS line is used.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum StatusForm {
    /// A plain level (OK / fault) with the configured polarity.
    #[default]
    Level,
    /// The SCANLAB-style status word in 20-bit frames.
    Word,
}

/// HANS-100 receiver decode mode (HANS-100 spec, "decoding modes"). Channels are
/// numbered 1..=5 as on the connector (CH1..CH5).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum HansDecode {
    /// Normal mode: decode one channel only.
    Normal(u8),
    /// Enhanced 3-in-1: bitwise 2-of-3 vote over three distinct channels.
    Vote3([u8; 3]),
    /// Enhanced 5-in-1: bitwise 3-of-5 vote over all channels.
    Vote5,
    /// Super mode: every channel decoded and checked on its own.
    Super,
}

impl Default for HansDecode {
    fn default() -> Self {
        HansDecode::Normal(1)
    }
}

/// Controller-side XY2-100 options.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Xy2Controller {
    /// 16-bit positions + commands, or 18-bit positions.
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::ModeDef"))]
    pub mode: Mode,
    /// Parity scope; must be checked (not `Ignore`) on the controller side.
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::ParityDef"))]
    pub parity: Parity,
    /// What the bridge drives on STATUS towards the controller.
    pub status: StatusForm,
    /// Level polarity for [`StatusForm::Level`].
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::PolarityDef"))]
    pub polarity: Polarity,
}

/// How the XY3-100 input's SPI slaves are selected (`controller.xy3.select`).
///
/// RM0433 (§50.4, slave select (SS) pin management) describes a slave's SS input only
/// as a chip select; it does not say what the slave does with the bits of a data
/// frame that SS cuts short, and none of the slave's settings (DSIZE, FTHLV, TSIZE;
/// SSOM / MIDI / MSSI shape a master's SS output only) defines it. A clock glitch
/// that gives one line's SPI 1..7 extra edges in a frame therefore either leaves
/// that line a few bits out of step for good (bits kept) or spoils only that
/// frame (bits dropped at SS release), and such a spoilt 24-bit frame passes its
/// checks about one time in four with nothing before or after it to tell
/// (`shared::xy3::step`, README "Known limits"). With software slave select the
/// question does not arise.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum Xy3Select {
    /// SYNC is every line's hardware SS (NSS pin, SSM = 0): works whatever the
    /// controller's clock does between frames; what a glitch's extra bits do is
    /// the silicon's undocumented choice (see the type's docs).
    #[default]
    Sync,
    /// Software slave select held active (SPI_CFG2.SSM = 1, SPI_CR1.SSI = 0,
    /// RM0433 §50.4, slave select (SS) pin management): the slaves never see SS go inactive, so no
    /// bit is ever dropped and every extra or missed clock edge shifts all later
    /// bits of its line, which the receiver and the step watch see and restart
    /// on. SYNC only marks the frame ends (its EXTI). Needs a controller whose
    /// CLK has no falling edge while SYNC is high (the XY3-100 text does not
    /// promise it): a clock running between frames would shift its edges into
    /// the stream, every period fails its checks and nothing is forwarded (the
    /// input stays in fault, restarting with back-off).
    Always,
}

/// Controller-side XY3-100 options.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Xy3Controller {
    /// The backchannel rate at power-up (in the file: the baud rate as a number).
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::back_rate"))]
    pub back_rate: BackRate,
    /// The data lines the controller drives (in the file: a list of `"x"`, `"y"`,
    /// `"z"`, `"u"`, `"w"`; X and Y required). Which of them the bridge receives:
    /// [`Config::xy3_input_lines`]. Default X, Y, Z: what the bridge received before
    /// this key existed (Z only with `z.source = "input"`).
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::xy3_lines"))]
    pub lines: Lines,
    /// How the input's SPI slaves are selected (in the file: `"sync"` or
    /// `"always"`).
    pub select: Xy3Select,
}

impl Default for Xy3Controller {
    fn default() -> Self {
        Xy3Controller {
            back_rate: BackRate::default(),
            lines: Lines::XYZ,
            select: Xy3Select::Sync,
        }
    }
}

/// Controller-side HANS-100 options.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct HansController {
    /// Receiver decode mode and channel choice.
    pub decode: HansDecode,
}

/// The controller side: its protocol and the options of each protocol (only the
/// selected protocol's options are used and validated).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct ControllerSide {
    /// The protocol the controller speaks.
    pub protocol: Protocol,
    /// XY2-100 options.
    pub xy2: Xy2Controller,
    /// XY3-100 options.
    pub xy3: Xy3Controller,
    /// HANS-100 options.
    pub hans: HansController,
}

/// Head-side XY2-100 options.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Xy2Head {
    /// 16-bit positions + commands, or 18-bit positions.
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::ModeDef"))]
    pub mode: Mode,
    /// Parity scope the head expects and sends.
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::ParityDef"))]
    pub parity: Parity,
    /// Pass XY2-100 enhanced commands from an XY2-100 controller to the head
    /// (default on; impossible in 18-bit mode).
    pub enhanced_commands: bool,
    /// What the head drives on STATUS.
    pub status: StatusForm,
    /// Level polarity for [`StatusForm::Level`].
    #[cfg_attr(feature = "serde", serde(with = "super::serde_impl::PolarityDef"))]
    pub polarity: Polarity,
}

impl Default for Xy2Head {
    fn default() -> Self {
        Xy2Head {
            mode: Mode::Standard16,
            parity: Parity::WholeFrame,
            enhanced_commands: true,
            status: StatusForm::Level,
            polarity: Polarity::LowIsOk,
        }
    }
}

/// Head-side XY3-100 options.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Xy3Head {
    /// Frame size sent to the head (in the file: `frame_bits = 24` or `32`).
    #[cfg_attr(
        feature = "serde",
        serde(rename = "frame_bits", with = "super::serde_impl::frame_bits")
    )]
    pub frame_size: FrameSize,
}

impl Default for Xy3Head {
    fn default() -> Self {
        Xy3Head {
            frame_size: FrameSize::Bits24,
        }
    }
}

/// The head side. HANS-100 heads have no options (the output is fixed at 100 kHz).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct HeadSide {
    /// The protocol the head speaks.
    pub protocol: Protocol,
    /// XY2-100 options.
    pub xy2: Xy2Head,
    /// XY3-100 options.
    pub xy3: Xy3Head,
}

/// The axis map, applied after resizing to the head's width: first the X / Y swap,
/// then inversion about the centre, then the offset (saturating at the field ends).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct AxisMap {
    /// The head's X gets the controller's Y and vice versa.
    pub swap_xy: bool,
    /// Mirror the head's X about the centre.
    pub invert_x: bool,
    /// Mirror the head's Y about the centre.
    pub invert_y: bool,
    /// Mirror the head's Z about the centre.
    pub invert_z: bool,
    /// X offset in head LSBs.
    pub offset_x: i32,
    /// Y offset in head LSBs.
    pub offset_y: i32,
    /// Z offset in head LSBs.
    pub offset_z: i32,
}

/// Where the head's Z comes from.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum ZSource {
    /// The controller's Z (XY2 / XY3 Z line, HANS DATA3 code 0), axis-mapped.
    #[default]
    Input,
    /// A constant, `z.fixed`.
    Fixed,
    /// No Z: the head gets none (transmitters idle the line or hold their last Z).
    None,
}

/// Z configuration.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct ZConfig {
    /// The source.
    pub source: ZSource,
    /// The constant for [`ZSource::Fixed`], 20-bit offset binary.
    pub fixed: u32,
}

impl Default for ZConfig {
    fn default() -> Self {
        ZConfig {
            source: ZSource::Input,
            fixed: CENTRE20,
        }
    }
}

/// What clocks the head-side output.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum Timing {
    /// The bridge's own clock at `output.frame_rate_hz`; rate mismatch is handled by
    /// repeating or skipping frames (counted).
    #[default]
    FreeRunning,
    /// One output frame per valid input frame. While input is lost, the fail-safe
    /// output runs at `output.frame_rate_hz`.
    Slaved,
}

/// Output timing.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct OutputConfig {
    /// Free-running or slaved.
    pub timing: Timing,
    /// Output frame rate, 1 kHz ..= 200 kHz (HANS-100: exactly 100 kHz).
    pub frame_rate_hz: u32,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            timing: Timing::FreeRunning,
            frame_rate_hz: 100_000,
        }
    }
}

/// What the output does once the hold time after an input loss has passed.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum AfterHold {
    /// Send the park position (`failsafe.park_*`) in every frame.
    #[default]
    Park,
    /// Send no frames at all (the head's own communication watchdog takes over).
    Stop,
}

/// Link supervision and fail-safe policy.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct FailSafe {
    /// No valid input frame for this long -> input lost (10 ..= 1 000 000 us).
    pub input_timeout_us: u32,
    /// Keep sending the last valid position this long after the loss (0 ..= 10 s).
    pub hold_us: u32,
    /// Then park or stop.
    pub after_hold: AfterHold,
    /// Park position X, 20-bit offset binary, head coordinates.
    pub park_x: u32,
    /// Park position Y.
    pub park_y: u32,
    /// Park position Z.
    pub park_z: u32,
    /// Park position U (XY3-100 heads that get U: [`Config::xy3_head_lines`]).
    pub park_u: u32,
    /// Park position W (as U).
    pub park_w: u32,
    /// Consecutive valid frames needed to leave the fail-safe states (1 ..= 1 000 000).
    pub recovery_frames: u32,
    /// No head status for this long -> status lost (0 = not supervised, else
    /// 1 000 ..= 10 000 000 us). While supervised, [`LaserConfig::off_on_head_alarm`]
    /// also keeps the gate off until the head's first status is in.
    pub status_timeout_us: u32,
}

impl Default for FailSafe {
    fn default() -> Self {
        FailSafe {
            input_timeout_us: 1_000,
            hold_us: 10_000,
            after_hold: AfterHold::Park,
            park_x: CENTRE20,
            park_y: CENTRE20,
            park_z: CENTRE20,
            park_u: CENTRE20,
            park_w: CENTRE20,
            recovery_frames: 100,
            status_timeout_us: 200_000,
        }
    }
}

/// What drives the bridge's laser gate output (besides the fail-safe, which always
/// forces it off).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(rename_all = "snake_case")
)]
pub enum GateSource {
    /// On while the link runs (valid input, not in a fail-safe state).
    #[default]
    LinkOk,
    /// As `LinkOk`, and additionally the latest HANS-100 code-3 MO and PA switches
    /// must both be on (HANS-100 controllers only).
    HansMoPa,
}

/// Laser-control handling.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct LaserConfig {
    /// Laser gate source.
    pub gate: GateSource,
    /// Force the gate off while the head reports any alarm, and, where the status is
    /// supervised (`failsafe.status_timeout_us != 0`), until its first status is in
    /// and while it is lost.
    pub off_on_head_alarm: bool,
    /// Forward HANS-100 laser control (DATA3 codes 1..=15) to a HANS-100 head. When
    /// off, or when the head is not HANS-100, laser control only drives the bridge's
    /// outputs and is counted as not carried.
    pub forward: bool,
}

impl Default for LaserConfig {
    fn default() -> Self {
        LaserConfig {
            gate: GateSource::LinkOk,
            off_on_head_alarm: true,
            forward: true,
        }
    }
}

/// The whole bridge configuration.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize),
    serde(default, deny_unknown_fields)
)]
pub struct Config {
    /// The controller side.
    pub controller: ControllerSide,
    /// The head side.
    pub head: HeadSide,
    /// The axis map.
    pub axes: AxisMap,
    /// The Z source.
    pub z: ZConfig,
    /// Output timing.
    pub output: OutputConfig,
    /// Supervision and fail-safe.
    pub failsafe: FailSafe,
    /// Laser-control handling.
    pub laser: LaserConfig,
}

impl Config {
    /// The XY3-100 data lines the bridge receives from the controller: of the lines
    /// it drives (`controller.xy3.lines`), those whose data the bridge uses. Z only
    /// with `z.source = "input"`; U and W only for an XY3-100 head, the only one that
    /// carries them. A line received but never used could only stop frames (a period
    /// is forwarded only if every received line decodes).
    pub const fn xy3_input_lines(&self) -> Lines {
        let mut lines = self.controller.xy3.lines;
        if !matches!(self.z.source, ZSource::Input) {
            lines = lines.without(Axis::Z);
        }
        if !matches!(self.head.protocol, Protocol::Xy3) {
            lines = lines.without(Axis::U).without(Axis::W);
        }
        lines
    }

    /// The data lines an XY3-100 head output drives (meaningful for an XY3-100
    /// head only): X and Y always, Z unless `z.source = "none"`, and U / W exactly
    /// when the bridge receives them from an XY3-100 controller
    /// ([`Config::xy3_input_lines`]). U and W have no other source (no other
    /// protocol carries them, and there is no fixed U / W like `z.fixed`), so a
    /// head line is driven only while it has the controller's value to carry, and
    /// then in every frame: hold repeats the last received U / W like X / Y / Z,
    /// park sends `failsafe.park_u` / `park_w`.
    pub const fn xy3_head_lines(&self) -> Lines {
        let mut lines = Lines::ALL;
        if matches!(self.z.source, ZSource::None) {
            lines = lines.without(Axis::Z);
        }
        let received = self.xy3_input_lines();
        let from_xy3 = matches!(self.controller.protocol, Protocol::Xy3);
        if !(from_xy3 && received.has(Axis::U)) {
            lines = lines.without(Axis::U);
        }
        if !(from_xy3 && received.has(Axis::W)) {
            lines = lines.without(Axis::W);
        }
        lines
    }
}

/// Centre of the field in 20-bit offset binary.
pub const CENTRE20: u32 = 0x8_0000;
/// Largest 20-bit offset-binary value.
pub const MAX20: u32 = 0xF_FFFF;
/// The only frame rate HANS-100 knows (125 bits at 12.5 Mbit/s).
pub const HANS_RATE_HZ: u32 = 100_000;
/// Lowest configurable output frame rate.
pub const MIN_RATE_HZ: u32 = 1_000;
/// Highest configurable output frame rate (the "-200" variants).
pub const MAX_RATE_HZ: u32 = 200_000;
