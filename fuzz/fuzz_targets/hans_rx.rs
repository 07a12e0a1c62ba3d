#![no_main]
//! HANS-100 line receiver on arbitrary sample words: any mode, sampling rate and
//! chunking. It must never panic, every published frame must re-encode to a pattern
//! that `Frame::decode` accepts, and the chunking must not change the events. Input
//! skipped (`HansRx::skip`) after it changes none of that, and a gap given in two
//! pieces behaves as the gap in one.
use libfuzzer_sys::fuzz_target;
use shared::hans::rx::{HansRx, Mode, RxEvent};
use shared::hans::Frame;

fuzz_target!(|data: &[u8]| {
    let Some((&head, rest)) = data.split_first() else {
        return;
    };
    let Some((&rate, rest)) = rest.split_first() else {
        return;
    };
    let Some((&chunk, rest)) = rest.split_first() else {
        return;
    };
    let mode = match head % 4 {
        0 => Mode::Normal {
            channel: head / 4 % 5 + 1,
        },
        1 => Mode::Vote3 {
            channels: [
                1,
                head / 4 % 4 + 2,
                1 + (head / 16 % 4 + 1 + head / 4 % 4) % 4 + 1,
            ],
        },
        2 => Mode::Vote5,
        _ => Mode::Super,
    };
    let hz = 37_500_000 + u32::from(rate) * 49_019;
    let Ok(mut whole) = HansRx::new(hz, mode) else {
        return;
    };
    let mut parts = whole;
    // Five channels' words interleaved in the input; channel n takes every fifth word.
    let words: Vec<u16> = rest
        .chunks_exact(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect();
    let per = words.len() / 5;
    let rings: Vec<Vec<u16>> = (0..5)
        .map(|c| words.iter().skip(c).step_by(5).take(per).copied().collect())
        .collect();
    let check = |e: &RxEvent| {
        if let RxEvent::Frame(f) = e {
            assert_eq!(Frame::decode(f.encode()), Ok(*f));
        }
    };
    let mut a = Vec::new();
    let all: Vec<&[u16]> = rings.iter().map(|r| &r[..]).collect();
    whole.push(&all, &mut |e| {
        check(&e);
        a.push(e);
    });
    let mut b = Vec::new();
    let step = usize::from(chunk % 17) + 1;
    let mut at = 0;
    while at < per {
        let n = step.min(per - at);
        let part: Vec<&[u16]> = rings.iter().map(|r| &r[at..at + n]).collect();
        parts.push(&part, &mut |e| b.push(e));
        at += n;
    }
    assert_eq!(a, b, "chunking changed the events");
    let (x, y) = (u32::from(rate) * 37, u32::from(chunk) * 91);
    let (mut one, mut two) = (whole, whole);
    let (mut c, mut d) = (Vec::new(), Vec::new());
    one.skip(x + y, &mut |e| c.push(e));
    two.skip(x, &mut |e| d.push(e));
    two.skip(y, &mut |e| d.push(e));
    one.push(&all, &mut |e| {
        check(&e);
        c.push(e);
    });
    two.push(&all, &mut |e| d.push(e));
    assert_eq!(c, d, "a gap in two pieces changed the events");
    assert_eq!(one.skipped(), two.skipped());
});
