#![no_main]
//! Fuzzes the XY3-100 backchannel parser two ways:
//!
//! (a) the input as a raw byte stream: no panic, every delivered packet keeps its
//!     type's length rule, and chunked feeding gives the same events as byte-wise;
//! (b) the input as a recipe for a stream of valid packets and garbage segments,
//!     checked against an exact reference model of the sync rules (XY3-100 §5.2).

use libfuzzer_sys::fuzz_target;
use shared::xy3::back::wire::{check_length, ty, LengthRule, HEAD};
use shared::xy3::back::{Event, LostSyncReason, Packet, PacketError, Parser};

/// An owned event, for comparisons.
#[derive(Clone, PartialEq, Eq, Debug)]
enum Ev {
    Packet(u8, Vec<u8>),
    Resynced(u32),
    Lost(LostSyncReason),
}

fn own(e: Event<'_>) -> Ev {
    match e {
        Event::Packet(p) => Ev::Packet(p.ty, p.payload.to_vec()),
        Event::Resynced { dropped } => Ev::Resynced(dropped),
        Event::LostSync { reason } => Ev::Lost(reason),
    }
}

fn parse_bytewise(bytes: &[u8]) -> (Vec<Ev>, Parser) {
    let mut p = Parser::new();
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(e) = p.push(b) {
            out.push(own(e));
        }
    }
    (out, p)
}

fn parse_chunked(bytes: &[u8], chunk: usize) -> Vec<Ev> {
    let mut p = Parser::new();
    let mut out = Vec::new();
    for c in bytes.chunks(chunk.max(1)) {
        let mut rest = c;
        while !rest.is_empty() {
            let (n, e) = p.push_slice(rest);
            assert!(n >= 1 && n <= rest.len());
            if let Some(e) = e {
                out.push(own(e));
            }
            rest = &rest[n..];
        }
    }
    out
}

fn raw_stream(data: &[u8]) {
    let (events, parser) = parse_bytewise(data);
    let mut packets = 0u32;
    for e in &events {
        if let Ev::Packet(t, payload) = e {
            packets += 1;
            assert!(
                check_length(*t, payload.len()).is_ok(),
                "{t:#x} len {}",
                payload.len()
            );
            // The length was checked by the parser, so only the ASCII rule can fail.
            match Packet::decode(*t, payload) {
                Ok(_) | Err(PacketError::NotAscii { .. }) => {}
                Err(e) => panic!("delivered packet fails decode: {e:?}"),
            }
        }
    }
    assert_eq!(parser.stats().packets, packets);
    let chunk = data.first().map_or(1, |&b| usize::from(b % 17) + 1);
    assert_eq!(parse_chunked(data, chunk), events);
}

/// Reads recipe bytes; past the end it yields zeros so every recipe is complete.
struct Recipe<'a>(&'a [u8]);

impl Recipe<'_> {
    fn next(&mut self) -> u8 {
        let (&b, rest) = self.0.split_first().unwrap_or((&0, &[]));
        self.0 = rest;
        b
    }
}

enum Segment {
    Garbage(Vec<u8>),
    Packet(u8, Vec<u8>),
}

/// Why the model can be exact: the parser resynchronises on `48 41 00 48`, so any
/// 0x48 the sender did not mean as a head byte could fake a sync sequence in the
/// middle of garbage or of a payload, after which the parser would (correctly, by
/// the spec's rules) frame garbage as packets. Without a checksum nobody can tell
/// those apart from real packets, so the model forbids 0x48 in garbage and in
/// payloads. Type and length bytes may still be 0x48: a fake sequence starting
/// there would need a 0x48 as the second or third payload byte of a packet whose
/// length is 0x41 or 0x48, which is excluded. So every `48 41 00 48` in the stream
/// is a real SYNC packet followed by a real head byte, and the parser's behaviour
/// is fully determined by where the garbage is.
fn no_head(b: u8) -> u8 {
    if b == HEAD {
        HEAD + 1
    } else {
        b
    }
}

fn build(recipe: &mut Recipe<'_>) -> Vec<Segment> {
    let mut segs = Vec::new();
    while !recipe.0.is_empty() && segs.len() < 64 {
        let op = recipe.next();
        if op % 4 == 0 {
            let n = usize::from(recipe.next() % 16);
            segs.push(Segment::Garbage(
                (0..n).map(|_| no_head(recipe.next())).collect(),
            ));
            continue;
        }
        let t = match recipe.next() % 12 {
            0 | 1 => ty::SYNC,
            k @ 2..=10 => k - 1,
            _ => {
                let t = recipe.next();
                if LengthRule::for_type(t).is_some() {
                    continue;
                }
                t
            }
        };
        let len = match LengthRule::for_type(t) {
            Some(r) => {
                let choices = (r.max - r.min) / r.unit + 1;
                r.min + (recipe.next() % choices) * r.unit
            }
            None => recipe.next(),
        };
        let ascii = matches!(t, ty::VENDOR | ty::MODEL | ty::FIRMWARE | ty::SERIAL);
        let payload = (0..len)
            .map(|_| {
                let b = recipe.next();
                no_head(if ascii { b & 0x7F } else { b })
            })
            .collect();
        segs.push(Segment::Packet(t, payload));
    }
    segs
}

fn model(data: &[u8]) {
    let segs = build(&mut Recipe(data));
    let mut stream = Vec::new();
    let mut want = Vec::new();
    let mut in_sync = false;
    let mut dropped = 0u32;
    for (i, seg) in segs.iter().enumerate() {
        match seg {
            Segment::Garbage(g) => {
                stream.extend_from_slice(g);
                if g.is_empty() {
                    continue;
                }
                if in_sync {
                    in_sync = false;
                    want.push(Ev::Lost(LostSyncReason::MissingHead { byte: g[0] }));
                }
                dropped += g.len() as u32;
            }
            Segment::Packet(t, p) => {
                stream.extend_from_slice(&[HEAD, *t, p.len() as u8]);
                stream.extend_from_slice(p);
                if in_sync {
                    want.push(Ev::Packet(*t, p.clone()));
                    continue;
                }
                // A SYNC resynchronises when the next byte is a head, i.e. when the
                // next non-empty segment is a packet.
                let next_is_packet = segs[i + 1..]
                    .iter()
                    .find(|s| !matches!(s, Segment::Garbage(g) if g.is_empty()))
                    .is_some_and(|s| matches!(s, Segment::Packet(..)));
                if *t == ty::SYNC && next_is_packet {
                    in_sync = true;
                    want.push(Ev::Resynced(dropped));
                    dropped = 0;
                } else {
                    dropped += 3 + p.len() as u32;
                }
            }
        }
    }
    let (got, parser) = parse_bytewise(&stream);
    assert_eq!(got, want);
    assert_eq!(parser.in_sync(), in_sync);
    // Every delivered packet was sent as one valid packet.
    for e in &got {
        if let Ev::Packet(t, p) = e {
            assert!(Packet::decode(*t, p).is_ok());
        }
    }
}

fuzz_target!(|data: &[u8]| {
    raw_stream(data);
    model(data);
});
