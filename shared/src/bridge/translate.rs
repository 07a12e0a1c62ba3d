//! Forward translation: a controller's [`ForwardFrame`] into the head's, at the
//! head's widths, through the axis map, with commands and laser control kept only
//! where the head protocol carries them.

use super::config::{AxisMap, Config, HeadSide, Protocol, ZConfig, ZSource};
use crate::model::{Axis, Command, ForwardFrame, Position};
use crate::xy2::Mode;
use crate::xy3::{self, BackRate};

/// How one head axis is produced: from which input axis, at which width, inverted
/// and shifted how. Resolved once from the configuration so the per-frame path does
/// not re-derive widths and swaps.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct AxisRoute {
    source: Axis,
    bits: u8,
    invert: bool,
    offset: i32,
}

impl AxisRoute {
    fn apply(&self, input: &ForwardFrame) -> Option<Position> {
        input
            .axis(self.source)
            .map(|p| map_position(p, self.bits, self.invert, self.offset))
    }
}

/// The translation policy, fixed at construction.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Translator {
    head: HeadSide,
    x: AxisRoute,
    y: AxisRoute,
    /// Z from the input (`ZSource::Input`).
    z: Option<AxisRoute>,
    /// Z when not from the input: the fixed position or none.
    z_other: Option<Position>,
    /// Widths of U and W; `None` unless the head is XY3-100 (only it has them).
    uw_bits: Option<(u8, u8)>,
    laser_forward: bool,
}

/// What one translation did not carry.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct Translated {
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
    let raw = p.to_raw(bits);
    // `raw` is within the field, so saturating at 0 and at the field's top is the
    // clamp (in 32-bit arithmetic: a 32-bit field's top is `u32::MAX`).
    let raw = if offset >= 0 {
        let max = u32::MAX >> (32 - u32::from(p.bits()));
        raw.saturating_add(offset.unsigned_abs()).min(max)
    } else {
        raw.saturating_sub(offset.unsigned_abs())
    };
    Position::from_raw(raw, bits).unwrap_or(p)
}

/// A 20-bit configuration position at the head's width for `axis`.
pub(crate) fn config_position(head: &HeadSide, axis: Axis, raw20: u32) -> Option<Position> {
    Position::from_raw(raw20, 20)
        .ok()
        .map(|p| p.resized(head.width(axis)))
}

impl Translator {
    pub fn new(c: &Config) -> Self {
        let a: &AxisMap = &c.axes;
        let head = c.head;
        let (src_x, src_y) = if a.swap_xy {
            (Axis::Y, Axis::X)
        } else {
            (Axis::X, Axis::Y)
        };
        let route = |source, target, invert, offset| AxisRoute {
            source,
            bits: head.width(target),
            invert,
            offset,
        };
        let z: &ZConfig = &c.z;
        Translator {
            head,
            x: route(src_x, Axis::X, a.invert_x, a.offset_x),
            y: route(src_y, Axis::Y, a.invert_y, a.offset_y),
            z: (z.source == ZSource::Input)
                .then(|| route(Axis::Z, Axis::Z, a.invert_z, a.offset_z)),
            z_other: match z.source {
                ZSource::Fixed => config_position(&head, Axis::Z, z.fixed),
                ZSource::Input | ZSource::None => None,
            },
            uw_bits: (head.protocol == Protocol::Xy3)
                .then(|| (head.width(Axis::U), head.width(Axis::W))),
            laser_forward: c.laser.forward && head.protocol == Protocol::Hans,
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

    /// Translates `input` into `out`, which must be empty (`ForwardFrame::default()`):
    /// written in place because the caller keeps the result in its own slot.
    pub fn translate(&self, input: &ForwardFrame, out: &mut ForwardFrame) -> Translated {
        let [x, y, z, u, w] = &mut out.axes;
        *x = self.x.apply(input);
        *y = self.y.apply(input);
        *z = match &self.z {
            Some(route) => route.apply(input),
            None => self.z_other,
        };
        if let Some((u_bits, w_bits)) = self.uw_bits {
            // Only XY3-100 has U and W; they pass resized, without mapping.
            *u = input.axis(Axis::U).map(|p| p.resized(u_bits));
            *w = input.axis(Axis::W).map(|p| p.resized(w_bits));
        }
        let mut t = Translated {
            command_dropped: false,
            laser_dropped: false,
            back_rate: None,
        };
        if let Some(c) = input.command {
            if let Command::Xy3(code) = c {
                if let Ok(xy3::Command::BackRate(r)) = xy3::Command::from_code(code) {
                    t.back_rate = Some(r);
                }
            }
            if self.carries(&c) {
                out.command = Some(c);
            } else {
                t.command_dropped = true;
            }
        }
        if let Some(l) = input.laser {
            if self.laser_forward {
                out.laser = Some(l);
            } else {
                t.laser_dropped = true;
            }
        }
        t
    }
}
