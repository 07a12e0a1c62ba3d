//! The sender's SYNC interleaving and the neutral-model mapping.

use super::neutral::{alarm_for, apply, error_codes_for, status_packet, StatusItem};
use super::tests_packet::any_packet;
use super::*;
use crate::model::{Alarms, HeadStatus, Text};
use heapless::Vec as HVec;
use proptest::prelude::*;

const SYNC: [u8; 3] = [0x48, 0x41, 0x00];

fn vendor() -> Packet {
    Packet::Vendor(Text::from_slice(b"abc").unwrap())
}

fn sent(s: &mut Sender, now: u64, p: &Packet) -> std::vec::Vec<u8> {
    let mut buf = [0u8; SEND_BUF_LEN];
    let n = s.send(now, p, &mut buf).unwrap();
    buf[..n].to_vec()
}

#[test]
fn sync_before_first_packet_then_by_interval() {
    let mut s = Sender::new(50_000);
    let v = [0x48, 0x01, 0x03, 0x61, 0x62, 0x63];
    assert_eq!(sent(&mut s, 1_000, &vendor()), [&SYNC[..], &v].concat());
    assert_eq!(sent(&mut s, 30_000, &vendor()), v);
    assert_eq!(sent(&mut s, 50_999, &vendor()), v);
    assert_eq!(sent(&mut s, 51_000, &vendor()), [&SYNC[..], &v].concat());
    assert_eq!(sent(&mut s, 51_001, &vendor()), v);
}

#[test]
fn sync_after_rate_change_and_backwards_clock() {
    let mut s = Sender::default();
    let v = [0x48, 0x01, 0x03, 0x61, 0x62, 0x63];
    sent(&mut s, 0, &vendor());
    s.note_rate_change();
    assert!(s.sync_due(1));
    assert_eq!(sent(&mut s, 1, &vendor()), [&SYNC[..], &v].concat());
    assert_eq!(sent(&mut s, 2, &vendor()), v);
    // A clock that jumps back sends a SYNC rather than none.
    assert_eq!(sent(&mut s, 0, &vendor()), [&SYNC[..], &v].concat());
    const { assert!(Sender::DEFAULT_SYNC_INTERVAL_US <= 100_000) };
}

#[test]
fn an_explicit_sync_is_not_doubled_and_poll_fills_idle_time() {
    let mut s = Sender::new(10);
    assert_eq!(sent(&mut s, 0, &Packet::Sync), SYNC);
    assert!(!s.sync_due(5));
    let mut buf = [0u8; 3];
    assert_eq!(s.poll(5, &mut buf), Ok(0));
    assert_eq!(s.poll(10, &mut buf), Ok(3));
    assert_eq!(buf, SYNC);
    assert!(!s.sync_due(19));
}

#[test]
fn failed_send_keeps_state() {
    let mut s = Sender::new(10);
    let mut small = [0u8; 7];
    assert_eq!(
        s.send(0, &vendor(), &mut small),
        Err(EncodeError::BufferTooSmall {
            needed: 9,
            available: 7
        })
    );
    assert!(s.sync_due(0));
    let bad = Packet::Vendor(Text::from_slice(b"x").unwrap());
    assert!(matches!(
        s.send(0, &bad, &mut [0u8; 20]),
        Err(EncodeError::Invalid(_))
    ));
    assert!(s.sync_due(0));
}

proptest! {
    /// What the sender writes, at any times, a fresh parser reads back exactly.
    #[test]
    fn sender_output_parses_back(
        items in proptest::collection::vec((any_packet(), 0u64..40_000), 1..20),
    ) {
        let mut s = Sender::default();
        let mut p = Parser::new();
        let mut now = 0;
        let mut got = vec![];
        let mut buf = [0u8; SEND_BUF_LEN];
        let mut syncs_sent = 0;
        for (packet, dt) in &items {
            now += dt;
            let n = s.send(now, packet, &mut buf).unwrap();
            if buf[..3] == SYNC && packet.ty() != 0x41 { syncs_sent += 1; }
            for &b in &buf[..n] {
                if let Some(Event::Packet(raw)) = p.push(b) {
                    got.push(Packet::decode(raw.ty, raw.payload).unwrap());
                }
            }
        }
        // The first SYNC only resynchronises; every other packet arrives, including
        // later SYNCs the sender put in between.
        let sent_packets: std::vec::Vec<&Packet> = items.iter().map(|(p, _)| p).collect();
        let data: std::vec::Vec<&Packet> = got.iter().filter(|p| **p != Packet::Sync).collect();
        let want: std::vec::Vec<&Packet> =
            sent_packets.into_iter().filter(|p| **p != Packet::Sync).collect();
        prop_assert_eq!(data, want);
        prop_assert!(syncs_sent >= 1 || items[0].0 == Packet::Sync);
    }
}

#[test]
fn apply_texts_temperatures_hours_frame_errors() {
    let mut st = HeadStatus::default();
    apply(&vendor(), &mut st);
    apply(&Packet::Serial(Text::from_slice(b"123").unwrap()), &mut st);
    assert_eq!(&st.identification.vendor[..], b"abc");
    assert_eq!(&st.identification.serial[..], b"123");
    st.temperatures = [Some(1); 22];
    apply(
        &Packet::Temperatures(HVec::from_slice(&[Some(2500), None, Some(-40)]).unwrap()),
        &mut st,
    );
    assert_eq!(&st.temperatures[..4], &[Some(2500), None, Some(-40), None]);
    assert!(st.temperatures[3..].iter().all(Option::is_none));
    apply(
        &Packet::WorkingHours(HVec::from_slice(&[None, Some(7)]).unwrap()),
        &mut st,
    );
    assert_eq!(&st.working_hours[..3], &[None, Some(7), None]);
    apply(&Packet::FrameErrorCount([1, 2, 3, 4, 5]), &mut st);
    assert_eq!(st.frame_errors, Some([1, 2, 3, 4, 5]));
    let before = st.clone();
    apply(&Packet::Sync, &mut st);
    apply(&Packet::Debug(Text::from_slice(b"xyz").unwrap()), &mut st);
    assert_eq!(st, before);
}

#[rustfmt::skip]
const CODE_ALARM: &[(u8, Alarms)] = &[
    (0, Alarms::NONE),
    (1, Alarms::TEMPERATURE),
    (2, Alarms::COMMUNICATION),
    (3, Alarms::MECHANICAL),
    (4, Alarms::POWER),
    (5, Alarms::ELECTRICAL),
    (6, Alarms::MECHANICAL),
    (7, Alarms::MECHANICAL),
    (8, Alarms::VENDOR),
    (99, Alarms::VENDOR),
    (100, Alarms::VENDOR),
    (255, Alarms::VENDOR),
];

#[test]
fn error_state_sets_codes_and_replaces_code_alarms() {
    for &(code, alarm) in CODE_ALARM {
        assert_eq!(alarm_for(code), alarm, "code {code}");
        // A stale code alarm goes away, the bridge's own alarm stays.
        let mut st = HeadStatus {
            alarms: Alarms::POWER.union(Alarms::STATUS_LOST),
            ..HeadStatus::default()
        };
        apply(
            &Packet::ErrorState(HVec::from_slice(&[0, code]).unwrap()),
            &mut st,
        );
        assert_eq!(st.alarms, alarm.union(Alarms::STATUS_LOST), "code {code}");
        assert_eq!(&st.error_codes[..3], &[Some(0), Some(code), None]);
    }
}

#[test]
fn status_packets_round_trip_through_apply() {
    let mut st = HeadStatus::default();
    st.identification.vendor = Text::from_slice(b"ACME").unwrap();
    st.identification.model = Text::from_slice(b"X").unwrap();
    st.identification.firmware = Text::from_slice(&[b'1', 0xE9, b'2']).unwrap();
    st.temperatures[0] = Some(3000);
    st.temperatures[3] = Some(-32767);
    st.temperatures[5] = Some(-100);
    st.working_hours[1] = Some(42);
    st.working_hours[2] = Some(u32::MAX);
    st.frame_errors = Some([9, 8, 7, 6, 5]);
    st.error_codes[4] = Some(1);
    st.alarms = Alarms::TEMPERATURE;
    let mut back = HeadStatus::default();
    for item in StatusItem::ALL {
        if let Some(p) = status_packet(&st, item) {
            let mut buf = [0u8; 258];
            let n = p.encode(&mut buf).unwrap();
            apply(&Packet::decode(buf[1], &buf[3..n]).unwrap(), &mut back);
        }
    }
    assert_eq!(&back.identification.vendor[..], b"ACME");
    assert_eq!(&back.identification.model[..], b"X  ");
    assert_eq!(&back.identification.firmware[..], b"1?2");
    assert!(back.identification.serial.is_empty());
    let mut temps = [None; 22];
    temps[0] = Some(3000);
    temps[5] = Some(-100);
    assert_eq!(back.temperatures, temps);
    let mut hours = [None; 22];
    hours[1] = Some(42);
    assert_eq!(back.working_hours, hours);
    assert_eq!(back.frame_errors, Some([9, 8, 7, 6, 5]));
    assert_eq!(
        &back.error_codes[..6],
        &[Some(0), Some(0), Some(0), Some(0), Some(1), None]
    );
    assert_eq!(back.alarms, Alarms::TEMPERATURE);
    assert_eq!(
        status_packet(&HeadStatus::default(), StatusItem::Temperatures),
        None
    );
    assert_eq!(
        status_packet(&HeadStatus::default(), StatusItem::FrameErrors),
        None
    );
}

#[rustfmt::skip]
const DERIVED: &[(Alarms, &[u8])] = &[
    // (alarms with no per-component codes, expected ERROR_STATE payload)
    (Alarms::NONE,          &[0]),
    (Alarms::POWER,         &[4]),
    (Alarms::TEMPERATURE,   &[1]),
    (Alarms::LASER,         &[5]),
    (Alarms::MECHANICAL,    &[7]),
    (Alarms::VENDOR,        &[100]),
    (Alarms::STATUS_LOST,   &[0, 2]),
    (Alarms::POSITION_Y,    &[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 7]),
    (Alarms(Alarms::POWER.0 | Alarms::TEMPERATURE.0 | Alarms::COMMUNICATION.0), &[4, 2]),
    (Alarms(1 << 31),       &[100]),
];

#[test]
fn error_state_derived_from_alarms() {
    for &(alarms, want) in DERIVED {
        let st = HeadStatus {
            alarms,
            ..HeadStatus::default()
        };
        assert_eq!(&error_codes_for(&st)[..], want, "{alarms:?}");
    }
    // Reported codes win over derivation when they already show an error.
    let mut st = HeadStatus {
        alarms: Alarms::POWER,
        ..HeadStatus::default()
    };
    st.error_codes[2] = Some(3);
    assert_eq!(&error_codes_for(&st)[..], &[0, 0, 3]);
}

proptest! {
    /// Fail-safe: an alarm is never sent as "no error".
    #[test]
    fn any_alarm_gives_a_nonzero_code(bits in any::<u32>(), codes in any::<[Option<u8>; 22]>()) {
        let st = HeadStatus { alarms: Alarms(bits), error_codes: codes, ..HeadStatus::default() };
        let Some(Packet::ErrorState(out)) = status_packet(&st, StatusItem::ErrorState) else {
            panic!("no error state");
        };
        prop_assert!(!out.is_empty());
        prop_assert_eq!(bits != 0 || codes.iter().any(|c| c.unwrap_or(0) != 0),
            out.iter().any(|&c| c != 0));
    }
}
