//! Property tests: round trips of every type, garbage never accepted twice differently.

use proptest::prelude::*;

use crate::model::{self, Position};
use crate::xy3::neutral::{command_frame, position_frame, to_neutral, Neutral};
use crate::xy3::*;

/// Any valid frame.
pub(super) fn frame() -> impl Strategy<Value = Frame> {
    prop_oneof![
        (0u32..1 << 20).prop_map(Frame::Position24),
        (0u32..1 << 26).prop_map(Frame::Position32),
        (0u32..1 << 20).prop_map(Frame::Command24),
        (0u32..1 << 20, 0u8..1 << 6).prop_map(|(code, unused)| Frame::Command32 { code, unused }),
    ]
}

fn size() -> impl Strategy<Value = FrameSize> {
    prop_oneof![Just(FrameSize::Bits24), Just(FrameSize::Bits32)]
}

fn typed_command() -> impl Strategy<Value = Command> {
    let flags = (0u8..=0x1F).prop_map(|b| AxisFlags::from_bits(b).unwrap());
    prop_oneof![
        flags.clone().prop_map(Command::AutocalibOn),
        flags.clone().prop_map(Command::AutocalibOff),
        flags.clone().prop_map(Command::CalibStart),
        flags.clone().prop_map(Command::RefStart),
        flags.clone().prop_map(Command::TempCompOn),
        flags.prop_map(Command::TempCompOff),
        proptest::sample::select(BackRate::ALL.to_vec()).prop_map(Command::BackRate),
    ]
}

proptest! {
    #[test]
    fn frame_round_trip(f in frame()) {
        let (word, size) = encode(&f).unwrap();
        prop_assert_eq!(size, f.size());
        prop_assert!(size.bits() == 32 || word >> size.bits() == 0);
        prop_assert_eq!(FrameSize::from_first_bit(word >> (size.bits() - 1) & 1 == 1), size);
        prop_assert_eq!(decode(word, size), Ok(f));
    }

    #[test]
    fn any_accepted_word_re_encodes_identically(word in any::<u32>(), size in size()) {
        if let Ok(f) = decode(word, size) {
            prop_assert_eq!(encode(&f), Ok((word, size)));
        }
    }

    #[test]
    fn every_code_round_trips(code in 0u32..1 << 20) {
        let cmd = Command::from_code(code).unwrap();
        prop_assert_eq!(cmd.code(), code);
    }

    #[test]
    fn typed_commands_round_trip(cmd in typed_command()) {
        prop_assert!(cmd.code() >> 20 == 0);
        prop_assert_eq!(Command::from_code(cmd.code()), Ok(cmd));
    }

    #[test]
    fn neutral_position_round_trip(v in any::<u32>(), size in size()) {
        let bits = size.position_bits();
        let v = v >> (32 - bits);
        let p = Position::from_raw(v, bits).unwrap();
        let f = position_frame(p, size);
        let (word, _) = encode(&f).unwrap();
        let back = to_neutral(&decode(word, size).unwrap());
        prop_assert_eq!(back, Ok(Neutral::Position(p)));
    }

    #[test]
    fn neutral_position_msb_aligned(v in 0u32..1 << 16) {
        let p = Position::from_raw(v, 16).unwrap();
        prop_assert_eq!(position_frame(p, FrameSize::Bits24), Frame::Position24(v << 4));
        prop_assert_eq!(position_frame(p, FrameSize::Bits32), Frame::Position32(v << 10));
    }

    #[test]
    fn neutral_command_round_trip(code in 0u32..1 << 20, size in size()) {
        let c = model::Command::Xy3(code);
        let f = command_frame(&c, size).unwrap();
        let (word, s) = encode(&f).unwrap();
        prop_assert_eq!(s, size);
        prop_assert_eq!(to_neutral(&decode(word, size).unwrap()), Ok(Neutral::Command(c)));
    }
}
