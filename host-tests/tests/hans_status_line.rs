//! The head's HANS-100 STATUS line as the firmware decodes it beside a HANS-100
//! controller: SPI6 halves of `HANS_HALF` words at `HANS_FS_HZ`, only every second
//! one passed on (`shared::hans::follow::status_every`), each decoded by one receiver that
//! follows the signal across the halves in between (`shared::hans::follow`, the
//! rule `status::hans_status` and `hans_in::hans_decode` share), every half passed
//! on while the receiver asks for it (`HANS_STATUS_CONTIGUOUS`: its lock cannot
//! coast yet; `follow::status_passes`, which `line::hans_status_in` asks). The
//! host pipeline runs the same path (`pipeline_hans_status`).
//!
//! Checks, on a line with the spec's ±25 % jitter and ±1 % rate offset: after the
//! acquisition (at most the first three halves) only every second half is
//! decoded, the lock is never lost again (no resync, no missing period), every
//! decoded half publishes from its first frames on (within two of the first frame
//! wholly inside it) and the later frames of it (a measured limit: one lost in
//! 672 halves), no frame of a half not decoded
//! and nothing unsent is published, in order; and each half gives more frames than
//! a new receiver per half (what the firmware did before) did.

use host_tests::impair;
use host_tests::line::drive::{bitstream_to_signal, HANS_BIT_RATE_HZ};
use host_tests::line::roles::STATUS;
use host_tests::line::sample::Oversampler;
use host_tests::wave::{Ps, Waveform};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use shared::hans::follow::{self, Follow};
use shared::hans::rx::{HansRx, Mode, RxEvent};
use shared::hans::{Frame, FRAME_BITS, WORD_MAX};
use shared::model::FaultKind;

/// `firmware/board.rs` `HANS_FS_HZ`: SPI6 is clocked at the TIM3 fs.
const FS_HZ: u32 = 40_000_000;
/// `firmware/channels.rs` `HANS_HALF`: 16-bit words per SPI6 DMA half (205 us).
const HALF: usize = 512;
/// Every how many halves beside a HANS-100 controller.
const EVERY: u32 = follow::status_every(true);
/// Halves of the run (the firmware numbers them from 1).
const HALVES: u32 = 16;
/// When the first frame starts.
const T0: Ps = 1_000_000;
/// The line's delay before the sampler.
const DELAY: Ps = 100_000;

/// The STATUS line: `frames` back to back at 12.5 Mbit/s `offset_pct` off, edges
/// jittered by up to `jitter` of a bit, sampled at [`FS_HZ`] from a random phase.
fn capture(frames: &[Frame], offset_pct: f64, jitter: f64, seed: u64) -> Vec<u16> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut bytes = vec![0u8; (frames.len() * FRAME_BITS).div_ceil(8)];
    for (i, f) in frames.iter().enumerate() {
        f.write_at(&mut bytes, i * FRAME_BITS).unwrap();
    }
    let rate = HANS_BIT_RATE_HZ * (1.0 + offset_pct / 100.0);
    let mut wave = Waveform::new();
    wave.insert(bitstream_to_signal(STATUS, &bytes, rate, T0).unwrap());
    if jitter > 0.0 {
        let max = (jitter * 1e12 / HANS_BIT_RATE_HZ) as u64;
        impair::jitter(&mut wave, &[], max, rng.random()).unwrap();
    }
    impair::skew(&mut wave, &[(STATUS, DELAY as i64)]).unwrap();
    let end = T0 + (bytes.len() as f64 * 8.0 * 1e12 / rate) as Ps;
    let sampler = Oversampler {
        fs_hz: f64::from(FS_HZ),
        start_ps: rng.random_range(0.0..100_000.0),
    };
    let words = sampler.sample(&wave, &[STATUS], end).unwrap();
    words[0]
        .iter()
        .flat_map(|&w| [(w >> 16) as u16, w as u16])
        .collect()
}

/// What one decoded half gave.
struct Half {
    /// Its number (1 = the first SPI6 half).
    number: u32,
    /// The published frames, as indices into the frames sent.
    frames: Vec<usize>,
    /// A resync or a missing period was reported with it (a lock lost).
    lost_lock: bool,
    /// After it, the decoder asked for every half (`HANS_STATUS_CONTIGUOUS`).
    asked: bool,
}

/// Random frames, enough to fill every half of a capture.
fn frames(rng: &mut ChaCha8Rng) -> Vec<Frame> {
    let n = (HALVES as usize * HALF * 16 * 12_500_000 / FS_HZ as usize) / 125 + 16;
    (0..n)
        .map(|_| {
            let mut w = || rng.random_range(0..=WORD_MAX);
            Frame::new(w(), w(), w()).unwrap()
        })
        .collect()
}

/// Runs the firmware's STATUS path over `words`: `hans_status_in` passes on every
/// [`EVERY`]-th half, or every half while the decoder asks for it, and
/// `hans_status` follows the signal with one receiver (`follow_signal`); or, as
/// before, a new receiver on every half decoded (not `follow_signal`: only every
/// [`EVERY`]-th half). The decoder keeps up (its request is seen by the next
/// half). Frames are matched to `sent`; a frame never sent fails the test.
fn decode(words: &[u16], sent: &[Frame], follow_signal: bool) -> Vec<Half> {
    let fresh = || HansRx::new(FS_HZ, Mode::Normal { channel: 1 });
    let mut rx = fresh().unwrap();
    let mut follow = Follow::new();
    let mut contiguous = follow_signal;
    let mut halves = Vec::new();
    for number in 1..=HALVES {
        if !follow::status_passes(number, EVERY, contiguous) {
            continue;
        }
        let from = (number - 1) as usize * HALF;
        let mut events = Vec::new();
        if follow_signal {
            let first_word = number.wrapping_mul(HALF as u32);
            follow.apply(&mut rx, 0, first_word, HALF as u32, fresh, &mut |e| {
                events.push(e)
            });
        } else {
            rx = fresh().unwrap();
        }
        rx.push(&[&words[from..from + HALF]], &mut |e| events.push(e));
        contiguous = follow_signal && !rx.coasts();
        let mut frames = Vec::new();
        let mut lost_lock = false;
        for e in events {
            match e {
                RxEvent::Frame(f) => {
                    // Frames repeat only by chance (random 20-bit words): the one
                    // sent nearest after the last one published.
                    let after = frames
                        .last()
                        .or(halves.iter().rev().find_map(|h: &Half| h.frames.last()))
                        .map_or(0, |&k| k + 1);
                    let k = sent[after..]
                        .iter()
                        .position(|s| *s == f)
                        .map(|k| after + k)
                        .unwrap_or_else(|| {
                            panic!("half {number}: published a frame never sent (or out of order)")
                        });
                    frames.push(k);
                }
                RxEvent::Fault {
                    kind: FaultKind::Resync | FaultKind::Missing,
                    ..
                } => lost_lock = true,
                RxEvent::Fault { .. } => {}
            }
        }
        halves.push(Half {
            number,
            frames,
            lost_lock,
            asked: contiguous,
        });
    }
    halves
}

#[test]
fn every_second_half_is_decoded_without_a_new_lock() {
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let (mut runs, mut per_half, mut per_half_before, mut decoded) = (0, 0, 0, 0);
    let mut acquisition = [0usize; 4];
    let (mut lost_all, mut lost_max, mut halves_losing) = (0, 0, 0);
    for offset in [-1.0, 0.0, 1.0] {
        for jitter in [0.0, 0.25] {
            for _ in 0..16 {
                let seed: u64 = rng.random();
                let sent = frames(&mut rng);
                let words = capture(&sent, offset, jitter, seed);
                assert!(words.len() >= HALVES as usize * HALF);
                let at = format!("{offset} %, ±{jitter} bit, seed {seed}");
                // Frame k starts at T0 + DELAY + k periods; word w is sampled from
                // w * 16 / fs on (plus a phase below 100 ns).
                let frame_ps =
                    FRAME_BITS as f64 * 1e12 / (HANS_BIT_RATE_HZ * (1.0 + offset / 100.0));
                let word_ps = 16.0 * 1e12 / f64::from(FS_HZ);
                let frame_at =
                    |word: usize| (word as f64 * word_ps - (T0 + DELAY) as f64) / frame_ps;

                let halves = decode(&words, &sent, true);
                // The acquisition: the halves up to the one after which the decoder
                // stopped asking for every half. Its lock must be out of the young
                // fit within three halves (~60 frames).
                let acquired = halves.iter().position(|h| !h.asked).unwrap() + 1;
                assert!(acquired <= 3, "{at}: {acquired} halves to acquire");
                acquisition[acquired] += 1;
                let settled = &halves[acquired..];
                assert!(!settled.is_empty());
                for (i, h) in settled.iter().enumerate() {
                    let at = format!("{at}, half {}", h.number);
                    // Only every second half once acquired.
                    if i > 0 {
                        assert_eq!(h.number, settled[i - 1].number + EVERY, "{at}");
                    }
                    assert!(!h.lost_lock && !h.asked, "{at}: the lock was lost");
                    let (start, end) = ((h.number - 1) as usize * HALF, h.number as usize * HALF);
                    // Frames surely within the half (a frame's margin each end).
                    let (first, last) = (frame_at(start).ceil() as usize, frame_at(end) as usize);
                    assert!(
                        h.frames.iter().all(|&k| k + 1 >= first && k <= last),
                        "{at}: a frame of a half not decoded: {:?}, {first}..{last}",
                        h.frames
                    );
                    let Some(&resumed) = h.frames.first() else {
                        panic!("{at}: nothing published");
                    };
                    // The first verified frame after a coast is held (it re-measures
                    // the phase), and `first` is known to a frame.
                    assert!(
                        resumed <= first + 2,
                        "{at}: resumed at {resumed}, first {first}"
                    );
                    let lost = (resumed..last).filter(|k| !h.frames.contains(k)).count();
                    lost_all += lost;
                    lost_max = lost_max.max(lost);
                    halves_losing += usize::from(lost > 0);
                    per_half += h.frames.len();
                }
                decoded += settled.len();
                // Before: a new receiver on every second half.
                let before = decode(&words, &sent, false);
                assert!(before.iter().all(|h| h.number.is_multiple_of(EVERY)));
                let same: Vec<&Half> = before
                    .iter()
                    .filter(|h| settled.iter().any(|s| s.number == h.number))
                    .collect();
                assert_eq!(same.len(), settled.len());
                per_half_before += same.iter().map(|h| h.frames.len()).sum::<usize>();
                runs += 1;
            }
        }
    }
    let (now, before) = (
        per_half as f64 / decoded as f64,
        per_half_before as f64 / decoded as f64,
    );
    println!(
        "{runs} runs, {decoded} halves decoded after the acquisition ({:?} runs took 1 / 2 / 3 contiguous halves): {now:.2} frames published per half (a new receiver per half: {before:.2}; a half is {:.2} frame periods)",
        &acquisition[1..],
        HALF as f64 * 16.0 * 12.5e6 / f64::from(FS_HZ) / 125.0
    );
    println!(
        "frames lost after the first published one of a half: {lost_all} in {halves_losing} halves, at most {lost_max} in one"
    );
    // A measured limit, not zero: at ±25 % jitter and +1 % offset one frame a few
    // frames into a half failed its check (1 frame in 672 halves, seed 6): after
    // the coast the phase is re-measured on two frames only. Failed frames are
    // counted, never published, and the next frames are published again.
    assert!(lost_max <= 1 && lost_all <= 2, "{lost_all} frames lost");
    // A new receiver hunts (1-2 frames) and publishes from its 8th settled start
    // edge on; the coasting one from the second frame wholly in the half.
    assert!(now >= before + 5.0, "{now:.2} against {before:.2}");
}

/// The host pipeline takes the head's STATUS words as the firmware does: in
/// halves, every second one beside a HANS-100 controller once the lock can coast
/// (`follow::status_passes`), one receiver following the signal across. Fed in
/// chunks of any size, it decodes exactly the halves `decode` (the firmware's
/// path above) does and publishes exactly their frames: each one sent, in order,
/// none from a half not decoded; and its counters count them.
#[test]
fn pipeline_hans_status() {
    use host_tests::pipeline::{HeadStatusInput, Options, Pipeline, HANS_STATUS_HALF};
    use shared::bridge::{Config, Protocol};
    assert_eq!(HANS_STATUS_HALF, HALF);
    let mut rng = ChaCha8Rng::seed_from_u64(61);
    let (mut runs, mut published, mut decoded) = (0usize, 0usize, 0usize);
    for offset in [-1.0, 0.0, 1.0] {
        for jitter in [0.0, 0.25] {
            for _ in 0..4 {
                let seed: u64 = rng.random();
                let sent = frames(&mut rng);
                let words = capture(&sent, offset, jitter, seed);
                let words = &words[..HALVES as usize * HALF];
                let at = format!("{offset} %, ±{jitter} bit, seed {seed}");
                let want = decode(words, &sent, true);

                let mut c = Config::default();
                c.controller.protocol = Protocol::Hans;
                c.head.protocol = Protocol::Hans;
                let options = Options {
                    hans_status_sample_hz: FS_HZ,
                    ..Options::default()
                };
                let mut p = Pipeline::new(&c, options).unwrap();
                // Chunks of 1..=700 words: halves end inside chunks, some chunks
                // complete two.
                let (mut fed, mut t_ns) = (0, 0u64);
                while fed < words.len() {
                    let to = (fed + rng.random_range(1..=700)).min(words.len());
                    t_ns += 1_000;
                    p.feed_status(t_ns, HeadStatusInput::HansStatus(&words[fed..to]))
                        .unwrap();
                    fed = to;
                }
                let got = p.hans_status_halves();
                let numbers = |h: &[_]| -> Vec<u32> {
                    h.iter()
                        .map(|h: &host_tests::pipeline::HansStatusHalf| h.number)
                        .collect()
                };
                let want_numbers: Vec<u32> = want.iter().map(|h| h.number).collect();
                assert_eq!(numbers(got), want_numbers, "{at}: halves decoded");
                // After the acquisition only every second half: 16 halves, 8 even.
                let asked = got.iter().filter(|h| h.asked).count();
                assert!((1..=2).contains(&asked), "{at}: {asked} halves asked for");
                assert_eq!(got.len(), 8 + asked, "{at}");
                assert!(got
                    .iter()
                    .all(|h| h.asked != h.number.is_multiple_of(EVERY)));
                let mut total = 0;
                for (g, w) in got.iter().zip(&want) {
                    let frames: Vec<Frame> = w.frames.iter().map(|&k| sent[k]).collect();
                    assert_eq!(g.frames, frames, "{at}, half {}", g.number);
                    total += g.frames.len();
                }
                // Every decoded half after the first publishes (a settled lock
                // resumes within two frames of the half's first whole one).
                assert!(got[1..].iter().all(|h| h.frames.len() >= 15), "{at}");
                let k = p.counters();
                assert_eq!(k.status_items, total as u64, "{at}");
                // Measured: none in these 24 runs (the firmware-path test above lost one
                // frame to a failed check in 672 halves).
                assert!(k.status_faults <= 2, "{at}: {k:?}");
                published += total;
                decoded += got.len();
                runs += 1;
            }
        }
    }
    println!(
        "pipeline: {runs} runs, {decoded} halves of {} decoded, {published} frames published ({:.2} a half)",
        runs * HALVES as usize,
        published as f64 / decoded as f64
    );
}
