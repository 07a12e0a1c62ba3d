//! Conversions between XY2-100 frames / STATUS and the neutral model
//! ([`crate::model`]).

use super::frame::{Frame, Mode};
use super::status::{Health, StatusWord};
use crate::model::{Alarms, Command, HeadStatus, Position, PositionError};

/// What one decoded frame on an axis line contributes to a
/// [`ForwardFrame`](crate::model::ForwardFrame).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AxisItem {
    /// A position for the axis the frame arrived on.
    Position(Position),
    /// An enhanced command ([`Command::Xy2Enhanced`]).
    Command(Command),
}

/// The four alarms the status word has a bit for.
const WORD_ALARMS: Alarms =
    Alarms(Alarms::POWER.0 | Alarms::TEMPERATURE.0 | Alarms::POSITION_X.0 | Alarms::POSITION_Y.0);

impl Frame {
    /// The frame in neutral terms: positions keep their width (16 or 18 bits).
    /// Fails only for a hand-built [`Frame::Position18`] wider than 18 bits; decoded
    /// frames always convert.
    pub fn to_model(self) -> Result<AxisItem, PositionError> {
        Ok(match self {
            Frame::Position16(v) => AxisItem::Position(Position::from_raw(u32::from(v), 16)?),
            Frame::Position18(v) => AxisItem::Position(Position::from_raw(v, 18)?),
            Frame::Command { command, parameter } => {
                AxisItem::Command(Command::Xy2Enhanced { command, parameter })
            }
        })
    }

    /// The position frame for `position` at the link's width, resized with
    /// [`Position::to_raw`] (exact widening, rounded and saturated narrowing).
    pub fn from_position(position: Position, mode: Mode) -> Frame {
        match mode {
            // `to_raw(16)` is at most 0xFFFF, so the conversion never fails; the
            // saturating fallback keeps that true even if it ever changed.
            Mode::Standard16 => {
                Frame::Position16(u16::try_from(position.to_raw(16)).unwrap_or(u16::MAX))
            }
            Mode::Extended18 => Frame::Position18(position.to_raw(18)),
        }
    }

    /// The command frame for `command`, or `None` for a command XY2-100 cannot carry
    /// (an XY3-100 command: the bridge counts and drops it).
    pub fn from_command(command: Command) -> Option<Frame> {
        match command {
            Command::Xy2Enhanced { command, parameter } => {
                Some(Frame::Command { command, parameter })
            }
            Command::Xy3(_) => None,
        }
    }
}

impl StatusWord {
    /// The alarms the word reports: a cleared flag raises the matching alarm.
    pub const fn alarms(self) -> Alarms {
        let mut a = 0;
        if !self.power_ok {
            a |= Alarms::POWER.0;
        }
        if !self.temperature_ok {
            a |= Alarms::TEMPERATURE.0;
        }
        if !self.position_ack_x {
            a |= Alarms::POSITION_X.0;
        }
        if !self.position_ack_y {
            a |= Alarms::POSITION_Y.0;
        }
        Alarms(a)
    }

    /// The word that reports `alarms`. An alarm the word has no bit for (Z position,
    /// communication, laser, …) also clears `power_ok`: the word must never read "all
    /// OK" while the head is in alarm, and "supplies not OK" is the flag controllers
    /// treat as "head not ready".
    pub const fn from_alarms(alarms: Alarms) -> StatusWord {
        let other = alarms.0 & !WORD_ALARMS.0 != 0;
        StatusWord {
            power_ok: !alarms.contains(Alarms::POWER) && !other,
            temperature_ok: !alarms.contains(Alarms::TEMPERATURE),
            position_ack_x: !alarms.contains(Alarms::POSITION_X),
            position_ack_y: !alarms.contains(Alarms::POSITION_Y),
        }
    }
}

impl Health {
    /// The alarms a level reports. A bare fault says nothing about its cause, so it
    /// maps to [`Alarms::ELECTRICAL`], the model's flag for unspecified level faults.
    pub const fn alarms(self) -> Alarms {
        match self {
            Health::Ok => Alarms::NONE,
            Health::Fault => Alarms::ELECTRICAL,
        }
    }

    /// The level for a set of alarms: any alarm is a fault.
    pub const fn from_alarms(alarms: Alarms) -> Health {
        if alarms.any() {
            Health::Fault
        } else {
            Health::Ok
        }
    }

    /// The level for a head status: any alarm is a fault (warnings are not).
    pub const fn from_head_status(status: &HeadStatus) -> Health {
        Health::from_alarms(status.alarms)
    }
}

#[cfg(test)]
// Wire literals are grouped by field (header_data_parity), not in nibbles: that is
// what makes them checkable by eye against the frame layout.
#[allow(clippy::unusual_byte_groupings)]
mod tests {
    use super::*;
    use crate::xy2::{decode, encode, LinkConfig, Parity};
    use proptest::prelude::*;

    #[rustfmt::skip]
    const TO_MODEL: &[(Frame, u8, u32)] = &[
        // (frame, expected width, expected MSB-aligned value)
        (Frame::Position16(0x0000),   16, 0x0000_0000),
        (Frame::Position16(0x8000),   16, 0x8000_0000),
        (Frame::Position16(0xFFFF),   16, 0xFFFF_0000),
        (Frame::Position18(0x0_0000), 18, 0x0000_0000),
        (Frame::Position18(0x2_0000), 18, 0x8000_0000),
        (Frame::Position18(0x3_FFFF), 18, 0xFFFF_C000),
    ];

    #[test]
    fn positions_to_model() {
        for &(frame, bits, aligned) in TO_MODEL {
            let Ok(AxisItem::Position(p)) = frame.to_model() else {
                panic!("{frame:?} is not a position");
            };
            assert_eq!((p.bits(), p.aligned()), (bits, aligned), "{frame:?}");
        }
        assert_eq!(
            Frame::Position18(0x4_0000).to_model(),
            Err(PositionError::TooWide {
                value: 0x4_0000,
                bits: 18
            })
        );
    }

    #[test]
    fn commands_to_and_from_model() {
        let frame = Frame::Command {
            command: 0x05,
            parameter: 0x01,
        };
        let cmd = Command::Xy2Enhanced {
            command: 0x05,
            parameter: 0x01,
        };
        assert_eq!(frame.to_model(), Ok(AxisItem::Command(cmd)));
        assert_eq!(Frame::from_command(cmd), Some(frame));
        assert_eq!(Frame::from_command(Command::Xy3(0x1234)), None);
    }

    #[rustfmt::skip]
    const FROM_POSITION: &[(u32, u8, Mode, Frame)] = &[
        // (raw, width, link mode, expected frame)
        (0x8000,   16, Mode::Extended18, Frame::Position18(0x2_0000)), // widen exactly
        (0xFFFF,   16, Mode::Extended18, Frame::Position18(0x3_FFFC)),
        (0x2_0000, 18, Mode::Standard16, Frame::Position16(0x8000)),
        (0x3_FFFF, 18, Mode::Standard16, Frame::Position16(0xFFFF)),   // saturates
        (0x0_0002, 18, Mode::Standard16, Frame::Position16(0x0001)),   // half LSB rounds up
        (0x0_0001, 18, Mode::Standard16, Frame::Position16(0x0000)),
        (0xF_FFFF, 20, Mode::Extended18, Frame::Position18(0x3_FFFF)),
    ];

    #[test]
    fn positions_from_model() {
        for &(raw, bits, mode, want) in FROM_POSITION {
            let p = Position::from_raw(raw, bits).unwrap();
            assert_eq!(Frame::from_position(p, mode), want, "{raw:#x}/{bits}");
        }
    }

    #[rustfmt::skip]
    const WORD_ALARMS_TABLE: &[(u16, Alarms)] = &[
        (0xFDFD, Alarms::NONE),
        (0x7D7D, Alarms::POWER),
        (0xBDBD, Alarms::TEMPERATURE),
        (0xF5F5, Alarms::POSITION_X),
        (0xEDED, Alarms::POSITION_Y),
        (0x2525, WORD_ALARMS),
    ];

    #[test]
    fn status_word_alarms() {
        for &(word, alarms) in WORD_ALARMS_TABLE {
            let s = StatusWord::from_word(word).unwrap();
            assert_eq!(s.alarms(), alarms, "{word:#06x}");
            assert_eq!(StatusWord::from_alarms(alarms), s);
        }
        // Alarms without a bit of their own never read as "all OK".
        for other in [
            Alarms::POSITION_Z,
            Alarms::COMMUNICATION,
            Alarms::STATUS_LOST,
        ] {
            let s = StatusWord::from_alarms(other);
            assert_eq!(s.to_word(), 0x7D7D, "{other:?}");
            assert!(s.alarms().any());
        }
    }

    #[test]
    fn level_alarms() {
        assert_eq!(Health::Ok.alarms(), Alarms::NONE);
        assert_eq!(Health::Fault.alarms(), Alarms::ELECTRICAL);
        assert_eq!(Health::from_alarms(Alarms::NONE), Health::Ok);
        let mut status = HeadStatus::default();
        assert_eq!(Health::from_head_status(&status), Health::Ok);
        status.warnings = crate::model::Warnings::TEMPERATURE;
        assert_eq!(Health::from_head_status(&status), Health::Ok);
        status.alarms = Alarms::VENDOR;
        assert_eq!(Health::from_head_status(&status), Health::Fault);
    }

    proptest! {
        /// Any alarm set becomes a fault and the word reports at least one alarm
        /// whenever the set is non-empty; the word's own four alarms survive exactly.
        #[test]
        fn alarms_round_trip(bits in 0u32..(1 << 12)) {
            let alarms = Alarms(bits);
            let s = StatusWord::from_alarms(alarms);
            prop_assert_eq!(s.alarms().any(), alarms.any());
            prop_assert_eq!(s.alarms().0 & !Alarms::POWER.0, bits & WORD_ALARMS.0 & !Alarms::POWER.0);
            let other = bits & !WORD_ALARMS.0 != 0;
            prop_assert_eq!(!s.power_ok, alarms.contains(Alarms::POWER) || other);
            prop_assert_eq!(Health::from_alarms(alarms) == Health::Fault, alarms.any());
            prop_assert_eq!(Health::from_alarms(Health::Fault.alarms()), Health::Fault);
        }

        /// Position -> frame -> word -> frame -> position is exact at the link width.
        #[test]
        fn position_through_the_wire(v in 0u32..(1 << 18), ext: bool, parity in 0usize..3) {
            let (mode, bits) = if ext { (Mode::Extended18, 18) } else { (Mode::Standard16, 16) };
            let parity = [Parity::WholeFrame, Parity::DataOnly, Parity::Ignore][parity];
            let cfg = LinkConfig { mode, parity };
            let v = v >> (18 - bits);
            let p = Position::from_raw(v, bits).unwrap();
            let word = encode(Frame::from_position(p, mode), &cfg).unwrap();
            let back = decode(word, &cfg).unwrap().to_model();
            prop_assert_eq!(back, Ok(AxisItem::Position(p)));
        }
    }
}
