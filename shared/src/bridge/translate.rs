//! Forward translation: a controller's [`ForwardFrame`] into the head's, at the
//! head's widths, through the axis map, with commands and laser control kept only
//! where the head protocol carries them.

use super::config::{AxisMap, Config, HeadSide, Protocol, ZConfig, ZSource};
use crate::model::{Axis, Command, ForwardFrame, Position};
use crate::xy2::Mode;
use crate::xy3::{self, BackRate};

/// The translation policy, fixed at construction.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Translator {
    head: HeadSide,
    axes: AxisMap,
    z: ZConfig,
    laser_forward: bool,
}

/// One translated frame and what did not fit.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct Translated {
    /// The frame for the head.
    pub frame: ForwardFrame,
    /// The input's command could not be carried.
    pub command_dropped: bool,
    /// The input's laser control was not forwarded.
    pub laser_dropped: bool,
    /// The input carried an XY3-100 backchannel rate command.
    pub back_rate: Option<BackRate>,
}

/// `p` at `bits`, inverted if asked, shifted by `offset` LSBs, clamped to the field:
/// an offset must never wrap a position to the other end of the field.
pub(super) fn map_position(p: Position, bits: u8, invert: bool, offset: i32) -> Position {
    let p = p.resized(bits);
    let p = if invert { p.inverted() } else { p };
    if offset == 0 {
        return p;
    }
    let max = (1i64 << bits.min(32)) - 1;
    let raw = (i64::from(p.to_raw(bits)) + i64::from(offset)).clamp(0, max);
    u32::try_from(raw)
        .ok()
        .and_then(|r| Position::from_raw(r, bits).ok())
        .unwrap_or(p)
}

/// A 20-bit configuration position at the head's width for `axis`.
pub(crate) fn config_position(head: &HeadSide, axis: Axis, raw20: u32) -> Option<Position> {
    Position::from_raw(raw20, 20)
        .ok()
        .map(|p| p.resized(head.width(axis)))
}

impl Translator {
    pub fn new(c: &Config) -> Self {
        Translator {
            head: c.head,
            axes: c.axes,
            z: c.z,
            laser_forward: c.laser.forward,
        }
    }

    /// Whether the head carries `command`.
    fn carries(&self, command: &Command) -> bool {
        match command {
            Command::Xy3(_) => self.head.protocol == Protocol::Xy3,
            Command::Xy2Enhanced { .. } => {
                self.head.protocol == Protocol::Xy2
                    && self.head.xy2.mode == Mode::Standard16
                    && self.head.xy2.enhanced_commands
            }
        }
    }

    pub fn translate(&self, input: &ForwardFrame) -> Translated {
        let a = &self.axes;
        let w = |axis| self.head.width(axis);
        let (src_x, src_y) = if a.swap_xy {
            (Axis::Y, Axis::X)
        } else {
            (Axis::X, Axis::Y)
        };
        let mut out = ForwardFrame::default();
        out.axes[Axis::X.index()] = input
            .axis(src_x)
            .map(|p| map_position(p, w(Axis::X), a.invert_x, a.offset_x));
        out.axes[Axis::Y.index()] = input
            .axis(src_y)
            .map(|p| map_position(p, w(Axis::Y), a.invert_y, a.offset_y));
        out.axes[Axis::Z.index()] = match self.z.source {
            ZSource::Input => input
                .axis(Axis::Z)
                .map(|p| map_position(p, w(Axis::Z), a.invert_z, a.offset_z)),
            ZSource::Fixed => config_position(&self.head, Axis::Z, self.z.fixed),
            ZSource::None => None,
        };
        if self.head.protocol == Protocol::Xy3 {
            // Only XY3-100 has U and W; they pass resized, without mapping.
            for axis in [Axis::U, Axis::W] {
                out.axes[axis.index()] = input.axis(axis).map(|p| p.resized(w(axis)));
            }
        }
        let back_rate = match input.command {
            Some(Command::Xy3(code)) => match xy3::Command::from_code(code) {
                Ok(xy3::Command::BackRate(r)) => Some(r),
                _ => None,
            },
            _ => None,
        };
        let mut command_dropped = false;
        if let Some(c) = input.command {
            if self.carries(&c) {
                out.command = Some(c);
            } else {
                command_dropped = true;
            }
        }
        let mut laser_dropped = false;
        if let Some(l) = input.laser {
            if self.laser_forward && self.head.protocol == Protocol::Hans {
                out.laser = Some(l);
            } else {
                laser_dropped = true;
            }
        }
        Translated {
            frame: out,
            command_dropped,
            laser_dropped,
            back_rate,
        }
    }
}
