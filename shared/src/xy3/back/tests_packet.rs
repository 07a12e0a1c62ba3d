//! The wire table worked out by hand from XY3-100 §5.2 (little-endian per erratum 6;
//! in [`super::vectors`], shared with the on-target runner), decode errors, encode
//! errors and round-trip properties.

use super::vectors::{hours, packet_rows, temps, txt, unknown};
use super::wire::{check_length, LengthRule};
use super::*;
use heapless::Vec as HVec;
use proptest::prelude::*;

#[test]
fn wire_table_encodes_and_decodes() {
    for (packet, bytes) in packet_rows() {
        let mut buf = [0u8; 300];
        let n = packet.encode(&mut buf).unwrap();
        assert_eq!(&buf[..n], bytes, "{packet:?}");
        assert_eq!(Packet::decode(bytes[1], &bytes[3..]).unwrap(), packet);
    }
}

/// Maximum lengths: the header bytes by hand, the payload a repeated pattern.
#[test]
fn max_length_packets() {
    #[rustfmt::skip]
    let cases: [(Packet, [u8; 3], &[u8]); 5] = [
        (Packet::Vendor(txt(&[b'A'; 200])), [0x48, 0x01, 0xC8], &[0x41]),
        (Packet::Debug(txt(&[0xEE; 200])),  [0x48, 0x08, 0xC8], &[0xEE]),
        (Packet::Temperatures(temps(&[Some(10_000); 22])), [0x48, 0x05, 0x2C], &[0x10, 0x27]),
        (Packet::WorkingHours(hours(&[Some(0x0102_0304); 22])), [0x48, 0x09, 0x58], &[0x04, 0x03, 0x02, 0x01]),
        (unknown(0x80, &[0x5A; 255]),       [0x48, 0x80, 0xFF], &[0x5A]),
    ];
    for (packet, header, pattern) in cases {
        let mut want = header.to_vec();
        while want.len() < 3 + usize::from(header[2]) {
            want.extend_from_slice(pattern);
        }
        let mut buf = [0u8; 258];
        let n = packet.encode(&mut buf).unwrap();
        assert_eq!(&buf[..n], &want[..]);
        assert_eq!(Packet::decode(header[1], &want[3..]).unwrap(), packet);
    }
}

#[test]
fn decode_rejects_bad_payloads() {
    let bl = |ty, len, min, max| Err(PacketError::BadLength { ty, len, min, max });
    assert_eq!(Packet::decode(0x41, &[0]), bl(0x41, 1, 0, 0));
    assert_eq!(Packet::decode(0x01, b"ab"), bl(0x01, 2, 3, 200));
    assert_eq!(Packet::decode(0x04, &[b'a'; 201]), bl(0x04, 201, 3, 200));
    assert_eq!(Packet::decode(0x08, &[0; 2]), bl(0x08, 2, 3, 200));
    assert_eq!(Packet::decode(0x05, &[0]), bl(0x05, 1, 2, 44));
    assert_eq!(Packet::decode(0x05, &[0; 46]), bl(0x05, 46, 2, 44));
    assert_eq!(Packet::decode(0x06, &[0; 19]), bl(0x06, 19, 20, 20));
    assert_eq!(Packet::decode(0x06, &[0; 21]), bl(0x06, 21, 20, 20));
    assert_eq!(Packet::decode(0x07, &[]), bl(0x07, 0, 1, 22));
    assert_eq!(Packet::decode(0x07, &[0; 23]), bl(0x07, 23, 1, 22));
    assert_eq!(Packet::decode(0x09, &[0; 3]), bl(0x09, 3, 4, 88));
    assert_eq!(Packet::decode(0x09, &[0; 92]), bl(0x09, 92, 4, 88));
    assert_eq!(Packet::decode(0x33, &[0; 256]), bl(0x33, 256, 0, 255));
    assert_eq!(
        Packet::decode(0x05, &[0; 3]),
        Err(PacketError::NotMultiple {
            ty: 0x05,
            len: 3,
            unit: 2
        })
    );
    assert_eq!(
        Packet::decode(0x09, &[0; 6]),
        Err(PacketError::NotMultiple {
            ty: 0x09,
            len: 6,
            unit: 4
        })
    );
    assert_eq!(
        Packet::decode(0x02, &[0x41, 0x80, 0x41]),
        Err(PacketError::NotAscii {
            ty: 0x02,
            index: 1,
            byte: 0x80
        })
    );
    assert_eq!(
        Packet::decode(0x03, &[0x41, 0x41, 0x41, 0xFF]),
        Err(PacketError::NotAscii {
            ty: 0x03,
            index: 3,
            byte: 0xFF
        })
    );
}

#[test]
fn encode_rejects_bad_packets_and_writes_nothing() {
    let mut buf = [0xAAu8; 8];
    let cases = [
        (
            Packet::Vendor(txt(b"abcdef")),
            EncodeError::BufferTooSmall {
                needed: 9,
                available: 8,
            },
        ),
        (
            Packet::Vendor(txt(b"ab")),
            EncodeError::Invalid(PacketError::BadLength {
                ty: 1,
                len: 2,
                min: 3,
                max: 200,
            }),
        ),
        (
            Packet::Serial(txt(&[b'a', 0xC3, b'b'])),
            EncodeError::Invalid(PacketError::NotAscii {
                ty: 4,
                index: 1,
                byte: 0xC3,
            }),
        ),
        (
            Packet::Temperatures(temps(&[])),
            EncodeError::Invalid(PacketError::BadLength {
                ty: 5,
                len: 0,
                min: 2,
                max: 44,
            }),
        ),
        (
            Packet::Temperatures(temps(&[Some(1), Some(-32767)])),
            EncodeError::ReservedValue { ty: 5, index: 1 },
        ),
        (
            Packet::WorkingHours(hours(&[Some(u32::MAX)])),
            EncodeError::ReservedValue { ty: 9, index: 0 },
        ),
        (unknown(0x07, &[0]), EncodeError::KnownType(0x07)),
        (unknown(0x41, &[]), EncodeError::KnownType(0x41)),
    ];
    for (packet, err) in cases {
        assert_eq!(packet.encode(&mut buf), Err(err), "{packet:?}");
        assert_eq!(buf, [0xAA; 8], "{packet:?} wrote on error");
    }
    assert_eq!(
        Packet::Sync.encode(&mut buf[..2]),
        Err(EncodeError::BufferTooSmall {
            needed: 3,
            available: 2
        })
    );
}

#[test]
fn error_codes_interpret() {
    assert_eq!(ErrorCode::from(0), ErrorCode::Ok);
    assert_eq!(ErrorCode::from(7), ErrorCode::OtherMechanical);
    assert_eq!(ErrorCode::from(8), ErrorCode::Undefined(8));
    assert_eq!(ErrorCode::from(99), ErrorCode::Undefined(99));
    assert_eq!(ErrorCode::from(100), ErrorCode::Vendor(100));
    assert_eq!(ErrorCode::from(255), ErrorCode::Vendor(255));
    assert_eq!(Component::Head.index(), 0);
    assert_eq!(Component::DacX.index(), 2);
    assert_eq!(Component::DriverX.index(), 7);
    assert_eq!(Component::GalvoX.index(), 12);
    assert_eq!(Component::MirrorW.index(), 21);
}

/// Any valid packet.
pub(super) fn any_packet() -> impl Strategy<Value = Packet> {
    let ascii = || proptest::collection::vec(0u8..0x80, 3..=200).prop_map(|v| txt(&v));
    let temp = proptest::option::of(any::<i16>().prop_filter("reserved", |t| *t != -32767));
    let hour = proptest::option::of(any::<u32>().prop_filter("reserved", |h| *h != u32::MAX));
    prop_oneof![
        Just(Packet::Sync),
        ascii().prop_map(Packet::Vendor),
        ascii().prop_map(Packet::Model),
        ascii().prop_map(Packet::Firmware),
        ascii().prop_map(Packet::Serial),
        proptest::collection::vec(any::<u8>(), 3..=200).prop_map(|v| Packet::Debug(txt(&v))),
        proptest::collection::vec(temp, 1..=22).prop_map(|v| Packet::Temperatures(temps(&v))),
        proptest::collection::vec(hour, 1..=22).prop_map(|v| Packet::WorkingHours(hours(&v))),
        any::<[u32; 5]>().prop_map(Packet::FrameErrorCount),
        proptest::collection::vec(any::<u8>(), 1..=22)
            .prop_map(|v| Packet::ErrorState(HVec::from_slice(&v).unwrap())),
        (
            any::<u8>().prop_filter("known", |t| LengthRule::for_type(*t).is_none()),
            proptest::collection::vec(any::<u8>(), 0..=255)
        )
            .prop_map(|(t, p)| unknown(t, &p)),
    ]
}

proptest! {
    #[test]
    fn encode_then_decode_is_identity(p in any_packet()) {
        let mut buf = [0u8; 258];
        let n = p.encode(&mut buf).unwrap();
        prop_assert_eq!(buf[0], 0x48);
        prop_assert_eq!(buf[1], p.ty());
        prop_assert_eq!(usize::from(buf[2]) + 3, n);
        prop_assert!(check_length(buf[1], n - 3).is_ok());
        prop_assert_eq!(Packet::decode(buf[1], &buf[3..n]).unwrap(), p);
    }

    /// decode never panics and whatever it accepts re-encodes to the same bytes.
    #[test]
    fn decode_accepts_only_what_encodes_back(t in any::<u8>(), payload in proptest::collection::vec(any::<u8>(), 0..=260)) {
        if let Ok(p) = Packet::decode(t, &payload) {
            let mut buf = [0u8; 258];
            let n = p.encode(&mut buf).unwrap();
            prop_assert_eq!(&buf[3..n], &payload[..]);
            prop_assert_eq!(buf[1], t);
        }
    }
}
