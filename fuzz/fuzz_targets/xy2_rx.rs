#![no_main]
//! XY2-100 line receiver: arbitrary bytes become a pin map, a link configuration, a
//! split point and a run of `u16` port samples. The receiver must never panic; every
//! frame it accepts re-encodes to a word that decodes to the same frame under the
//! link's configuration and, unless parity is ignored (re-encoding then sets the
//! parity bit), is not all ones (never a frame that failed a check); its
//! frame counter matches the frame events; and feeding the samples in two chunks gives
//! the same events as one call.

use libfuzzer_sys::fuzz_target;
use shared::xy2::rx::{Event, PinMap, Receiver};
use shared::xy2::{decode, encode, LinkConfig, Mode, Parity, FRAME_MASK};

fn config(byte: u8) -> LinkConfig {
    LinkConfig {
        mode: if byte & 1 == 0 {
            Mode::Standard16
        } else {
            Mode::Extended18
        },
        parity: match (byte >> 1) % 3 {
            0 => Parity::WholeFrame,
            1 => Parity::DataOnly,
            _ => Parity::Ignore,
        },
    }
}

fuzz_target!(|data: &[u8]| {
    let [a, b, c, d, rest @ ..] = data else {
        return;
    };
    let pins = PinMap {
        sync: a & 0x1F,
        x: a >> 4 | (b & 1) << 4,
        y: b >> 3,
        z: (c & 0x20 != 0).then_some(c & 0x1F),
    };
    let link = config(c >> 6 | (d & 1) << 2);
    let Ok(mut rx) = Receiver::new(pins, link) else {
        return;
    };
    let mut rx2 = rx.clone();
    let samples: Vec<u16> = rest
        .chunks_exact(2)
        .map(|p| u16::from_le_bytes([p[0], p[1]]))
        .collect();

    let mut events = Vec::new();
    rx.feed(&samples, &mut |e| events.push(e));
    let mut frames = 0u32;
    for e in &events {
        if let Event::Frame(p) = e {
            frames += 1;
            for f in [p.x, p.y].into_iter().chain(p.z).flatten() {
                let w = encode(f, &link).expect("an accepted frame re-encodes");
                if link.parity != Parity::Ignore {
                    assert_ne!(w, FRAME_MASK, "all-ones accepted");
                }
                assert_eq!(decode(w, &link), Ok(f));
            }
            assert_eq!(p.z.is_some(), pins.z.is_some());
        }
        e.line_events(&mut |_| {});
    }
    assert_eq!(rx.counters().frames, frames);

    let split = usize::from(*d >> 1).min(samples.len());
    let mut chunked = Vec::new();
    rx2.feed(&samples[..split], &mut |e| chunked.push(e));
    rx2.feed(&samples[split..], &mut |e| chunked.push(e));
    assert_eq!(chunked, events);
});
