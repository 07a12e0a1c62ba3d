//! Clean lines sampled within a few hundred ppm of a whole number of samples a
//! bit (README "Known limits", docs/engineering-log.md, issue 4): every edge then sits at nearly the same
//! sub-sample phase, so every measured edge has the same rounding, which steps
//! by a whole sample each time that phase crosses a sample. A frame whose tail is
//! measured a sample off its timing at such a step is re-read at the phase its
//! successor's start edge shows (`HansRx::rephased`); nothing else changes.

use super::*;

/// Frames sent per run.
const FRAMES: usize = 400;

/// One clean line: `n` frames sampled at `ratio` samples a bit from `phase`
/// bits, every rising edge `rise` bits late against the falling ones
/// ([`oversample_asym`]; 0: symmetric), fed in 64-word chunks (as the firmware
/// does) to a receiver configured for `hz`.
struct Clean {
    ratio: f64,
    phase: f64,
    rise: f64,
    hz: u32,
    n: usize,
    seed: u32,
}

impl Clean {
    /// Runs the line; returns the frames sent and the index in them of every
    /// frame published. Panics (naming `at`) if a published frame was not sent,
    /// or not after the one published before it.
    fn run(&self, mode: Mode, at: &str) -> (Vec<Frame>, Vec<usize>) {
        let sent = frames(self.n, self.seed);
        let words = oversample_asym(&line_bits(&sent), self.ratio, self.phase, self.rise);
        let mut rx = HansRx::new(self.hz, mode).unwrap();
        let got = published(&run(&mut rx, &words, 64));
        let mut index = Vec::new();
        for f in &got {
            let from = index.last().map_or(0, |&i| i + 1);
            let i = sent[from..].iter().position(|s| s == f);
            assert!(
                i.is_some(),
                "{at}: published a frame not sent (after {index:?})"
            );
            index.push(from + i.unwrap_or(0));
        }
        (sent, index)
    }
}

/// Every sent frame after the first lock is published, in order, and nothing
/// else, at ratios from exactly 3 (no step) to 0.1 % above it (a step every 160
/// frames at 3.00005 to every 2.7 at 3.003), with 3.2 and 4 and offsets from
/// them as controls, in normal and super mode, at three sampling phases. Before
/// the re-read (`HansRx::rephased`), 3.00005 to 3.001 lost frames at some or
/// all phases (3.0001: 331 to 343 of 391 published, 3.0003: 211 to 223, 3.0005:
/// 103; README "Known limits", docs/engineering-log.md).
#[test]
fn clean_lines_near_whole_ratios_lose_nothing() {
    let cases = [
        (3.0, 37_500_000),
        (3.00005, 37_500_000),
        (3.0001, 37_500_000),
        (3.0003, 37_500_000),
        (3.0003439957615265, 37_504_300),
        (3.0005, 37_500_000),
        (3.001, 37_500_000),
        (3.003, 37_500_000),
        (3.2, 40_000_000),
        (3.2003, 40_000_000),
        (3.1997, 40_000_000),
        (3.9997, 50_000_000),
        (4.0, 50_000_000),
        (4.0003, 50_000_000),
    ];
    // The runs that lost frames, all reported at the end.
    let mut short = Vec::new();
    for (ratio, hz) in cases {
        for (k, phase) in [0.0, 0.37, 0.81].into_iter().enumerate() {
            for mode in [Mode::Normal { channel: 1 }, Mode::Super] {
                let at = format!("{ratio} {phase} {mode:?}");
                let line = Clean {
                    ratio,
                    phase,
                    rise: 0.0,
                    hz,
                    n: FRAMES,
                    seed: 11 + k as u32,
                };
                let (sent, index) = line.run(mode, &at);
                let got = index.len();
                let first = index.first().copied().unwrap_or(usize::MAX);
                if first > LOCK {
                    short.push(format!("{at}: first published is frame {first}"));
                    continue;
                }
                // All after the first, but the last (its successor's edge is cut).
                let expect = sent.len() - first - 1;
                eprintln!("{at}: {got} of {expect}");
                if got < expect {
                    short.push(format!("{at}: {got} of {expect}"));
                }
            }
        }
    }
    assert!(short.is_empty(), "lost frames: {short:#?}");
}

/// The same clean lines with asymmetric edges: every rising edge `rise` bits
/// late against the falling ones (negative: the falling ones late), 200 frames
/// a run, normal and super mode, three sampling phases. No frame that was not
/// sent is published anywhere, and 3.2x (40 MHz, the firmware's rate) loses
/// nothing. Near a whole ratio the rising and falling edges round to samples
/// one apart whenever a sample lies between them, which the tail confirmation
/// takes for a phase error: those lines lose frames (README "Known limits",
/// docs/engineering-log.md, 2026-12-03), at most [`ASYM_KNOWN_LOST`] each (of
/// the 6 runs of a ratio and asymmetry), pinned so that no change makes it worse
/// and a fix shows.
#[test]
fn asymmetric_clean_lines_publish_nothing_wrong() {
    const N: usize = 200;
    let mut report = Vec::new();
    for (ratio, hz) in ASYM_RATIOS {
        for rise in ASYM_RISES {
            let mut lost = 0;
            for (k, phase) in [0.0, 0.37, 0.81].into_iter().enumerate() {
                let line = Clean {
                    ratio,
                    phase,
                    rise,
                    hz,
                    n: N,
                    seed: 21 + k as u32,
                };
                for mode in [Mode::Normal { channel: 1 }, Mode::Super] {
                    let at = format!("{ratio} {rise} {phase} {mode:?}");
                    let (_, index) = line.run(mode, &at);
                    let first = index.first().copied().unwrap_or(N);
                    assert!(first <= LOCK, "{at}: first published is frame {first}");
                    // All after the first, but the last (its successor's edge
                    // is cut).
                    lost += (N - first - 1) - index.len();
                }
            }
            report.push(format!("{ratio} {rise}: {lost}"));
            let known = ASYM_KNOWN_LOST
                .iter()
                .find(|k| (k.0, k.1) == (ratio, rise))
                .map_or(0, |k| k.2);
            assert!(lost <= known, "{ratio} x, {rise} bit: {lost} frames lost");
        }
    }
    eprintln!("frames lost per ratio and asymmetry: {report:#?}");
}

/// Ratios of [`asymmetric_clean_lines_publish_nothing_wrong`] (with the
/// receiver's rate).
const ASYM_RATIOS: [(f64, u32); 5] = [
    (3.0, 37_500_000),
    (3.0003, 37_500_000),
    (3.2, 40_000_000),
    (4.0, 50_000_000),
    (4.0003, 50_000_000),
];

/// Asymmetries of [`asymmetric_clean_lines_publish_nothing_wrong`] (bits).
const ASYM_RISES: [f64; 6] = [-0.1, -0.05, -0.025, 0.025, 0.05, 0.1];

/// Frames lost today by [`asymmetric_clean_lines_publish_nothing_wrong`]'s
/// points (ratio, asymmetry, frames of its 6 runs of ~190 scored frames each):
/// a known limit, all at 3.0003x. Exactly 3x and 4x lose nothing (no rounding
/// steps), nor does 4.0003x here. The tail's second look
/// (`confirm::tail_again`: the edges between the pairs) took 2 / 8 / 4 / 32 at
/// -5 / -2.5 / +2.5 / +5 % down to 2 / 6 / 0 / 4.
const ASYM_KNOWN_LOST: &[(f64, f64, usize)] =
    &[(3.0003, -0.05, 2), (3.0003, -0.025, 6), (3.0003, 0.05, 4)];
