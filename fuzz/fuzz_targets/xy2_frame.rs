#![no_main]
//! XY2-100 word codec: arbitrary bytes become a link configuration and a run of words
//! (full 32-bit, so words wider than 20 bits are exercised too). For each word:
//! decode never panics; an accepted frame re-encodes to the same word (Ignore: same
//! bits 19..1, whole-frame parity); the same bits read as a frame to encode round-trip
//! through decode; the STATUS word and frame codecs agree with themselves.

use libfuzzer_sys::fuzz_target;
use shared::xy2::{decode, encode, Frame, LinkConfig, Mode, Parity, StatusWord, FRAME_MASK};

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

/// A frame built from raw bits (may be invalid for the link: encode must say so).
fn frame(word: u32, selector: u8) -> Frame {
    match selector % 3 {
        0 => Frame::Position16(word as u16),
        1 => Frame::Position18(word >> 8),
        _ => Frame::Command {
            command: (word >> 8) as u8,
            parameter: word as u8,
        },
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&first, rest)) = data.split_first() else {
        return;
    };
    let cfg = config(first);
    for chunk in rest.chunks_exact(4) {
        let word = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);

        // Decode arbitrary words (including > 20 bits).
        if let Ok(f) = decode(word, &cfg) {
            assert_eq!(word & !FRAME_MASK, 0);
            let again = encode(f, &cfg).expect("a decoded frame re-encodes");
            if cfg.parity == Parity::Ignore {
                assert_eq!(again >> 1, word >> 1);
                assert_eq!(decode(again, &cfg), Ok(f));
            } else {
                assert_eq!(again, word);
            }
            let _ = f.to_model().expect("decoded frames convert");
        }

        // Encode arbitrary fields: Ok words decode back to the same frame.
        let f = frame(word, chunk[3]);
        if let Ok(w) = encode(f, &cfg) {
            assert_eq!(decode(w, &cfg), Ok(f));
        }

        // STATUS word and frame.
        if let Ok(s) = StatusWord::from_word(word as u16) {
            assert_eq!(s.to_word(), word as u16);
        }
        if let Ok(s) = StatusWord::from_frame(word, &cfg) {
            if cfg.parity == Parity::Ignore {
                assert_eq!(s.to_frame(&cfg) >> 1, word >> 1);
            } else {
                assert_eq!(s.to_frame(&cfg), word);
            }
        }
    }
});
