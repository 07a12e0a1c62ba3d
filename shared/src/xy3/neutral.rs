//! Conversions between XY3-100 frames and the protocol-neutral model
//! ([`crate::model`]).
//!
//! Positions are offset binary (notes erratum 7) and MSB-aligned (§5.1): a 24-bit
//! frame carries a 20-bit [`Position`], a 32-bit frame a 26-bit one. Sending narrows
//! or widens with [`Position::to_raw`] (exact shift when widening, rounding with
//! saturation when narrowing). Commands are only taken from the X channel (§5.1.1).

use core::fmt;

use super::command::Command;
use super::frame::{EncodeError, Frame, FrameSize, CODE_BITS};
use crate::model::{self, Axis, ForwardFrame, Position};

/// What one decoded frame means in the neutral model.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Neutral {
    /// A position at the frame's full width (20 or 26 bits).
    Position(Position),
    /// A command frame's 20-bit code as [`model::Command::Xy3`]; the ignored bits of a
    /// 32-bit command frame are dropped.
    Command(model::Command),
}

/// What [`apply`] did with a frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Applied {
    /// The position was stored for the channel's axis.
    Position,
    /// The command was stored (X channel).
    Command,
    /// A command on a channel other than X, ignored as §5.1.1 allows.
    CommandIgnored,
}

/// Why a neutral command cannot become an XY3-100 command frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CommandFrameError {
    /// The command belongs to another protocol; translating it is the bridge's policy.
    Foreign,
    /// The XY3-100 code does not fit 20 bits.
    CodeTooWide(u32),
}

impl fmt::Display for CommandFrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Foreign => f.write_str("not an XY3-100 command"),
            Self::CodeTooWide(c) => write!(f, "command code {c:#x} does not fit 20 bits"),
        }
    }
}

/// The neutral meaning of a frame. Fails only for hand-built frames with fields wider
/// than the wire allows (decoded frames always convert).
pub fn to_neutral(frame: &Frame) -> Result<Neutral, EncodeError> {
    let position = |value: u32, size: FrameSize| {
        let bits = size.position_bits();
        Position::from_raw(value, bits)
            .map(Neutral::Position)
            .map_err(|_| EncodeError::PositionTooWide { value, bits })
    };
    let command = |code: u32| {
        if code >> CODE_BITS == 0 {
            Ok(Neutral::Command(model::Command::Xy3(code)))
        } else {
            Err(EncodeError::CodeTooWide(code))
        }
    };
    match *frame {
        Frame::Position24(v) => position(v, FrameSize::Bits24),
        Frame::Position32(v) => position(v, FrameSize::Bits32),
        Frame::Command24(code) | Frame::Command32 { code, .. } => command(code),
    }
}

/// Stores a frame received on `axis`'s channel into `out`: a position into
/// `out.axes`, a command into `out.command` if it came on X (commands repeated on
/// other channels are ignored, §5.1.1).
pub fn apply(frame: &Frame, axis: Axis, out: &mut ForwardFrame) -> Result<Applied, EncodeError> {
    Ok(match to_neutral(frame)? {
        Neutral::Position(p) => {
            if let Some(slot) = out.axes.get_mut(axis.index()) {
                *slot = Some(p);
            }
            Applied::Position
        }
        Neutral::Command(c) if axis == Axis::X => {
            out.command = Some(c);
            Applied::Command
        }
        Neutral::Command(_) => Applied::CommandIgnored,
    })
}

/// The position frame of `size` for `position`, narrowed (rounded, saturated) or
/// widened (exact) to 20 or 26 bits as [`Position::to_raw`] does.
pub const fn position_frame(position: Position, size: FrameSize) -> Frame {
    let raw = position.to_raw(size.position_bits());
    match size {
        FrameSize::Bits24 => Frame::Position24(raw),
        FrameSize::Bits32 => Frame::Position32(raw),
    }
}

/// The command frame of `size` for a neutral command; the ignored bits of a 32-bit
/// frame are sent as 0. Send it on X (and, if wanted, repeat it on other channels).
pub const fn command_frame(
    command: &model::Command,
    size: FrameSize,
) -> Result<Frame, CommandFrameError> {
    let code = match *command {
        model::Command::Xy3(code) => code,
        model::Command::Xy2Enhanced { .. } => return Err(CommandFrameError::Foreign),
    };
    if code >> CODE_BITS != 0 {
        return Err(CommandFrameError::CodeTooWide(code));
    }
    Ok(match size {
        FrameSize::Bits24 => Frame::Command24(code),
        FrameSize::Bits32 => Frame::Command32 { code, unused: 0 },
    })
}

impl From<Command> for model::Command {
    fn from(command: Command) -> Self {
        model::Command::Xy3(command.code())
    }
}
