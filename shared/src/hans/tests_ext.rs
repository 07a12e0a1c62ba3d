//! Extension-code tests. Expected words are worked out by hand: DATA3 = data << 4 |
//! code; DATA1 = data_high << 4 | code >> 4, DATA2 = data_low << 4 | code & 0xF.

use super::ext::{ControllerExt, DeviceExt, ExtError, LaserAlarms, ZAlarms};
use super::status::{GalvoAlarms, GalvoStatus};
use crate::model::LaserControl;
use proptest::prelude::*;

use ControllerExt::{Laser, Z};
use LaserControl::*;

const fn power(power: u8, mo: bool, pa: bool, red_pointer: bool, reserved: u8) -> ControllerExt {
    Laser(Power {
        power,
        mo,
        pa,
        red_pointer,
        reserved,
    })
}

#[rustfmt::skip]
const FORWARD: &[(ControllerExt, u32)] = &[
    (Z(0x0000), 0x0_0000),
    (Z(0x8000), 0x8_0000),
    (Z(0xFFFF), 0xF_FFF0),
    (Laser(RemoteOutputs(0x0000)), 0x0_0001),
    (Laser(RemoteOutputs(0x8001)), 0x8_0011),
    (Laser(RemoteOutputs(0xFFFF)), 0xF_FFF1),
    // D7..D0 power, D8 MO, D9 PA, D10 red pointer, D15..D11 reserved.
    (power(0x00, false, false, false, 0x00), 0x0_0003),
    (power(0x80, true, false, false, 0x00),  0x0_1803), // data 0x0180
    (power(0x12, false, true, true, 0x01),   0x0_E123), // data 0x0800|0x0400|0x0200|0x12
    (power(0xFF, true, true, true, 0x1F),    0xF_FFF3),
    (Laser(QPeriod(0x0000)), 0x0_0004),
    (Laser(QPeriod(0x0032)), 0x0_0324), // 50 counts = 1 us
    (Laser(QPeriod(0xFFFF)), 0xF_FFF4),
    (Laser(StandbyFrequency(0x0000)), 0x0_0005),
    (Laser(StandbyFrequency(0x1234)), 0x1_2345),
    (Laser(StandbyFrequency(0xFFFF)), 0xF_FFF5),
    (Laser(PulseWidthMode(0x0000)), 0x0_0006),
    (Laser(PulseWidthMode(0x8000)), 0x8_0006),
    (Laser(PulseWidthMode(0xFFFF)), 0xF_FFF6),
    (Laser(StandbyPower(0x0000)), 0x0_0009),
    (Laser(StandbyPower(0x8000)), 0x8_0009),
    (Laser(StandbyPower(0xFFFF)), 0xF_FFF9),
    (Laser(Other { code: 2, data: 0x0000 }),  0x0_0002),
    (Laser(Other { code: 7, data: 0x8000 }),  0x8_0007),
    (Laser(Other { code: 8, data: 0x0001 }),  0x0_0018),
    (Laser(Other { code: 10, data: 0xABCD }), 0xA_BCDA),
    (Laser(Other { code: 15, data: 0xFFFF }), 0xF_FFFF),
];

const fn z15(
    velocity: u16,
    over_temperature: bool,
    following_error: bool,
    communication: bool,
    power: bool,
) -> DeviceExt {
    DeviceExt::ZVelocity {
        velocity,
        alarms: ZAlarms {
            over_temperature,
            following_error,
            communication,
            power,
        },
    }
}

#[rustfmt::skip]
const DEVICE: &[(DeviceExt, u32)] = &[
    (DeviceExt::RemoteInputs(0x0000), 0x0_0002),
    (DeviceExt::RemoteInputs(0x8000), 0x8_0002),
    (DeviceExt::RemoteInputs(0xFFFF), 0xF_FFF2),
    (DeviceExt::PulseWidthMode(0x0000), 0x0_0007),
    (DeviceExt::PulseWidthMode(0x8000), 0x8_0007),
    (DeviceExt::PulseWidthMode(0xFFFF), 0xF_FFF7),
    (DeviceExt::LaserAlarms(LaserAlarms(0x0000)), 0x0_000A),
    (DeviceExt::LaserAlarms(LaserAlarms(0x8001)), 0x8_001A), // emission + power alarm
    (DeviceExt::LaserAlarms(LaserAlarms(0x0204)), 0x0_204A), // communication + temp warning
    (DeviceExt::LaserAlarms(LaserAlarms(0xFFFF)), 0xF_FFFA),
    (DeviceExt::ZActual(0x0000), 0x0_000E),
    (DeviceExt::ZActual(0x8000), 0x8_000E),
    (DeviceExt::ZActual(0xFFFF), 0xF_FFFE),
    // DATA3[19:8] velocity, [7] over-temp, [6] following, [5] comm, [4] power; 0 = alarm.
    (z15(0x000, false, false, false, false), 0x0_00FF), // all normal: 1111
    (z15(0x800, true, true, true, true),     0x8_000F), // all alarms: 0000
    (z15(0xFFF, true, false, false, false),  0xF_FF7F), // 0111
    (z15(0x123, false, false, false, true),  0x1_23EF), // 1110
    (DeviceExt::Raw { code: 0, data: 0x0000 }, 0x0_0000),
    (DeviceExt::Raw { code: 1, data: 0xFFFF }, 0xF_FFF1),
    (DeviceExt::Raw { code: 3, data: 0x8000 }, 0x8_0003),
    (DeviceExt::Raw { code: 9, data: 0x1234 }, 0x1_2349),
];

const NORMAL: GalvoAlarms = GalvoAlarms {
    over_temperature: false,
    following_error: false,
    low_speed_filtered: false,
    power: false,
    temperature_warning: false,
    low_speed: false,
    reserved_level: true,
    communication: false,
};
const ALL_ACTIVE: GalvoAlarms = GalvoAlarms {
    over_temperature: true,
    following_error: true,
    low_speed_filtered: true,
    power: true,
    temperature_warning: true,
    low_speed: true,
    reserved_level: false,
    communication: true,
};
const HOT_AND_SLOW: GalvoAlarms = GalvoAlarms {
    over_temperature: true,
    low_speed: true,
    ..NORMAL
};

#[rustfmt::skip]
const GALVO: &[(GalvoStatus, (u32, u32))] = &[
    // Code 64 = 0x40: DATA1 nibble 4, DATA2 nibble 0.
    (GalvoStatus::Position { x: 0x0000, y: 0x0000 }, (0x0_0004, 0x0_0000)),
    (GalvoStatus::Position { x: 0x8000, y: 0x8000 }, (0x8_0004, 0x8_0000)),
    (GalvoStatus::Position { x: 0x1234, y: 0xABCD }, (0x1_2344, 0xA_BCD0)),
    (GalvoStatus::Position { x: 0xFFFF, y: 0xFFFF }, (0xF_FFF4, 0xF_FFF0)),
    // Code 65 = 0x41: DATA1 nibble 4, DATA2 nibble 1; flag nibbles 0 = active.
    (GalvoStatus::Velocity { x: 0x000, y: 0x000, alarms: NORMAL },       (0x0_00F4, 0x0_00F1)),
    (GalvoStatus::Velocity { x: 0x800, y: 0x800, alarms: ALL_ACTIVE },   (0x8_0004, 0x8_0001)),
    (GalvoStatus::Velocity { x: 0x123, y: 0xABC, alarms: HOT_AND_SLOW }, (0x1_2374, 0xA_BCB1)),
    (GalvoStatus::Velocity { x: 0xFFF, y: 0xFFF, alarms: NORMAL },       (0xF_FFF4, 0xF_FFF1)),
    (GalvoStatus::Raw { code: 0x00, data: 0x0000_0000 }, (0x0_0000, 0x0_0000)),
    (GalvoStatus::Raw { code: 0x42, data: 0x1234_5678 }, (0x1_2344, 0x5_6782)),
    (GalvoStatus::Raw { code: 0xFF, data: 0xFFFF_FFFF }, (0xF_FFFF, 0xF_FFFF)),
];

#[test]
fn forward_table() {
    for &(ext, word) in FORWARD {
        assert_eq!(ext.to_data3(), Ok(word), "{ext:?}");
        // `Other` with a code that has a typed meaning would decode typed; the table
        // only uses undefined codes, so every row decodes back to itself.
        assert_eq!(ControllerExt::from_data3(word), Ok(ext), "{word:#x}");
    }
}

#[test]
fn device_table() {
    for &(ext, word) in DEVICE {
        assert_eq!(ext.to_data3(), Ok(word), "{ext:?}");
        // `Raw` rows only use codes without a typed meaning.
        assert_eq!(DeviceExt::from_data3(word), Ok(ext), "{word:#x}");
    }
}

#[test]
fn galvo_table() {
    for &(st, words) in GALVO {
        assert_eq!(st.to_words(), Ok(words), "{st:?}");
        assert_eq!(GalvoStatus::from_words(words.0, words.1), Ok(st));
    }
}

#[test]
fn laser_alarm_bits() {
    let a = LaserAlarms(0x8004);
    assert!(a.contains(LaserAlarms::EMISSION | LaserAlarms::TEMPERATURE_WARNING));
    assert!(!a.any_alarm(), "D2 and D15 are not alarms");
    for bit in (0..15).filter(|&b| b != 2) {
        assert!(LaserAlarms(1 << bit).any_alarm(), "D{bit}");
    }
    assert_eq!(LaserAlarms::SECOND_AMPLIFIER, 1 << 8);
    assert_eq!(LaserAlarms::COMMUNICATION, 1 << 9);
}

#[test]
fn bad_input() {
    assert_eq!(
        ControllerExt::from_data3(0x10_0000),
        Err(ExtError::WordTooWide(0x10_0000))
    );
    assert_eq!(
        DeviceExt::from_data3(u32::MAX),
        Err(ExtError::WordTooWide(u32::MAX))
    );
    assert_eq!(
        GalvoStatus::from_words(0, 0x10_0000),
        Err(ExtError::WordTooWide(0x10_0000))
    );
    assert_eq!(
        Laser(Other { code: 16, data: 0 }).to_data3(),
        Err(ExtError::CodeTooWide(16))
    );
    assert_eq!(
        DeviceExt::Raw {
            code: 0xFF,
            data: 0
        }
        .to_data3(),
        Err(ExtError::CodeTooWide(0xFF))
    );
    assert_eq!(
        power(0, false, false, false, 0x20).to_data3(),
        Err(ExtError::ReservedTooWide(0x20))
    );
    assert_eq!(
        z15(0x1000, false, false, false, false).to_data3(),
        Err(ExtError::VelocityTooWide(0x1000))
    );
    assert_eq!(
        GalvoStatus::Velocity {
            x: 0,
            y: 0x1000,
            alarms: NORMAL
        }
        .to_words(),
        Err(ExtError::VelocityTooWide(0x1000))
    );
}

fn laser_control() -> impl Strategy<Value = LaserControl> {
    prop_oneof![
        any::<u16>().prop_map(RemoteOutputs),
        (
            any::<u8>(),
            any::<bool>(),
            any::<bool>(),
            any::<bool>(),
            0u8..32
        )
            .prop_map(|(power, mo, pa, red_pointer, reserved)| Power {
                power,
                mo,
                pa,
                red_pointer,
                reserved
            }),
        any::<u16>().prop_map(QPeriod),
        any::<u16>().prop_map(StandbyFrequency),
        any::<u16>().prop_map(PulseWidthMode),
        any::<u16>().prop_map(StandbyPower),
        (
            prop::sample::select(vec![2u8, 7, 8, 10, 11, 12, 13, 14, 15]),
            any::<u16>()
        )
            .prop_map(|(code, data)| Other { code, data }),
    ]
}

fn z_alarms() -> impl Strategy<Value = ZAlarms> {
    any::<[bool; 4]>().prop_map(
        |[over_temperature, following_error, communication, power]| ZAlarms {
            over_temperature,
            following_error,
            communication,
            power,
        },
    )
}

fn device_ext() -> impl Strategy<Value = DeviceExt> {
    prop_oneof![
        any::<u16>().prop_map(DeviceExt::RemoteInputs),
        any::<u16>().prop_map(DeviceExt::PulseWidthMode),
        any::<u16>().prop_map(|d| DeviceExt::LaserAlarms(LaserAlarms(d))),
        any::<u16>().prop_map(DeviceExt::ZActual),
        (0u16..0x1000, z_alarms())
            .prop_map(|(velocity, alarms)| DeviceExt::ZVelocity { velocity, alarms }),
        (
            prop::sample::select(vec![0u8, 1, 3, 4, 5, 6, 8, 9, 11, 12, 13]),
            any::<u16>()
        )
            .prop_map(|(code, data)| DeviceExt::Raw { code, data }),
    ]
}

pub(super) fn galvo_status() -> impl Strategy<Value = GalvoStatus> {
    prop_oneof![
        (any::<u16>(), any::<u16>()).prop_map(|(x, y)| GalvoStatus::Position { x, y }),
        (0u16..0x1000, 0u16..0x1000, any::<[bool; 8]>()).prop_map(|(x, y, b)| {
            let alarms = GalvoAlarms {
                over_temperature: b[0],
                following_error: b[1],
                low_speed_filtered: b[2],
                power: b[3],
                temperature_warning: b[4],
                low_speed: b[5],
                reserved_level: b[6],
                communication: b[7],
            };
            GalvoStatus::Velocity { x, y, alarms }
        }),
        (
            any::<u8>().prop_filter("typed codes", |c| !matches!(c, 64 | 65)),
            any::<u32>()
        )
            .prop_map(|(code, data)| GalvoStatus::Raw { code, data }),
    ]
}

proptest! {
    #[test]
    fn every_data3_word_round_trips(word in 0u32..=0xF_FFFF) {
        let fwd = ControllerExt::from_data3(word).unwrap();
        prop_assert_eq!(fwd.to_data3(), Ok(word));
        let dev = DeviceExt::from_data3(word).unwrap();
        prop_assert_eq!(dev.to_data3(), Ok(word));
    }

    #[test]
    fn every_code_round_trips(code in 0u32..16, data in any::<u16>()) {
        let word = u32::from(data) << 4 | code;
        prop_assert_eq!(ControllerExt::from_data3(word).unwrap().to_data3(), Ok(word));
        prop_assert_eq!(DeviceExt::from_data3(word).unwrap().to_data3(), Ok(word));
    }

    #[test]
    fn every_galvo_word_pair_round_trips(w1 in 0u32..=0xF_FFFF, w2 in 0u32..=0xF_FFFF) {
        let st = GalvoStatus::from_words(w1, w2).unwrap();
        prop_assert_eq!(st.to_words(), Ok((w1, w2)));
    }

    #[test]
    fn typed_values_round_trip(
        l in laser_control(),
        z in any::<u16>(),
        d in device_ext(),
        g in galvo_status(),
    ) {
        prop_assert_eq!(ControllerExt::from_data3(Laser(l).to_data3().unwrap()), Ok(Laser(l)));
        prop_assert_eq!(ControllerExt::from_data3(Z(z).to_data3().unwrap()), Ok(Z(z)));
        prop_assert_eq!(DeviceExt::from_data3(d.to_data3().unwrap()), Ok(d));
        let (w1, w2) = g.to_words().unwrap();
        prop_assert_eq!(GalvoStatus::from_words(w1, w2), Ok(g));
    }
}
