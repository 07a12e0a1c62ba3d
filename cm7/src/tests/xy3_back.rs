//! The XY3-100 backchannel on the target: the shared hand-worked packet table and
//! parser streams (`shared::xy3::back::vectors`), a stream cut at every pair of chunk
//! boundaries, random packets through the parser, and garbage.

use super::prng::Prng;
use super::Case;
use shared::model::COMPONENTS;
use shared::xy3::back::vectors::{
    errors, hours, packet_rows, temps, txt, unknown, Expected, BAD_LENGTH_EVENTS, BAD_LENGTH_STATS,
    BAD_LENGTH_STREAM, GARBAGE_EVENTS, GARBAGE_STATS, GARBAGE_STREAM, SPLIT_EVENTS, SPLIT_STREAM,
};
use shared::xy3::back::wire::{check_length, LengthRule};
use shared::xy3::back::{Event, Packet, Parser, Stats, HOURS_NOT_SUPPORTED};
use shared::xy3::back::{SEND_BUF_LEN, TEMPERATURE_NOT_SUPPORTED};

/// This module's cases.
pub const CASES: &[Case] = &[
    Case {
        name: "xy3_back::packet_table",
        run: packet_table,
    },
    Case {
        name: "xy3_back::parser_hand_streams",
        run: parser_hand_streams,
    },
    Case {
        name: "xy3_back::parser_every_chunk_boundary",
        run: parser_every_chunk_boundary,
    },
    Case {
        name: "xy3_back::packets_through_parser_random",
        run: packets_through_parser_random,
    },
    Case {
        name: "xy3_back::parser_garbage_random",
        run: parser_garbage_random,
    },
];

/// Random packets sent through the parser.
const PACKETS: u32 = 2000;
/// Random garbage streams.
const GARBAGE_STREAMS: u32 = 300;

fn packet_table() {
    for (packet, bytes) in packet_rows() {
        let mut buf = [0u8; SEND_BUF_LEN];
        let n = packet.encode(&mut buf).unwrap();
        assert_eq!(&buf[..n], bytes, "{packet:?}");
        assert_eq!(Packet::decode(bytes[1], &bytes[3..]), Ok(packet));
    }
}

/// Whether an event is the one the table expects.
fn same(event: &Event<'_>, want: &Expected) -> bool {
    match (event, want) {
        (Event::Packet(p), Expected::Packet(ty, payload)) => p.ty == *ty && p.payload == *payload,
        (Event::Resynced { dropped }, Expected::Resynced(d)) => dropped == d,
        (Event::LostSync { reason }, Expected::LostSync(r)) => reason == r,
        _ => false,
    }
}

/// Feeds `chunks` one after the other through `push_slice`, checks the events
/// against `want` in order and returns the parser's totals.
fn run_chunks(chunks: &[&[u8]], want: &[Expected]) -> Stats {
    let mut parser = Parser::new();
    let mut next = 0;
    for chunk in chunks {
        let mut rest = *chunk;
        while !rest.is_empty() {
            let (n, event) = parser.push_slice(rest);
            assert!(n >= 1 && n <= rest.len());
            if let Some(event) = event {
                let expected = want.get(next);
                assert!(
                    expected.is_some_and(|w| same(&event, w)),
                    "event {next}: {event:?}, want {expected:?}"
                );
                next += 1;
            }
            rest = rest.get(n..).unwrap();
        }
    }
    assert_eq!(next, want.len(), "events missing");
    parser.stats()
}

fn parser_hand_streams() {
    assert_eq!(run_chunks(&[GARBAGE_STREAM], GARBAGE_EVENTS), GARBAGE_STATS);
    assert_eq!(
        run_chunks(&[BAD_LENGTH_STREAM], BAD_LENGTH_EVENTS),
        BAD_LENGTH_STATS
    );
    // Byte by byte gives the same as one slice.
    let mut parser = Parser::new();
    let mut next = 0;
    for &b in GARBAGE_STREAM {
        if let Some(event) = parser.push(b) {
            assert!(same(&event, &GARBAGE_EVENTS[next]), "{event:?}");
            next += 1;
        }
    }
    assert_eq!(next, GARBAGE_EVENTS.len());
    assert_eq!(parser.stats(), GARBAGE_STATS);
}

/// Cut into three chunks at every pair of boundaries: always the same events.
fn parser_every_chunk_boundary() {
    let s = SPLIT_STREAM;
    for i in 0..=s.len() {
        for j in i..=s.len() {
            let stats = run_chunks(&[&s[..i], &s[i..j], &s[j..]], SPLIT_EVENTS);
            assert_eq!(stats.packets, 4, "split at {i}, {j}");
        }
    }
}

/// A random byte below 0x80 (7-bit ASCII).
fn ascii(rng: &mut Prng) -> u8 {
    // Truncation intended: 7 random bits.
    rng.bits(7) as u8
}

/// A random valid packet of any type.
fn random_packet(rng: &mut Prng) -> Packet {
    let mut bytes = [0u8; 255];
    let n = |rng: &mut Prng, lo: u32, hi: u32| (lo + rng.next_u32() % (hi - lo + 1)) as usize;
    match rng.next_u32() % 8 {
        0 => Packet::Sync,
        1 => {
            let len = n(rng, 3, 200);
            bytes[..len].iter_mut().for_each(|b| *b = ascii(rng));
            Packet::Vendor(txt(&bytes[..len]))
        }
        2 => {
            let len = n(rng, 3, 200);
            // Truncation intended: random bytes.
            bytes[..len]
                .iter_mut()
                .for_each(|b| *b = rng.next_u32() as u8);
            Packet::Debug(txt(&bytes[..len]))
        }
        3 => {
            let mut t = [None; COMPONENTS];
            let len = n(rng, 1, COMPONENTS as u32);
            for v in &mut t[..len] {
                // Truncation intended: random 16 bits.
                let x = rng.next_u32() as i16;
                *v = (x != TEMPERATURE_NOT_SUPPORTED && x & 7 != 0).then_some(x);
            }
            Packet::Temperatures(temps(&t[..len]))
        }
        4 => {
            let mut h = [None; COMPONENTS];
            let len = n(rng, 1, COMPONENTS as u32);
            for v in &mut h[..len] {
                let x = rng.next_u32();
                *v = (x != HOURS_NOT_SUPPORTED && x & 7 != 0).then_some(x);
            }
            Packet::WorkingHours(hours(&h[..len]))
        }
        5 => Packet::FrameErrorCount([(); 5].map(|_| rng.next_u32())),
        6 => {
            let len = n(rng, 1, COMPONENTS as u32);
            bytes[..len]
                .iter_mut()
                .for_each(|b| *b = rng.next_u32() as u8);
            Packet::ErrorState(errors(&bytes[..len]))
        }
        _ => {
            // Truncation intended: a random type byte, redrawn while known.
            let mut ty = rng.next_u32() as u8;
            while LengthRule::for_type(ty).is_some() {
                ty = rng.next_u32() as u8;
            }
            let len = n(rng, 0, 255);
            bytes[..len]
                .iter_mut()
                .for_each(|b| *b = rng.next_u32() as u8);
            unknown(ty, &bytes[..len])
        }
    }
}

/// Random packets, encoded back to back after one SYNC and fed in random chunks:
/// each comes out of the parser exactly once, on its last byte, and decodes to
/// itself.
fn packets_through_parser_random() {
    let mut rng = Prng::new(0x0003_0B01);
    let mut parser = Parser::new();
    for &b in &[0x48, 0x41, 0x00] {
        assert!(parser.push(b).is_none());
    }
    let mut buf = [0u8; SEND_BUF_LEN];
    for k in 0..PACKETS {
        let packet = random_packet(&mut rng);
        let len = packet.encode(&mut buf).unwrap();
        assert!(check_length(buf[1], len - 3).is_ok());
        let mut rest = &buf[..len];
        let mut delivered = 0;
        while !rest.is_empty() {
            let cut = 1 + (rng.next_u32() % 64) as usize;
            let (chunk, after) = rest.split_at(cut.min(rest.len()));
            rest = after;
            let mut chunk = chunk;
            while !chunk.is_empty() {
                let (used, event) = parser.push_slice(chunk);
                chunk = &chunk[used..];
                match event {
                    None => {}
                    Some(Event::Resynced { dropped: 0 }) if k == 0 => {}
                    Some(Event::Packet(raw)) => {
                        assert!(chunk.is_empty() && rest.is_empty(), "early: {packet:?}");
                        assert_eq!(Packet::decode(raw.ty, raw.payload).as_ref(), Ok(&packet));
                        delivered += 1;
                    }
                    Some(other) => panic!("packet {k}: unexpected {other:?}"),
                }
            }
        }
        assert_eq!(delivered, 1, "packet {k}: {packet:?}");
    }
    assert_eq!(parser.stats().packets, PACKETS);
    assert_eq!(parser.stats().resyncs, 1);
    assert!(parser.in_sync());
}

/// Pure noise and bit-flipped valid streams: never a panic or a hang, every
/// delivered packet of a known type keeps its length rule, and the totals count
/// what was delivered.
fn parser_garbage_random() {
    let mut rng = Prng::new(0x0003_0B02);
    let mut stream = [0u8; 1024];
    let mut buf = [0u8; SEND_BUF_LEN];
    for round in 0..GARBAGE_STREAMS {
        let mut len = 0;
        if round % 2 == 0 {
            for b in &mut stream[..512] {
                // Mostly noise, with head and SYNC bytes often enough to resync.
                *b = match rng.next_u32() % 8 {
                    0 => 0x48,
                    1 => 0x41,
                    2 => 0x00,
                    // Truncation intended: a random byte.
                    _ => rng.next_u32() as u8,
                };
            }
            len = 512;
        } else {
            stream[..3].copy_from_slice(&[0x48, 0x41, 0x00]);
            len += 3;
            loop {
                let n = random_packet(&mut rng).encode(&mut buf).unwrap();
                if len + n > stream.len() {
                    break;
                }
                stream[len..len + n].copy_from_slice(&buf[..n]);
                len += n;
            }
            for _ in 0..1 + rng.next_u32() % 8 {
                let i = (rng.next_u32() as usize) % len;
                stream[i] ^= 1 << (rng.next_u32() % 8);
            }
        }
        let skip = (rng.next_u32() % 8) as usize;
        let mut parser = Parser::new();
        let mut delivered = 0u32;
        for &b in &stream[skip..len] {
            if let Some(Event::Packet(raw)) = parser.push(b) {
                assert!(check_length(raw.ty, raw.payload.len()).is_ok(), "{raw:?}");
                delivered += 1;
            }
        }
        assert_eq!(parser.stats().packets, delivered, "round {round}");
    }
}
