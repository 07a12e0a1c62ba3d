//! Neutral-model mapping tests.

use super::ext::{DeviceExt, LaserAlarms, ZAlarms};
use super::frame::Frame;
use super::neutral::{status_frame, StatusReceiver};
use super::status::{GalvoAlarms, GalvoStatus};
use super::tests_ext::galvo_status;
use crate::model::{Alarms, Axis, ForwardFrame, HeadStatus, LaserControl, Position, Warnings};
use proptest::prelude::*;

fn pos(v: u32, bits: u8) -> Option<Position> {
    Some(Position::from_raw(v, bits).unwrap())
}

fn frame(d1: u32, d2: u32, d3: u32) -> Frame {
    Frame::new(d1, d2, d3).unwrap()
}

/// (frame words, (X, Y) raw 20-bit, Z raw 16-bit, laser).
type ForwardRow = (
    (u32, u32, u32),
    (u32, u32),
    Option<u32>,
    Option<LaserControl>,
);

#[rustfmt::skip]
const FORWARD: &[ForwardRow] = &[
    // (frame words, (X, Y) raw 20-bit, Z raw 16-bit, laser)
    ((0x0_0000, 0x0_0000, 0x0_0000), (0x0_0000, 0x0_0000), Some(0x0000), None),
    ((0x8_0000, 0x8_0000, 0x8_0000), (0x8_0000, 0x8_0000), Some(0x8000), None),
    ((0xF_FFFF, 0xF_FFFF, 0xF_FFF0), (0xF_FFFF, 0xF_FFFF), Some(0xFFFF), None),
    ((0x1_2345, 0xA_BCDE, 0x0_0324), (0x1_2345, 0xA_BCDE), None, Some(LaserControl::QPeriod(0x32))),
    ((0x0_0001, 0xF_FFFE, 0xA_BCDA), (0x0_0001, 0xF_FFFE), None,
     Some(LaserControl::Other { code: 10, data: 0xABCD })),
];

#[test]
fn forward_table() {
    for &((d1, d2, d3), (x, y), z, laser) in FORWARD {
        let f = frame(d1, d2, d3);
        let n = f.to_forward();
        assert_eq!(n.axis(Axis::X), pos(x, 20));
        assert_eq!(n.axis(Axis::Y), pos(y, 20));
        assert_eq!(n.axis(Axis::Z), z.and_then(|z| pos(z, 16)));
        assert_eq!(n.laser, laser);
        assert_eq!(n.command, None);
        assert_eq!(Frame::from_forward(&n, &Frame::CENTRE), Ok(f));
    }
}

#[test]
fn from_forward_resizes_and_holds() {
    let hold = frame(0x1_1111, 0x2_2222, 0x3_3330);
    // 16-bit XY2 positions widen exactly to 20 bits; a 20-bit Z narrows with rounding.
    let mut n = ForwardFrame::default();
    n.axes[0] = pos(0xFFFF, 16);
    n.axes[1] = pos(0x8000, 16);
    n.axes[2] = pos(0x0_0008, 20);
    assert_eq!(
        Frame::from_forward(&n, &hold),
        Ok(frame(0xF_FFF0, 0x8_0000, 0x0_0010))
    );
    // Laser control takes DATA3 even when Z is present.
    n.laser = Some(LaserControl::StandbyPower(0x1234));
    assert_eq!(
        Frame::from_forward(&n, &hold),
        Ok(frame(0xF_FFF0, 0x8_0000, 0x1_2349))
    );
    // Missing axes and DATA3 come from `hold`.
    let empty = ForwardFrame::default();
    assert_eq!(Frame::from_forward(&empty, &hold), Ok(hold));
    let mut only_y = ForwardFrame::default();
    only_y.axes[1] = pos(0, 20);
    assert_eq!(
        Frame::from_forward(&only_y, &hold),
        Ok(frame(0x1_1111, 0, 0x3_3330))
    );
    // An unencodable laser value is an error, not a wrong frame.
    let bad = ForwardFrame {
        laser: Some(LaserControl::Other { code: 16, data: 0 }),
        ..ForwardFrame::default()
    };
    assert!(Frame::from_forward(&bad, &hold).is_err());
}

#[test]
fn status_frames_apply_to_head_status() {
    let mut rx = StatusReceiver::new();
    let mut st = HeadStatus {
        alarms: Alarms::STATUS_LOST, // not HANS-100's to change
        ..HeadStatus::default()
    };
    // Code 64 (X 0x1234, Y 0xABCD) + DATA3 code 14 (Z 0x8000).
    rx.apply(&frame(0x1_2344, 0xA_BCD0, 0x8_000E), &mut st);
    assert_eq!(
        st.actual,
        [pos(0x1234, 16), pos(0xABCD, 16), pos(0x8000, 16)]
    );
    assert_eq!(st.alarms, Alarms::STATUS_LOST);
    // Code 65: X velocity 0x123, Y 0xABC, DATA1 flags 0111 (over-temperature),
    // DATA2 flags 1011 (unfiltered low speed); DATA3 code 15, Z velocity 0x456,
    // flags 1011 (Z following error).
    rx.apply(&frame(0x1_2374, 0xA_BCB1, 0x4_56BF), &mut st);
    assert_eq!(st.velocity, [Some(0x123), Some(0xABC), Some(0x456)]);
    assert_eq!(
        st.alarms,
        Alarms::STATUS_LOST
            .union(Alarms::TEMPERATURE)
            .union(Alarms::POSITION_Z)
    );
    assert_eq!(st.warnings, Warnings::LOW_SPEED);
    // Galvo all normal; Z reports following error and over-temperature (flags 0011,
    // data 0x0003): over-temperature is now only on Z, and the union keeps
    // TEMPERATURE raised by the Z report.
    rx.apply(&frame(0x0_00F4, 0x0_00F1, 0x0_003F), &mut st);
    assert_eq!(
        st.alarms,
        Alarms::STATUS_LOST
            .union(Alarms::TEMPERATURE)
            .union(Alarms::POSITION_Z)
    );
    assert_eq!(st.warnings, Warnings::NONE);
    // Laser code 10: power alarm + temperature warning + emission; galvo part raw.
    rx.apply(&frame(0, 0, 0x8_005A), &mut st);
    assert_eq!(st.laser_state, Some(0x8005));
    assert!(st.alarms.contains(Alarms::LASER));
    assert_eq!(
        st.warnings,
        Warnings(Warnings::LASER_TEMPERATURE.0 | Warnings::LASER_EMISSION.0)
    );
    // Galvo code 65 with following error + power + communication; Z back to normal;
    // laser only emitting.
    // DATA1 flags 1010, DATA2 flags 1110 (reserved 1), Z flags 1111.
    rx.apply(&frame(0x0_00A4, 0x0_00E1, 0x0_00FF), &mut st);
    rx.apply(&frame(0, 0, 0x8_000A), &mut st);
    assert_eq!(
        st.alarms,
        Alarms::STATUS_LOST
            .union(Alarms::POSITION_X)
            .union(Alarms::POSITION_Y)
            .union(Alarms::POWER)
            .union(Alarms::COMMUNICATION)
    );
    assert_eq!(st.warnings, Warnings::LASER_EMISSION);
    // Remote inputs (2) and pulse-width mode (7).
    rx.apply(&frame(0, 0, 0xB_EEF2), &mut st);
    rx.apply(&frame(0, 0, 0x0_0037), &mut st);
    assert_eq!(
        (st.remote_inputs, st.pulse_width_mode),
        (Some(0xBEEF), Some(3))
    );
    // A word that is not 20 bits cannot come from a Frame; bad words via the parts:
    assert!(GalvoStatus::from_words(0x10_0000, 0).is_err());
}

#[test]
fn bridge_alarms_reach_a_hans_controller() {
    let mut st = HeadStatus {
        alarms: Alarms::MECHANICAL.union(Alarms::INPUT_LOST),
        ..HeadStatus::default()
    };
    st.actual[2] = pos(0, 16);
    let GalvoStatus::Velocity { alarms, .. } = GalvoStatus::velocity_from(&st) else {
        panic!("code 65 expected");
    };
    assert!(alarms.power && alarms.communication && !alarms.over_temperature);
    let z = DeviceExt::all_from(&st);
    assert_eq!(
        z.as_slice(),
        &[
            DeviceExt::ZActual(0),
            DeviceExt::ZVelocity {
                velocity: 0,
                alarms: ZAlarms {
                    over_temperature: false,
                    following_error: false,
                    communication: true,
                    power: true
                },
            }
        ]
    );
    // A LASER alarm without a laser word is sent as the D3 system alarm.
    let l = HeadStatus {
        alarms: Alarms::LASER,
        ..HeadStatus::default()
    };
    assert_eq!(
        DeviceExt::all_from(&l).as_slice(),
        &[DeviceExt::LaserAlarms(LaserAlarms(LaserAlarms::SYSTEM))]
    );
    assert!(DeviceExt::all_from(&HeadStatus::default()).is_empty());
    assert_eq!(GalvoStatus::position_from(&HeadStatus::default()), None);
}

fn head_status() -> impl Strategy<Value = HeadStatus> {
    (
        any::<[u16; 3]>(),
        [0u16..0x1000, 0u16..0x1000, 0u16..0x1000],
        any::<u16>(),
        any::<(u16, u16)>(),
        any::<[bool; 10]>(),
    )
        .prop_map(|(actual, velocity, laser, (inputs, pwm), b)| {
            let mut st = HeadStatus::default();
            for i in 0..3 {
                st.actual[i] = pos(u32::from(actual[i]), 16);
                st.velocity[i] = Some(velocity[i]);
            }
            st.laser_state = Some(laser);
            st.remote_inputs = Some(inputs);
            st.pulse_width_mode = Some(pwm);
            let flags = [
                Alarms::POWER,
                Alarms::TEMPERATURE,
                Alarms::POSITION_X.union(Alarms::POSITION_Y),
                Alarms::POSITION_Z,
                Alarms::COMMUNICATION,
            ];
            for (flag, &on) in flags.iter().zip(&b[..5]) {
                st.alarms.set(*flag, on);
            }
            st.alarms.set(Alarms::LASER, LaserAlarms(laser).any_alarm());
            st.warnings.set(Warnings::TEMPERATURE, b[5]);
            st.warnings.set(Warnings::LOW_SPEED_FILTERED, b[6]);
            st.warnings.set(Warnings::LOW_SPEED, b[7]);
            let l = LaserAlarms(laser);
            st.warnings.set(
                Warnings::LASER_TEMPERATURE,
                l.contains(LaserAlarms::TEMPERATURE_WARNING),
            );
            st.warnings
                .set(Warnings::LASER_EMISSION, l.contains(LaserAlarms::EMISSION));
            st
        })
}

proptest! {
    #[test]
    fn forward_frame_round_trip(d1 in 0u32..=0xF_FFFF, d2 in 0u32..=0xF_FFFF, d3 in 0u32..=0xF_FFFF) {
        let f = frame(d1, d2, d3);
        let n = f.to_forward();
        prop_assert_eq!(Frame::from_forward(&n, &frame(d2, d3, d1)), Ok(f));
        prop_assert_eq!(Frame::from_forward(&n, &frame(d1, d2, d3)).unwrap().to_forward(), n);
    }

    /// Every HeadStatus HANS-100 can represent survives building all status frames
    /// (alternated as a bridge would) and receiving them in any order.
    #[test]
    fn head_status_round_trip(st in head_status(), rotate in 0usize..5) {
        let mut parts = DeviceExt::all_from(&st);
        prop_assert_eq!(parts.len(), 5);
        parts.rotate_left(rotate);
        let galvo = [GalvoStatus::position_from(&st).unwrap(), GalvoStatus::velocity_from(&st)];
        let mut rx = StatusReceiver::new();
        let mut got = HeadStatus::default();
        for (i, d) in parts.iter().enumerate() {
            let f = status_frame(&galvo[i % 2], d).unwrap();
            rx.apply(&f, &mut got);
        }
        prop_assert_eq!(got, st);
    }

    #[test]
    fn status_frame_parts_round_trip(g in galvo_status(), w3 in 0u32..=0xF_FFFF) {
        let d = DeviceExt::from_data3(w3).unwrap();
        let f = status_frame(&g, &d).unwrap();
        prop_assert_eq!(GalvoStatus::from_words(f.data1(), f.data2()), Ok(g));
        prop_assert_eq!(f.data3(), w3);
    }

    #[test]
    fn galvo_alarm_flags_map_one_to_one(b in any::<[bool; 8]>()) {
        let alarms = GalvoAlarms {
            over_temperature: b[0], following_error: b[1], low_speed_filtered: b[2], power: b[3],
            temperature_warning: b[4], low_speed: b[5], reserved_level: true, communication: b[6],
        };
        let mut rx = StatusReceiver::new();
        let mut st = HeadStatus::default();
        rx.apply_galvo(&GalvoStatus::Velocity { x: 0, y: 0, alarms }, &mut st);
        prop_assert_eq!(st.alarms.contains(Alarms::TEMPERATURE), b[0]);
        prop_assert_eq!(st.alarms.contains(Alarms::POSITION_X.union(Alarms::POSITION_Y)), b[1]);
        prop_assert_eq!(st.warnings.contains(Warnings::LOW_SPEED_FILTERED), b[2]);
        prop_assert_eq!(st.alarms.contains(Alarms::POWER), b[3]);
        prop_assert_eq!(st.warnings.contains(Warnings::TEMPERATURE), b[4]);
        prop_assert_eq!(st.warnings.contains(Warnings::LOW_SPEED), b[5]);
        prop_assert_eq!(st.alarms.contains(Alarms::COMMUNICATION), b[6]);
        prop_assert_eq!(GalvoStatus::velocity_from(&st), GalvoStatus::Velocity { x: 0, y: 0, alarms });
    }
}
