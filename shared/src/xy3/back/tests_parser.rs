//! The streaming parser against hand-built streams and random chunkings.

use super::tests_packet::any_packet;
use super::vectors::{
    Expected, BAD_LENGTH_EVENTS, BAD_LENGTH_STATS, BAD_LENGTH_STREAM, GARBAGE_EVENTS,
    GARBAGE_STATS, GARBAGE_STREAM, SPLIT_EVENTS, SPLIT_STREAM,
};
use super::wire::check_length;
use super::*;
use proptest::prelude::*;

/// An owned copy of an [`Event`], so tests can collect them.
#[derive(Clone, PartialEq, Eq, Debug)]
enum Ev {
    P(u8, std::vec::Vec<u8>),
    Resynced(u32),
    Lost(LostSyncReason),
}

fn own(e: Event<'_>) -> Ev {
    match e {
        Event::Packet(p) => Ev::P(p.ty, p.payload.to_vec()),
        Event::Resynced { dropped } => Ev::Resynced(dropped),
        Event::LostSync { reason } => Ev::Lost(reason),
    }
}

/// Feeds `chunks` through `push_slice` and collects every event.
fn run_chunks(p: &mut Parser, chunks: &[&[u8]]) -> std::vec::Vec<Ev> {
    let mut out = vec![];
    for chunk in chunks {
        let mut rest = *chunk;
        while !rest.is_empty() {
            let (n, ev) = p.push_slice(rest);
            assert!(n >= 1 && n <= rest.len());
            if let Some(ev) = ev {
                out.push(own(ev));
            }
            rest = &rest[n..];
        }
    }
    out
}

fn run(bytes: &[u8]) -> (std::vec::Vec<Ev>, Stats) {
    let mut p = Parser::new();
    let mut out = vec![];
    for &b in bytes {
        if let Some(e) = p.push(b) {
            out.push(own(e));
        }
    }
    (out, p.stats())
}

fn bad_len(ty: u8, len: u8) -> Ev {
    Ev::Lost(LostSyncReason::BadLength { ty, len })
}

/// The owned form of a table event.
fn expected(e: &Expected) -> Ev {
    match *e {
        Expected::Packet(ty, payload) => Ev::P(ty, payload.to_vec()),
        Expected::Resynced(dropped) => Ev::Resynced(dropped),
        Expected::LostSync(reason) => Ev::Lost(reason),
    }
}

#[test]
fn garbage_before_the_first_sync_is_dropped_and_counted() {
    let (ev, stats) = run(GARBAGE_STREAM);
    let want: std::vec::Vec<Ev> = GARBAGE_EVENTS.iter().map(expected).collect();
    assert_eq!(ev, want);
    assert_eq!(stats, GARBAGE_STATS);
}

#[test]
fn nothing_is_delivered_before_sync() {
    // Well-formed packets, but no SYNC: all dropped.
    #[rustfmt::skip]
    let stream = [
        0x48, 0x01, 0x03, 0x61, 0x62, 0x63,
        0x48, 0x07, 0x01, 0x00,
        0x48, 0x41, 0x00,                   // SYNC, but nothing follows yet
    ];
    let (ev, stats) = run(&stream);
    assert_eq!(ev, vec![]);
    assert_eq!(stats.dropped_bytes, 10);
}

fn split_expected() -> std::vec::Vec<Ev> {
    SPLIT_EVENTS.iter().map(expected).collect()
}

#[test]
fn every_chunk_boundary_gives_the_same_events() {
    let s = SPLIT_STREAM;
    assert_eq!(run(s).0, split_expected());
    for i in 0..=s.len() {
        for j in i..=s.len() {
            let mut p = Parser::new();
            let ev = run_chunks(&mut p, &[&s[..i], &s[i..j], &s[j..]]);
            assert_eq!(ev, split_expected(), "split at {i}, {j}");
            assert_eq!(p.stats().packets, 4);
        }
    }
}

#[test]
fn known_type_with_bad_length_loses_sync() {
    let (ev, stats) = run(BAD_LENGTH_STREAM);
    let want: std::vec::Vec<Ev> = BAD_LENGTH_EVENTS.iter().map(expected).collect();
    assert_eq!(ev, want);
    assert_eq!(stats, BAD_LENGTH_STATS);
}

#[test]
fn bad_length_bytes_and_other_types_at_the_range_ends() {
    // (type, length, accepted)
    #[rustfmt::skip]
    let cases: &[(u8, u8, bool)] = &[
        (0x41, 0, true), (0x41, 1, false),
        (0x01, 2, false), (0x01, 3, true), (0x02, 200, true), (0x04, 201, false),
        (0x08, 2, false), (0x08, 3, true), (0x08, 200, true), (0x08, 201, false),
        (0x05, 0, false), (0x05, 2, true), (0x05, 44, true), (0x05, 45, false), (0x05, 46, false),
        (0x06, 19, false), (0x06, 20, true), (0x06, 21, false),
        (0x07, 0, false), (0x07, 1, true), (0x07, 22, true), (0x07, 23, false),
        (0x09, 0, false), (0x09, 4, true), (0x09, 6, false), (0x09, 88, true), (0x09, 92, false),
        (0x00, 0, true), (0x0A, 255, true), (0x40, 7, true), (0x48, 0x48, true),
    ];
    for &(ty, len, ok) in cases {
        let mut stream = vec![0x48, 0x41, 0x00, 0x48, ty, len];
        stream.extend(std::iter::repeat_n(0x30, usize::from(len)));
        let (ev, _) = run(&stream);
        let want = if ok {
            vec![Ev::Resynced(0), Ev::P(ty, vec![0x30; usize::from(len)])]
        } else {
            vec![Ev::Resynced(0), bad_len(ty, len)]
        };
        assert_eq!(ev, want, "type {ty:#x} len {len}");
    }
}

#[test]
fn a_length_byte_of_0x48_can_start_the_next_sync() {
    #[rustfmt::skip]
    let stream = [
        0x48, 0x41, 0x00,
        0x48, 0x05, 0x48,                    // TEMPERATURES with 72 bytes: bad
        0x41, 0x00, 0x48,                    // ... whose length byte starts a sync
        0x09, 0x04, 0x01, 0x00, 0x00, 0x00,  // WORKING_HOURS [1]
    ];
    let (ev, _) = run(&stream);
    assert_eq!(
        ev,
        vec![
            Ev::Resynced(0),
            bad_len(0x05, 0x48),
            Ev::Resynced(2),
            Ev::P(0x09, vec![1, 0, 0, 0]),
        ]
    );
}

#[test]
fn unknown_types_are_delivered_by_their_length() {
    #[rustfmt::skip]
    let stream = [
        0x48, 0x41, 0x00,
        0x48, 0x42, 0x02, 0xAA, 0xBB,         // unknown 0x42
        0x48, 0x0A, 0x00,                     // unknown 0x0A, empty
        0x48, 0xC0, 0x03, 0x48, 0x41, 0x00,   // unknown, payload looks like SYNC
        0x48, 0x41, 0x00,
    ];
    let (ev, stats) = run(&stream);
    assert_eq!(
        ev,
        vec![
            Ev::Resynced(0),
            Ev::P(0x42, vec![0xAA, 0xBB]),
            Ev::P(0x0A, vec![]),
            Ev::P(0xC0, vec![0x48, 0x41, 0x00]),
            Ev::P(0x41, vec![]),
        ]
    );
    assert_eq!(stats.packets, 4);
}

#[test]
fn missing_head_after_a_packet_loses_sync() {
    #[rustfmt::skip]
    let stream = [
        0x48, 0x41, 0x00,
        0x48, 0x07, 0x01, 0x04,              // ERROR_STATE [4]
        0x47, 0x07, 0x01, 0x00,              // head bit-flipped: lost
        0x48, 0x07, 0x01, 0x00,              // dropped while out of sync
    ];
    let (ev, stats) = run(&stream);
    assert_eq!(
        ev,
        vec![
            Ev::Resynced(0),
            Ev::P(0x07, vec![4]),
            Ev::Lost(LostSyncReason::MissingHead { byte: 0x47 }),
        ]
    );
    assert_eq!(stats.dropped_bytes, 8);
    assert!(!Parser::new().in_sync());
}

#[test]
fn back_to_back_syncs() {
    #[rustfmt::skip]
    let stream = [
        0x48, 0x41, 0x00, 0x48, 0x41, 0x00, 0x48, 0x41, 0x00,
        0x48, 0x02, 0x03, 0x58, 0x59, 0x33,
    ];
    let (ev, _) = run(&stream);
    assert_eq!(
        ev,
        vec![
            Ev::Resynced(0),
            Ev::P(0x41, vec![]),
            Ev::P(0x41, vec![]),
            Ev::P(0x02, b"XY3".to_vec()),
        ]
    );
}

#[test]
fn max_length_packets_back_to_back() {
    let mut stream = vec![0x48, 0x41, 0x00];
    let mut want = vec![Ev::Resynced(0)];
    for (ty, len) in [
        (0x80u8, 255u8),
        (0x01, 200),
        (0x05, 44),
        (0x09, 88),
        (0x07, 22),
        (0xFF, 255),
    ] {
        stream.extend([0x48, ty, len]);
        let payload: std::vec::Vec<u8> = (0..len).map(|i| i % 0x70).collect();
        stream.extend(&payload);
        want.push(Ev::P(ty, payload));
    }
    let (ev, stats) = run(&stream);
    assert_eq!(ev, want);
    assert_eq!(stats.packets, 6);
}

#[test]
fn a_truncated_packet_is_not_delivered() {
    let stream = [0x48, 0x41, 0x00, 0x48, 0x01, 0x05, 0x61, 0x62];
    let (ev, stats) = run(&stream);
    assert_eq!(ev, vec![Ev::Resynced(0)]);
    assert_eq!(stats.packets, 0);
}

fn encode_all(packets: &[Packet]) -> std::vec::Vec<u8> {
    let mut out = vec![];
    let mut buf = [0u8; 258];
    for p in packets {
        let n = p.encode(&mut buf).unwrap();
        out.extend_from_slice(&buf[..n]);
    }
    out
}

proptest! {
    #[test]
    fn random_packets_in_random_chunks_parse_back(
        packets in proptest::collection::vec(any_packet(), 1..12),
        cuts in proptest::collection::vec(1usize..300, 0..40),
    ) {
        let mut stream = vec![0x48, 0x41, 0x00];
        stream.extend(encode_all(&packets));
        let mut chunks = vec![];
        let mut rest = &stream[..];
        for c in cuts {
            let (a, b) = rest.split_at(c.min(rest.len()));
            chunks.push(a);
            rest = b;
        }
        chunks.push(rest);
        let mut p = Parser::new();
        let ev = run_chunks(&mut p, &chunks);
        prop_assert_eq!(&ev[0], &Ev::Resynced(0));
        prop_assert_eq!(ev.len(), packets.len() + 1);
        for (e, sent) in ev[1..].iter().zip(&packets) {
            let Ev::P(ty, payload) = e else { panic!("not a packet: {e:?}") };
            prop_assert_eq!(&Packet::decode(*ty, payload).unwrap(), sent);
        }
        prop_assert_eq!(p.stats().packets as usize, packets.len());
        prop_assert!(p.in_sync());
    }

    /// Garbage, bit flips and misalignment: no panic, and every delivered known
    /// packet keeps its type's length rule.
    #[test]
    fn arbitrary_bytes_never_break_the_rules(
        packets in proptest::collection::vec(any_packet(), 0..6),
        noise in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..8),
        skip in 0usize..8,
    ) {
        let mut stream = vec![0x48, 0x41, 0x00];
        stream.extend(encode_all(&packets));
        for (pos, bit) in noise {
            let i = pos % stream.len();
            stream[i] ^= 1 << (bit % 8);
        }
        let (ev, stats) = run(&stream[skip.min(stream.len())..]);
        for e in &ev {
            if let Ev::P(ty, payload) = e {
                prop_assert!(check_length(*ty, payload.len()).is_ok());
            }
        }
        let delivered = ev.iter().filter(|e| matches!(e, Ev::P(..))).count();
        prop_assert_eq!(stats.packets as usize, delivered);
    }
}
