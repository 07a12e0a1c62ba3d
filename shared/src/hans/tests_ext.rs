//! Extension-code tests. Expected words (in [`super::vectors`], shared with the
//! on-target runner) are worked out by hand: DATA3 = data << 4 | code; DATA1 =
//! data_high << 4 | code >> 4, DATA2 = data_low << 4 | code & 0xF.

use super::ext::{ControllerExt, DeviceExt, ExtError, LaserAlarms, ZAlarms};
use super::status::{GalvoAlarms, GalvoStatus};
use super::vectors::{power, z15, DEVICE, FORWARD, GALVO, NORMAL};
use crate::model::LaserControl;
use proptest::prelude::*;

use ControllerExt::{Laser, Z};
use LaserControl::*;

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
