#![no_main]
//! XY3-100 forward frames: decoding arbitrary words never panics, every accepted word
//! re-encodes to itself, and every encodable frame decodes back to itself.

use shared::xy3::{decode, encode, Frame, FrameSize};

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    // Byte 0 picks the receiver's frame size and the frame kind; bytes 1..5 are a word.
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    let mut raw = [0u8; 4];
    for (dst, src) in raw.iter_mut().zip(rest) {
        *dst = *src;
    }
    let word = u32::from_le_bytes(raw);
    let size = FrameSize::from_first_bit(selector & 1 == 1);

    // Decode arbitrary input: never panics; anything accepted re-encodes exactly.
    for candidate in [word, word & 0xFF_FFFF] {
        if let Ok(frame) = decode(candidate, size) {
            assert_eq!(encode(&frame), Ok((candidate, size)));
        }
    }

    // Encode arbitrary fields: either rejected, or decodes back to the same frame.
    let frame = match selector >> 1 & 3 {
        0 => Frame::Position24(word),
        1 => Frame::Position32(word),
        2 => Frame::Command24(word),
        _ => Frame::Command32 {
            code: word,
            unused: rest.get(4).copied().unwrap_or(0),
        },
    };
    let masked = match frame {
        Frame::Position24(v) => Frame::Position24(v & 0xF_FFFF),
        Frame::Position32(v) => Frame::Position32(v & 0x3FF_FFFF),
        Frame::Command24(c) => Frame::Command24(c & 0xF_FFFF),
        Frame::Command32 { code, unused } => Frame::Command32 {
            code: code & 0xF_FFFF,
            unused: unused & 0x3F,
        },
    };
    for f in [frame, masked] {
        if let Ok((w, s)) = encode(&f) {
            assert_eq!(decode(w, s), Ok(f));
        }
    }
    assert!(encode(&masked).is_ok());
});
