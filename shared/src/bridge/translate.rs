//! Forward translation: a controller's [`ForwardFrame`] into the head's, at the
//! head's widths, through the axis map, with commands and laser control kept only
//! where the head protocol carries them.

use super::config::{AxisMap, Config, HeadSide, Protocol, ZConfig, ZSource};
use crate::model::{Axis, Command, ForwardFrame, Position};
use crate::xy2::Mode;
use crate::xy3::{self, BackRate};

/// How one head axis is produced: from which input axis, at which width, inverted
/// and shifted how. Resolved once from the configuration so the per-frame path does
/// not re-derive widths and swaps, and works on the MSB-aligned value directly:
/// rounding, inversion and offset are then a few word operations (the result equals
/// [`map_position`], which the tests check).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct AxisRoute {
    source: Axis,
    /// Position 0 at the head width: the width of every result.
    zero: Position,
    /// The field's bits in the aligned value (the width from the top).
    mask: u32,
    /// Half an LSB of the field (0 for a 32-bit field: nothing to round).
    half: u32,
    /// XORed into the aligned value: `mask` to invert, 0 not to.
    flip: u32,
    /// `|offset|` LSBs aligned, saturated at the field (an offset as large as the
    /// field takes any position to the end).
    step: u32,
    /// The offset is negative.
    down: bool,
}

impl AxisRoute {
    fn new(source: Axis, bits: u8, invert: bool, offset: i32) -> AxisRoute {
        let bits = bits.clamp(1, 32);
        let shift = 32 - u32::from(bits);
        let mask = u32::MAX << shift;
        let step = u64::from(offset.unsigned_abs()) << shift;
        AxisRoute {
            source,
            zero: Position::from_raw(0, bits).unwrap_or(Position::CENTRE),
            mask,
            half: (1u32 << shift) >> 1,
            flip: if invert { mask } else { 0 },
            step: u32::try_from(step).unwrap_or(u32::MAX) & mask,
            down: offset < 0,
        }
    }

    fn apply(&self, input: &ForwardFrame) -> Option<Position> {
        input.axis(self.source).map(|p| self.map(p))
    }

    /// `p` resized, inverted and shifted as configured.
    #[inline(always)]
    fn map(&self, p: Position) -> Position {
        // Round to the field, saturating at full scale (as `Position::resized`): in
        // the field's top step the sum stays in it or saturates, and the mask gives
        // the top step either way; below it the sum cannot wrap.
        let a = p.aligned().saturating_add(self.half) & self.mask;
        let a = a ^ self.flip;
        // The offset saturates at both ends of the field instead of wrapping.
        let a = if self.down {
            a.saturating_sub(self.step)
        } else {
            a.saturating_add(self.step) & self.mask
        };
        // Every step kept the bits below the field zero.
        self.zero.with_aligned(a)
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
/// an offset must never wrap a position to the other end of the field. (The
/// translator's own per-axis form of this, kept for the tests' arithmetic model.)
#[cfg(test)]
pub(super) fn map_position(p: Position, bits: u8, invert: bool, offset: i32) -> Position {
    AxisRoute::new(Axis::X, bits, invert, offset).map(p)
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
        let route = |source, target, invert, offset| {
            AxisRoute::new(source, head.width(target), invert, offset)
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

    /// Whether [`Translator::translate`] gives `input`'s own command and its own
    /// laser control to the output (replacing any already there).
    pub fn carries_own(&self, input: &ForwardFrame) -> (bool, bool) {
        (
            input.command.is_some_and(|c| self.carries(&c)),
            input.laser.is_some() && self.laser_forward,
        )
    }

    /// Translates `input` into `out`, whose axes must be empty: written in place
    /// because the caller keeps the result in its own slot. A command or laser
    /// control already in `out` stays unless `input` brings its own that the head
    /// takes ([`Translator::carries_own`]).
    /// Inlined into the engine's frame path (its one caller per timing mode).
    #[inline(always)]
    pub fn translate(&self, input: &ForwardFrame, out: &mut ForwardFrame) -> Translated {
        let [x, y, z, u, w] = &mut out.axes;
        *x = self.x.apply(input);
        *y = self.y.apply(input);
        *z = match &self.z {
            Some(route) => route.apply(input),
            None => self.z_other,
        };
        if let Some((u_bits, w_bits)) = self.uw_bits {
            // Only XY3-100 has U and W; they pass resized, without mapping. `out`'s
            // axes are empty: an axis the input lacks is already `None`.
            if let Some(p) = input.axis(Axis::U) {
                *u = Some(p.resized(u_bits));
            }
            if let Some(p) = input.axis(Axis::W) {
                *w = Some(p.resized(w_bits));
            }
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
