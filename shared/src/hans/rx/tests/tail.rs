//! A frame whose tail the line moves off its timing between two good start edges
//! (the tail confirmation, [`super::confirm`]): a transient phase excursion of
//! `δ` bits over the last 28 bits, the stop field taking it back up, so both
//! start edges lie where the timing puts them.

use super::*;

/// The frame that carries the excursion.
const AT: usize = 12;
/// First line bit of that frame whose start boundary the excursion moves: pair 47
/// (DATA3 D13), the last 14 data pairs and the stop field's first bit.
const FROM: usize = 94;
/// Last moved boundary: the start of bit 121 (D0's complement); the stop bits'
/// boundaries are where they belong.
const TO: usize = 121;

/// The frames sent: frame [`AT`] has DATA3's last 16 bits zero, so that its pairs
/// 45..=60 are `0 1` and its line a square wave of one bit per level there.
fn sent() -> Vec<Frame> {
    let mut sent = frames(24, 31);
    let f = sent[AT];
    sent[AT] = frame(f.data1(), f.data2(), f.data3() & !0xFFFF);
    sent
}

/// The line bits sampled at `ratio` samples per bit from `phase` bits, with the
/// bit boundaries `FROM..=TO` of frame [`AT`] moved `delta` bits later.
fn excursion(bits: &[bool], ratio: f64, phase: f64, delta: f64) -> Vec<u16> {
    let moved = AT * 125 + FROM..=AT * 125 + TO;
    let samples = ((bits.len() as f64 - phase) * ratio) as usize;
    let mut words = Vec::new();
    for w in 0..samples / 16 {
        let mut word = 0u16;
        for k in 0..16 {
            let t = phase + (w * 16 + k) as f64 / ratio;
            let mut b = t as usize;
            // Inside a moved bit's first `delta`: the previous bit still holds.
            if moved.contains(&b) && t - (b as f64) < delta {
                b -= 1;
            } else if moved.contains(&(b + 1)) && delta < 0.0 && t - (b as f64) >= 1.0 + delta {
                b += 1;
            }
            word = word << 1 | u16::from(bits.get(b).copied().unwrap_or(true));
        }
        words.push(word);
    }
    words
}

/// Frame [`AT`] read 0.65 bit late over its last 14 data pairs: each of them is
/// read one bit late, `1 0` (the previous pair's complement, this pair's data
/// bit), a valid pair with D = 1, so the pattern passes every check as a frame
/// with DATA3's last 14 bits set, which was never sent. Its start edges are on
/// time, so the start-edge confirmation alone published it (asserted as the old
/// behaviour with the tail check off); its mid-pair edges lie 0.35 bit early
/// against the timing, so the receiver rejects it, as a check failure on every
/// channel, in every mode, and publishes every other frame.
#[test]
fn a_tail_read_off_its_timing_is_not_published() {
    let sent = sent();
    let wrong = frame(
        sent[AT].data1(),
        sent[AT].data2(),
        sent[AT].data3() | 0x3FFF,
    );
    // At 4x the same excursion can pass: there two bits are eight samples, so
    // every checked edge of a line without jitter is measured with the same
    // rounding, up to half a sample (an eighth of a bit) towards the timing
    // (README "Known limits").
    // 3.0003: within the rounding steps of a line near a whole ratio, which a
    // frame whose edges show one is re-read across (`HansRx::rephased`): the
    // excursion's successor edge is not at the tail's rounding.
    for (ratio, hz) in [(3.0, 37_500_000), (3.0003, 37_500_000), (3.2, 40_000_000)] {
        for phase in [0.1, 0.45, 0.7] {
            let words = excursion(&line_bits(&sent), ratio, phase, 0.65);
            for mode in MODES {
                let mut rx = HansRx::new(hz, mode).unwrap();
                let events = run(&mut rx, &words, 16);
                let got = published(&events);
                let at = format!("{mode:?} {ratio} {phase}");
                assert!(!got.contains(&wrong), "{at}: wrong frame published");
                assert!(!got.contains(&sent[AT]), "{at}: not the frame sent");
                let mut expect = sent.clone();
                expect.remove(AT);
                assert_recovered(&expect, &got, LOCK);
                for ch in mode_channels(mode) {
                    assert_eq!(rx.stats(ch).unwrap().check_failures, 1, "{at} channel {ch}");
                }
            }
        }
    }
}

/// The same line with the excursion under half a bit (0.4): every bit is still
/// read right, but its tail's edges are 0.4 bit late: the frame is rejected too
/// (the check sees the phase, not the content; a good line's mean stays within
/// a few hundredths of a bit).
#[test]
fn a_tail_phase_excursion_is_rejected_even_when_read_right() {
    let sent = sent();
    let words = excursion(&line_bits(&sent), 3.2, 0.3, 0.4);
    let mut rx = HansRx::new(40_000_000, Mode::Super).unwrap();
    let got = published(&run(&mut rx, &words, 25));
    let mut expect = sent.clone();
    expect.remove(AT);
    assert_recovered(&expect, &got, LOCK);
    assert!(!got.contains(&sent[AT]));
}

/// The channels 1..=5 a mode uses.
fn mode_channels(mode: Mode) -> Vec<u8> {
    (1..=5)
        .filter(|&c| mode.channel_mask() & bit(c) != 0)
        .collect()
}
