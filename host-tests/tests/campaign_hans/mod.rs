//! The HANS-100 controller campaign (see `a_million_faulted_hans_frames_none_corrupted`
//! in `pipeline_campaign.rs`): blocks of frames in every decode mode, random faults on
//! the oversampled channel lines, through the host pipeline to an XY2-100 head whose
//! output is decoded again by an independent XY2-100 receiver.

pub mod line;

use std::collections::HashMap;

use host_tests::pipeline::check::{expected, raw};
use host_tests::pipeline::stimulus::{self, GenTiming};
use host_tests::pipeline::{ControllerInput, HeadOutput, Options, Pipeline, HEAD_PINS_XY2};
use line::{flip, get, set, Clock, Line};
use rand::rngs::ChaCha8Rng;
use rand::RngExt;
use shared::bridge::{Config, HansDecode, LinkState};
use shared::hans::FRAME_BITS;
use shared::model::{Axis, ForwardFrame, Position};
use shared::xy2;

/// The firmware's HANS-100 DMA half, words per channel.
const HALF: usize = 512;

/// Which faults a block draws from (see the campaign's documentation for why
/// some are held back).
#[derive(Debug, Clone, Copy)]
pub struct Mix {
    /// Idle gaps between frames (re-acquisition of the timing).
    pub gaps: bool,
    /// Lines stuck high or low for 1..=20 frame times (re-alignment of a channel).
    pub stuck: bool,
    /// Noise bursts and bit flips may cover the start pair and stop bits (the
    /// start-edge region the receiver tracks its timing on); else they stay on the
    /// data bits.
    pub edges: bool,
}

/// What a block injected.
#[derive(Debug, Default, Clone, Copy)]
pub struct Injected {
    /// Frame periods with a fault on a used channel (flip, glitch, noise, stuck).
    pub faulted: u64,
    /// Of those: one bit's samples inverted.
    pub flips: u64,
    /// One sample inverted.
    pub glitches: u64,
    /// Noise bursts.
    pub noise: u64,
    /// Stuck stretches (1..=20 frames, high or low).
    pub stuck: u64,
    /// Idle gaps before a frame; of them longer than the input timeout.
    pub gaps: u64,
    /// Gaps longer than the input timeout (each must cost one input loss).
    pub long_gaps: u64,
    /// Complement pairs the faults had inverted in both bits, put back on the
    /// second (the excluded class: no frame check can see it).
    pub pairs_restored: u64,
}

/// What the head decoded, judged against the controller's frames.
#[derive(Debug, Default, Clone, Copy)]
pub struct Score {
    /// Frames the controller sent.
    pub sent: u64,
    /// Head frames carrying a controller frame (repeats included).
    pub forwarded: u64,
    /// Controller frames that reached the head (each counted once).
    pub distinct: u64,
    /// Head frames at the park position (fail-safe after a long gap).
    pub park: u64,
    /// Head frames that are no controller frame, or an older one than before.
    pub corrupted: u64,
    /// Frames the head's receiver rejected (the bridge must never send one).
    pub head_faults: u64,
    /// Input frames the free-running output replaced by a newer one.
    pub skipped: u64,
    /// Output slots that repeated the last frame.
    pub repeated: u64,
    /// Running -> fail-safe transitions.
    pub losses: u64,
    /// Fail-safe -> running transitions.
    pub recoveries: u64,
    /// Valid frames received outside running (recovery run).
    pub not_forwarded: u64,
    /// Periods the receiver reported lost as a whole (`Framing` faults).
    pub period_faults: u64,
    /// Channel faults (every kind) on the HANS channels.
    pub channel_faults: u64,
    /// Channel `missing` counts.
    pub missing: u64,
}

impl Score {
    /// Adds another block's score.
    pub fn add(&mut self, o: &Score) {
        self.sent += o.sent;
        self.forwarded += o.forwarded;
        self.distinct += o.distinct;
        self.park += o.park;
        self.corrupted += o.corrupted;
        self.head_faults += o.head_faults;
        self.skipped += o.skipped;
        self.repeated += o.repeated;
        self.losses += o.losses;
        self.recoveries += o.recoveries;
        self.not_forwarded += o.not_forwarded;
        self.period_faults += o.period_faults;
        self.channel_faults += o.channel_faults;
        self.missing += o.missing;
    }
}

impl Injected {
    /// Adds another block's injections.
    pub fn add(&mut self, o: &Injected) {
        self.faulted += o.faulted;
        self.flips += o.flips;
        self.glitches += o.glitches;
        self.noise += o.noise;
        self.stuck += o.stuck;
        self.gaps += o.gaps;
        self.long_gaps += o.long_gaps;
        self.pairs_restored += o.pairs_restored;
    }
}

/// The channels (1..=5) a decode mode uses.
fn used(decode: HansDecode) -> Vec<usize> {
    match decode {
        HansDecode::Normal(c) => vec![usize::from(c)],
        HansDecode::Vote3(c) => c.iter().map(|&c| usize::from(c)).collect(),
        HansDecode::Vote5 | HansDecode::Super => (1..=5).collect(),
    }
}

/// Random faults on one block's channels. Returns the channel streams (index 0 =
/// CH1; unused channels empty) and what was injected.
fn faulted_channels(
    line: &Line,
    decode: HansDecode,
    mix: &Mix,
    rng: &mut ChaCha8Rng,
    inj: &mut Injected,
) -> [Vec<u16>; 5] {
    let chans = used(decode);
    let skew: Vec<u32> = (0..5).map(|_| rng.random_range(0..=2)).collect();
    let clean: Vec<Vec<u16>> = (0..5)
        .map(|n| {
            if chans.contains(&(n + 1)) {
                line.skewed(skew[n])
            } else {
                Vec::new()
            }
        })
        .collect();
    let mut out = clean.clone();
    // Faulted spans per channel (channel sample coordinates), for the
    // complement-pair exclusion below.
    let mut spans: Vec<Vec<(usize, usize)>> = vec![Vec::new(); 5];
    let samples = line.samples();
    // The last frames stay clean so that every block ends with the link running
    // (a stuck line or a relock right at the end would leave it recovering).
    let faultable = line.frame_bit.len().saturating_sub(40);
    for &fb in &line.frame_bit[..faultable] {
        if rng.random_range(0..4) != 0 {
            continue;
        }
        inj.faulted += 1;
        let ch = chans[rng.random_range(0..chans.len())] - 1;
        let s = skew[ch] as usize;
        let w = &mut out[ch];
        let (f0, _) = line.bit_span(fb);
        let (_, f1) = line.bit_span(fb + FRAME_BITS - 1);
        let kinds = if mix.stuck { 0..8 } else { 0..6 };
        let kind = rng.random_range(kinds);
        match kind {
            // One bit inverted: every sample of it (a data bit unless `edges`).
            0..=2 => {
                inj.flips += 1;
                let bit = if mix.edges {
                    rng.random_range(0..FRAME_BITS)
                } else {
                    rng.random_range(2..FRAME_BITS - 3)
                };
                let (a, b) = line.bit_span(fb + bit);
                for k in a + s..b + s {
                    flip(w, k);
                }
                spans[ch].push((a + s, b + s));
            }
            // One sample inverted (a glitch shorter than a bit).
            3 => {
                inj.glitches += 1;
                let k = rng.random_range(f0..f1) + s;
                flip(w, k);
                spans[ch].push((k, k + 1));
            }
            // A noise burst, 3 samples to a whole frame (inside the data bits, bits
            // 4..118 of its frame, unless `edges`).
            4..=5 => {
                inj.noise += 1;
                let (lo, hi) = if mix.edges {
                    (f0, samples)
                } else {
                    (
                        line.bit_span(fb + 4).0,
                        line.bit_span(fb + FRAME_BITS - 7).0,
                    )
                };
                let a = rng.random_range(f0.max(lo)..f1.min(hi)) + s;
                let b = (a + rng.random_range(3..=400)).min(hi + s);
                for k in a..b {
                    set(w, k, rng.random());
                }
                spans[ch].push((a, b));
            }
            // Stuck high or low (open or shorted line) for 1..=20 frame times.
            _ => {
                inj.stuck += 1;
                let level = rng.random();
                let a = rng.random_range(f0..f1) + s;
                let len = rng.random_range(1..=20) * (f1 - f0);
                let b = (a + len).min(samples);
                for k in a..b {
                    set(w, k, level);
                }
                spans[ch].push((a, b));
            }
        }
    }
    // The excluded class: both bits of one complement pair inverted pass every
    // check (README "What each check catches"), on one channel or, by bitwise
    // majority, on most of them (which needs one channel with both). Wherever the
    // faults left an inverted sample in each bit of a pair (each bit's own samples,
    // where the receiver reads it), the second bit is put back. Only that class is
    // undone: a flipped bit, noise that leaves one bit of a pair alone, and a stuck
    // line (it inverts one bit of each pair) all stay.
    for ch in 0..5 {
        let s = skew[ch] as usize;
        let (w, c) = (&mut out[ch], &clean[ch]);
        let changed =
            |w: &[u16], (a, b): (usize, usize)| (a + s..b + s).any(|k| get(w, k) != get(c, k));
        for &(a, b) in &spans[ch] {
            for k in line.bits_in(a.saturating_sub(s), b.saturating_sub(s)) {
                let Some(p) = line.partner(k) else { continue };
                let (first, second) = (k.min(p), k.max(p));
                if changed(w, line.bit_span(first)) && changed(w, line.bit_span(second)) {
                    inj.pairs_restored += 1;
                    let (ra, rb) = line.bit_span(second);
                    for j in ra + s..rb + s {
                        set(w, j, get(c, j));
                    }
                }
            }
        }
    }
    std::array::from_fn(|n| std::mem::take(&mut out[n]))
}

/// The head's XY2-100 receiver input: the port sampled at each CLK falling edge
/// (`port_samples`), after the idle SYNC-low sample before the first frame.
fn head_samples(words: &[u32], clk: u8) -> Vec<u16> {
    let mut out = vec![0];
    out.extend(super::port_samples(words, clk));
    out
}

/// Decodes the head's output with a fresh XY2-100 receiver: the frames and the
/// number of faults it reported.
fn decode_head(c: &Config, out: &HeadOutput) -> (Vec<ForwardFrame>, u64) {
    let HeadOutput::Wave { words, pins, .. } = out else {
        panic!("not an XY2-100 head");
    };
    assert_eq!(*pins, HEAD_PINS_XY2);
    let link = xy2::LinkConfig {
        mode: c.head.xy2.mode,
        parity: c.head.xy2.parity,
    };
    let rx_pins = xy2::rx::PinMap {
        sync: pins.sync,
        x: pins.x,
        y: pins.y,
        z: pins.z,
    };
    let mut rx = xy2::rx::Receiver::new(rx_pins, link).expect("head receiver");
    let (mut frames, mut faults) = (Vec::new(), 0u64);
    rx.feed(&head_samples(words, pins.clk), &mut |e| {
        e.line_events(&mut |le| match le {
            shared::model::LineEvent::Frame(f) => frames.push(f),
            shared::model::LineEvent::Fault { .. } => faults += 1,
        })
    });
    faults += u64::from(rx.counters().framing);
    (frames, faults)
}

/// Runs one block: `n` frames in `decode` at `clock`, random gaps and faults.
pub fn block(
    c: &Config,
    clock: &Clock,
    mix: &Mix,
    n: u32,
    block: u32,
    rng: &mut ChaCha8Rng,
    inj: &mut Injected,
) -> Score {
    let frames = controller_frames(c, n, block);
    let patterns = wire_patterns(&frames);
    // Idle gaps: before about one frame in 200, mostly up to 300 us (the receiver
    // hunts again; the link holds), one in 25 of them 1.5..4 ms (longer than the
    // 1 ms input timeout: the link is lost and must recover).
    let mut gaps = vec![0usize; frames.len()];
    gaps[0] = 40;
    for g in gaps.iter_mut().skip(1) {
        if mix.gaps && rng.random_range(0..200) == 0 {
            inj.gaps += 1;
            *g = if rng.random_range(0..25) == 0 {
                inj.long_gaps += 1;
                rng.random_range(150..400) * FRAME_BITS
            } else {
                rng.random_range(1..=30 * FRAME_BITS)
            };
        }
    }
    let line = Line::new(&patterns, &gaps, clock, rng);
    let chans = faulted_channels(&line, c.controller.hans.decode, mix, rng, inj);
    let p = run(c, clock.fs_hz, &chans);
    score(c, &p, &frames)
}

/// Controller frames of a block, values unique within it at 16 bits.
fn controller_frames(c: &Config, n: u32, block: u32) -> Vec<ForwardFrame> {
    let t = GenTiming::default();
    let w = stimulus::controller_widths(c, t.xy3_size);
    (0..n)
        .map(|i| {
            let v16 = [
                (block * 7 + i * 37) & 0xFFFF,
                (60_000 + block * 3 + i * 53) & 0xFFFF,
                (i * 11 + block) & 0xFFFF,
            ];
            let v = [0, 1, 2].map(|k| v16[k] << (w[k] - 16));
            stimulus::frame(c, &t, v, None)
        })
        .collect()
}

/// The wire patterns the controller's encoder makes of `frames`.
fn wire_patterns(frames: &[ForwardFrame]) -> Vec<u128> {
    let mut hold = shared::hans::Frame::CENTRE;
    frames
        .iter()
        .map(|f| {
            hold = shared::hans::Frame::from_forward(f, &hold).expect("HANS frame");
            hold.encode()
        })
        .collect()
}

/// Feeds channel streams through a pipeline in the firmware's DMA halves.
fn run(c: &Config, fs_hz: u32, chans: &[Vec<u16>; 5]) -> Pipeline {
    let opts = Options {
        hans_sample_hz: fs_hz,
        ..Options::default()
    };
    let mut p = Pipeline::new(c, opts).expect("pipeline");
    let words = chans.iter().map(Vec::len).max().unwrap_or(0);
    let word_ns = 16e9 / f64::from(fs_hz);
    for from in (0..words).step_by(HALF) {
        let to = (from + HALF).min(words);
        let part: [&[u16]; 5] = std::array::from_fn(|k| chans[k].get(from..to).unwrap_or(&[]));
        // Handed over when its last word is in, its events spread over the next half
        // as the firmware's bridge loop does.
        let t_ns = (to as f64 * word_ns) as u64;
        let span = ((to - from) as f64 * word_ns) as u64;
        p.feed_spread(t_ns, span, ControllerInput::Hans(part))
            .expect("feed");
    }
    p.run_until((words as f64 * word_ns) as u64 + 300_000);
    p
}

/// `n` clean frames at 40 MHz on the channels of `c`'s decode mode, where each
/// channel of `noisy` (1..=5) has its data bits (4..118 of the frame) replaced by
/// noise in about `per_mille` of the frames (independently per channel), or, with
/// `per_mille` = 1000, in every frame. Returns the finished pipeline.
pub fn noisy_channels(c: &Config, noisy: &[usize], per_mille: u32, n: u32) -> Pipeline {
    let frames = controller_frames(c, n, 0);
    let mut gaps = vec![0usize; frames.len()];
    gaps[0] = 40;
    let clock = Clock {
        fs_hz: 40_000_000,
        ppm: 0.0,
        jitter: 0.0,
        phase: 0.4,
    };
    let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(u64::from(per_mille));
    let line = Line::new(&wire_patterns(&frames), &gaps, &clock, &mut rng);
    let chans: [Vec<u16>; 5] = std::array::from_fn(|n| {
        if !used(c.controller.hans.decode).contains(&(n + 1)) {
            return Vec::new();
        }
        let mut w = line.words.clone();
        if noisy.contains(&(n + 1)) {
            for &fb in &line.frame_bit {
                if rng.random_range(0..1000) < per_mille {
                    let (a, _) = line.bit_span(fb + 4);
                    let (b, _) = line.bit_span(fb + FRAME_BITS - 7);
                    for k in a..b {
                        set(&mut w, k, rng.random());
                    }
                }
            }
        }
        w
    });
    run(c, clock.fs_hz, &chans)
}

/// Judges the head's decoded output against the controller's frames.
fn score(c: &Config, p: &Pipeline, frames: &[ForwardFrame]) -> Score {
    let want: HashMap<_, usize> = frames
        .iter()
        .enumerate()
        .map(|(i, f)| (expected(c, f), i))
        .collect();
    let park = {
        let fs = &c.failsafe;
        let mut f = ForwardFrame::default();
        for (a, v) in [
            (Axis::X, fs.park_x),
            (Axis::Y, fs.park_y),
            (Axis::Z, fs.park_z),
        ] {
            f.axes[a.index()] = Position::from_raw(v, 20).ok();
        }
        expected(c, &f)
    };
    let (decoded, head_faults) = decode_head(c, &p.head_output());
    let mut s = Score {
        sent: frames.len() as u64,
        head_faults,
        ..Score::default()
    };
    // The head decodes every frame the bridge wrote (the last may be cut).
    let written = p.sent().len();
    assert!(
        decoded.len() == written || decoded.len() + 1 == written,
        "head decoded {} of {written}",
        decoded.len()
    );
    let mut last: Option<usize> = None;
    for f in &decoded {
        let r = raw(c, f);
        match want.get(&r) {
            Some(&i) if last.is_none_or(|l| i >= l) => {
                s.forwarded += 1;
                if last != Some(i) {
                    s.distinct += 1;
                }
                last = Some(i);
            }
            _ if r == park => s.park += 1,
            _ => s.corrupted += 1,
        }
    }
    let k = p.bridge_counters();
    s.skipped = k.skipped;
    s.repeated = k.repeated;
    s.losses = k.input_losses;
    s.recoveries = k.recoveries;
    s.not_forwarded = k.not_forwarded;
    let fr = k.line(shared::model::Line::Framing);
    s.period_faults = fr.total();
    for ch in 1..=5 {
        let l = k.line(shared::model::Line::HansChannel(ch));
        s.channel_faults += l.total();
        s.missing += l.missing;
    }
    assert_eq!(
        p.bridge().state(),
        LinkState::Running,
        "the link ends running"
    );
    s
}
