//! The `bridge-sim` tool: decode captures, encode and generate waveforms (issue 7).
//! The README (section "bridge-sim") documents the commands and the formats.
//!
//! Pieces:
//! - [`jsonl`] — the JSON-lines formats (one record per frame / packet), parse and print;
//! - [`generate`] — test patterns -> records, and the impairment options;
//! - [`encode`] — records -> waveform (the path `generate` and `encode` share);
//! - [`capture`] — capture -> the firmware's receive DMA buffers (for `decode` and
//!   `bridge`);
//! - [`decode`] — capture -> the `shared` receivers -> records;
//! - [`bridge`] — the whole bridge ([`crate::pipeline`]) on a capture, written to an
//!   output directory;
//! - [`demo`] — the no-argument demo (XY2-100 controller -> HANS-100 head, a line
//!   breaking halfway);
//! - [`cli`] — the command line (clap) and the commands.
//!
//! Signals in files use the default names of [`names`]; `--map ROLE=NAME` renames them.

pub mod bridge;
pub mod capture;
pub mod cli;
pub mod decode;
pub mod demo;
pub mod encode;
pub mod generate;
pub mod jsonl;

use std::fmt;

use crate::impair::ImpairError;
use crate::line::LineError;
use crate::vcd_io::VcdError;
use crate::wave::WaveError;

/// The four links the tool handles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Protocol {
    /// XY2-100 / XY2-100E forward link.
    Xy2,
    /// XY3-100 forward link.
    Xy3,
    /// HANS-100 forward link.
    Hans,
    /// XY3-100 RS485 backchannel (head -> controller).
    #[value(name = "xy3-back")]
    Xy3Back,
}

impl fmt::Display for Protocol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Xy2 => "xy2",
            Self::Xy3 => "xy3",
            Self::Hans => "hans",
            Self::Xy3Back => "xy3-back",
        })
    }
}

/// Default signal names in VCD files (the names; lower case).
pub mod names {
    /// Bit clock.
    pub const CLK: &str = "clk";
    /// Frame sync.
    pub const SYNC: &str = "sync";
    /// XY2-100 data lines, in JSON key order.
    pub const XY2_DATA: [&str; 3] = ["x", "y", "z"];
    /// XY3-100 data lines, in JSON key order.
    pub const XY3_DATA: [&str; 5] = ["x", "y", "z", "u", "w"];
    /// HANS-100 channels.
    pub const HANS: [&str; 5] = ["ch1", "ch2", "ch3", "ch4", "ch5"];
    /// XY3-100 backchannel UART line.
    pub const BACK: &str = "back";
    /// XY2-100 / HANS-100 STATUS line (head -> controller).
    pub const STATUS: &str = "status";
    /// The bridge's laser gate output (in `bridge`'s head-side file).
    pub const LASER_GATE: &str = "laser_gate";
}

/// Everything that can stop a command. Each one ends the tool with a one-line message
/// and a non-zero exit code.
#[derive(Debug, Clone, PartialEq)]
pub enum SimError {
    /// Reading or writing a VCD file failed, or the capture is unusable.
    Vcd(VcdError),
    /// A waveform <-> buffer conversion failed.
    Line(LineError),
    /// An impairment could not be applied.
    Impair(ImpairError),
    /// Building a waveform failed.
    Wave(WaveError),
    /// A file could not be read or written.
    Io {
        /// The file.
        path: String,
        /// The system's message.
        message: String,
    },
    /// A JSON-lines input has a bad line.
    Json {
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// A command-line value is out of range or malformed.
    BadOption {
        /// The option.
        option: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The bridge configuration file does not parse or does not validate.
    Config {
        /// The file.
        path: String,
        /// What is wrong, naming the key.
        message: String,
    },
    /// The bridge pipeline refused its set-up or its input.
    Bridge(String),
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Vcd(e) => write!(f, "{e}"),
            Self::Line(e) => write!(f, "{e}"),
            Self::Impair(e) => write!(f, "{e}"),
            Self::Wave(e) => write!(f, "{e}"),
            Self::Io { path, message } => write!(f, "{path}: {message}"),
            Self::Json { line, message } => write!(f, "line {line}: {message}"),
            Self::BadOption { option, message } => write!(f, "{option}: {message}"),
            Self::Config { path, message } => write!(f, "{path}: {message}"),
            Self::Bridge(m) => write!(f, "bridge: {m}"),
        }
    }
}

impl std::error::Error for SimError {}

impl From<VcdError> for SimError {
    fn from(e: VcdError) -> Self {
        Self::Vcd(e)
    }
}

impl From<LineError> for SimError {
    fn from(e: LineError) -> Self {
        Self::Line(e)
    }
}

impl From<ImpairError> for SimError {
    fn from(e: ImpairError) -> Self {
        Self::Impair(e)
    }
}

impl From<WaveError> for SimError {
    fn from(e: WaveError) -> Self {
        Self::Wave(e)
    }
}
