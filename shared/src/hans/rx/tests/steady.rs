//! The steady-state shortcuts ([`HansRx::shortcuts`]: `evaluate` for a frame every
//! channel verified, `next` for a lone measured reference) against the general
//! path: on random lines with jitter, skew between the channels, glitches, dead or
//! noisy channels and gaps, in every mode and chunking, a receiver with them and
//! one without report the same events at the same positions and are in the same
//! state after every push. Both also check, in every `need`, that the kept latest delay is the
//! one the channels give (`HansRx::latest`).

use super::*;

/// A line of five channels: `frames` sent from one clock, each channel with its own
/// skew and edge jitter, sampled at `ratio` samples per bit.
#[derive(Clone, Debug)]
struct Line {
    ratio: f64,
    phase: f64,
    /// Edge jitter shared by every channel (the sender's), in bits, peak.
    jitter: f64,
    /// Per channel: skew in samples.
    skew: [f64; 5],
    /// Per channel: probability that a sample is flipped (a glitch).
    noise: [f64; 5],
    /// Per channel: from which word to which the channel is broken, and how (0:
    /// stuck low, 1: stuck high, 2: random words).
    broken: [Option<(usize, usize, u8)>; 5],
    /// Words in which every channel is stuck high (a gap: the lock is lost).
    gap: Option<(usize, usize)>,
}

/// Xorshift, for the sample-level randomness (proptest picks the seed).
struct Rng(u32);

impl Rng {
    fn next(&mut self) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        self.0
    }

    /// Uniform in -1..1.
    fn signed(&mut self) -> f64 {
        f64::from(self.next()) / f64::from(u32::MAX) * 2.0 - 1.0
    }
}

impl Line {
    /// The five channels' sample words.
    fn words(&self, sent: &[Frame], seed: u32) -> Vec<Vec<u16>> {
        let bits = line_bits(sent);
        let mut rng = Rng(seed | 1);
        // Edge k (the start of bit k) at k plus the sender's jitter.
        let edges: Vec<f64> = (0..=bits.len())
            .map(|k| k as f64 + self.jitter * rng.signed())
            .collect();
        let samples = ((bits.len() as f64 - 2.0) * self.ratio) as usize;
        (0..5)
            .map(|c| {
                let mut words = Vec::new();
                let mut bit = 0;
                for w in 0..samples / 16 {
                    let mut word = 0u16;
                    for k in 0..16 {
                        let s = (w * 16 + k) as f64 - self.skew[c];
                        let t = self.phase + s / self.ratio;
                        while bit + 1 < edges.len() && edges[bit + 1] <= t {
                            bit += 1;
                        }
                        let mut v = bits.get(bit).copied().unwrap_or(true);
                        if f64::from(rng.next()) / f64::from(u32::MAX) < self.noise[c] {
                            v = !v;
                        }
                        word = word << 1 | u16::from(v);
                    }
                    let broken = match self.broken[c] {
                        Some((from, to, how)) if (from..to).contains(&w) => Some(how),
                        _ => None,
                    };
                    word = match broken {
                        Some(0) => 0,
                        Some(1) => 0xFFFF,
                        Some(_) => rng.next() as u16,
                        None => word,
                    };
                    if self.gap.is_some_and(|(from, to)| (from..to).contains(&w)) {
                        word = 0xFFFF;
                    }
                    words.push(word);
                }
                words
            })
            .collect()
    }
}

/// Feeds `words` to both receivers `chunk` words at a time; after every push both
/// reported the same events at the same positions and are in the same state
/// (timing, delays, reference, counters, rings). Returns the frames published.
fn lockstep(
    fast: &mut HansRx,
    general: &mut HansRx,
    words: &[Vec<u16>],
    chunk: usize,
) -> Result<usize, TestCaseError> {
    let len = words.iter().map(Vec::len).min().unwrap_or(0);
    let mut published = 0;
    for at in (0..len).step_by(chunk.max(1)) {
        let end = (at + chunk.max(1)).min(len);
        let parts: [&[u16]; 5] = std::array::from_fn(|n| &words[n][at..end]);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        fast.push_at(&parts, &mut |p, e| a.push((p, e)));
        general.push_at(&parts, &mut |p, e| b.push((p, e)));
        prop_assert_eq!(&a, &b, "events of the push at word {}", at);
        let state = HansRx {
            general: false,
            ..*general
        };
        prop_assert!(*fast == state, "state after the push at word {}", at);
        published += a
            .iter()
            .filter(|(_, e)| matches!(e, RxEvent::Frame(_)))
            .count();
    }
    Ok(published)
}

fn mode() -> impl Strategy<Value = Mode> {
    prop_oneof![
        (1u8..=5).prop_map(|channel| Mode::Normal { channel }),
        Just(Mode::Vote3 {
            channels: [1, 3, 5]
        }),
        Just(Mode::Vote3 {
            channels: [2, 4, 5]
        }),
        Just(Mode::Vote5),
        Just(Mode::Super),
    ]
}

fn line() -> impl Strategy<Value = Line> {
    let broken = prop::option::weighted(0.25, (0usize..900, 1usize..600, 0u8..3))
        .prop_map(|b| b.map(|(from, len, how)| (from, from + len, how)));
    (
        3.0f64..=4.0,
        0.0f64..1.0,
        prop_oneof![Just(0.0), 0.0f64..0.25],
        prop::array::uniform5(-2.5f64..2.5),
        prop::array::uniform5(prop_oneof![3 => Just(0.0), 1 => 0.0f64..0.003]),
        prop::array::uniform5(broken),
        prop::option::weighted(0.15, (100usize..800, 10usize..120)),
    )
        .prop_map(|(ratio, phase, jitter, skew, noise, broken, gap)| Line {
            ratio,
            phase,
            jitter,
            skew,
            noise,
            broken,
            gap: gap.map(|(from, len)| (from, from + len)),
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]
    #[test]
    fn shortcuts_equal_the_general_path(line in line(), mode in mode(), seed in 1u32..,
                                        chunk in prop_oneof![1usize..8, 8usize..100]) {
        let sent = frames(28, seed);
        let words = line.words(&sent, seed);
        let hz = (line.ratio * 12.5e6).round() as u32;
        let mut fast = HansRx::new(hz, mode).unwrap();
        let mut general = HansRx::new(hz, mode).unwrap();
        general.general = true;
        let frames = lockstep(&mut fast, &mut general, &words, chunk)?;
        // A clean line publishes frames (the shortcuts were taken).
        let clean = line.jitter < 0.15
            && line.noise.iter().all(|&p| p == 0.0)
            && line.broken.iter().all(Option::is_none)
            && line.gap.is_none();
        if clean {
            prop_assert!(frames > 10, "{} frames published", frames);
        }
    }
}
