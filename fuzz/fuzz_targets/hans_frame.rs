#![no_main]
//! HANS-100 frames from arbitrary bytes: decoding never panics, every accepted frame
//! re-encodes to exactly the bits it was decoded from, and encode -> decode is the
//! identity (also for the DATA3 and DATA1/DATA2 extension codes), and a flipped bit
//! of a valid frame is always rejected.
use libfuzzer_sys::fuzz_target;
use shared::hans::{ControllerExt, DeviceExt, Frame, GalvoStatus, WORD_MAX};

fuzz_target!(|data: &[u8]| {
    // 16-byte form (also exercises the length check on every other length).
    if let Ok(f) = Frame::from_bytes(data) {
        assert_eq!(&f.to_bytes()[..], data);
    }
    // Raw u128 pattern from the first 16 bytes.
    let mut raw = [0u8; 16];
    for (r, &d) in raw.iter_mut().zip(data) {
        *r = d;
    }
    let pattern = u128::from_be_bytes(raw);
    if let Ok(f) = Frame::decode(pattern) {
        assert_eq!(f.encode(), pattern);
    }
    // A frame at an arbitrary bit offset of the stream (first byte = offset).
    if let Some((&off, rest)) = data.split_first() {
        let off = usize::from(off);
        if let Ok(f) = Frame::read_at(rest, off) {
            let mut copy = rest.to_vec();
            f.write_at(&mut copy, off).unwrap();
            assert_eq!(copy, rest, "re-encoding changed the stream");
        }
    }
    // Round trip of three words taken from the input.
    let word = |i: usize| {
        let b = |j: usize| u32::from(*data.get(i + j).unwrap_or(&0));
        (b(0) << 16 | b(1) << 8 | b(2)) & WORD_MAX
    };
    let (w1, w2, w3) = (word(0), word(3), word(6));
    let f = Frame::new(w1, w2, w3).unwrap();
    assert_eq!(Frame::decode(f.encode()), Ok(f));
    assert_eq!(Frame::from_bytes(&f.to_bytes()), Ok(f));
    // Any single flipped line bit of a valid frame is rejected.
    let t = u32::from(*data.get(9).unwrap_or(&0)) % 125;
    assert!(Frame::decode(f.encode() ^ 1 << t).is_err());
    assert_eq!(ControllerExt::from_data3(w3).unwrap().to_data3(), Ok(w3));
    assert_eq!(DeviceExt::from_data3(w3).unwrap().to_data3(), Ok(w3));
    assert_eq!(
        GalvoStatus::from_words(w1, w2).unwrap().to_words(),
        Ok((w1, w2))
    );
    assert_eq!(ControllerExt::from_frame(&f).to_data3(), Ok(w3));
    assert_eq!(DeviceExt::from_frame(&f).to_data3(), Ok(w3));
    assert_eq!(GalvoStatus::from_frame(&f).to_words(), Ok((w1, w2)));
    assert_eq!(Frame::from_forward(&f.to_forward(), &Frame::CENTRE), Ok(f));
});
