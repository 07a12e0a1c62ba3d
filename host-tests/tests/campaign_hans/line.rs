//! The HANS-100 controller's lines for the campaign, made cheaply: the `shared`
//! encoder's 125-bit patterns with idle gaps between frames, one sender clock with
//! a rate offset and edge jitter, sampled once into packed ring words; each channel
//! is that stream skewed by whole samples, then faulted on its own.

use rand::rngs::ChaCha8Rng;
use rand::RngExt;
use shared::hans::FRAME_BITS;

/// The sender's bit rate, Hz.
const BIT_HZ: f64 = 12_500_000.0;

/// One block's clean line: every bit's first sample and every frame's first bit.
pub struct Line {
    /// Packed samples, 16 a word, MSB first = earliest (the DMA ring layout).
    pub words: Vec<u16>,
    /// Sample index of each bit's first sample; one more entry ends the last bit.
    pub bit_start: Vec<u32>,
    /// Global bit index of each frame's first bit.
    pub frame_bit: Vec<usize>,
}

/// Sender and sampler of one block.
#[derive(Debug, Clone, Copy)]
pub struct Clock {
    /// Sampling rate, Hz.
    pub fs_hz: u32,
    /// Sender clock offset, ppm (positive: fast).
    pub ppm: f64,
    /// Edge jitter, uniform within +-this fraction of a bit.
    pub jitter: f64,
    /// Sampler phase at the first bit, in samples (0..1).
    pub phase: f64,
}

impl Line {
    /// Samples `patterns` (the encoder's `u128`, bit 124 first) sent after
    /// `gaps[i]` idle (low) bits each, as `clock` makes them.
    pub fn new(patterns: &[u128], gaps: &[usize], clock: &Clock, rng: &mut ChaCha8Rng) -> Line {
        let mut bits: Vec<bool> = Vec::with_capacity(patterns.len() * (FRAME_BITS + 1));
        let mut frame_bit = Vec::with_capacity(patterns.len());
        for (p, &gap) in patterns.iter().zip(gaps) {
            bits.resize(bits.len() + gap, false);
            frame_bit.push(bits.len());
            bits.extend((0..FRAME_BITS).rev().map(|i| (p >> i) & 1 == 1));
        }
        // The line idles low after the last frame for a few frame times.
        bits.resize(bits.len() + 4 * FRAME_BITS, false);
        let per_bit = f64::from(clock.fs_hz) / (BIT_HZ * (1.0 + clock.ppm * 1e-6));
        let edge = |k: usize, j: f64| clock.phase + k as f64 * per_bit + j * clock.jitter * per_bit;
        let bit_start: Vec<u32> = (0..=bits.len())
            .map(|k| {
                let j = if k == 0 {
                    0.0
                } else {
                    rng.random_range(-1.0..=1.0)
                };
                edge(k, j).ceil() as u32
            })
            .collect();
        let samples = *bit_start.last().unwrap_or(&0) as usize;
        let mut words = vec![0u16; samples.div_ceil(16)];
        for (k, &b) in bits.iter().enumerate() {
            if b {
                for s in bit_start[k]..bit_start[k + 1] {
                    words[s as usize >> 4] |= 0x8000 >> (s & 15);
                }
            }
        }
        Line {
            words,
            bit_start,
            frame_bit,
        }
    }

    /// Samples in the line.
    pub fn samples(&self) -> usize {
        self.words.len() * 16
    }

    /// This line delayed by `skew` whole samples (0..16), the same length.
    pub fn skewed(&self, skew: u32) -> Vec<u16> {
        if skew == 0 {
            return self.words.clone();
        }
        let mut prev = 0u16;
        self.words
            .iter()
            .map(|&w| {
                let out = (w >> skew) | (prev << (16 - skew));
                prev = w;
                out
            })
            .collect()
    }

    /// The sample span `[a, b)` of global bit `k`.
    pub fn bit_span(&self, k: usize) -> (usize, usize) {
        (self.bit_start[k] as usize, self.bit_start[k + 1] as usize)
    }

    /// The global bits whose samples meet `[a, b)`.
    pub fn bits_in(&self, a: usize, b: usize) -> std::ops::Range<usize> {
        let first = self
            .bit_start
            .partition_point(|&s| (s as usize) <= a)
            .saturating_sub(1);
        let last = self.bit_start.partition_point(|&s| (s as usize) < b);
        first..last.min(self.bit_start.len() - 1)
    }

    /// The complement partner of global bit `k` if it is a data bit of a frame
    /// (the 60 D/~D pairs, not the start pair or the stop bits).
    pub fn partner(&self, k: usize) -> Option<usize> {
        let f = self.frame_bit.partition_point(|&b| b <= k).checked_sub(1)?;
        let o = k - self.frame_bit[f];
        ((2..FRAME_BITS - 3).contains(&o)).then(|| if o.is_multiple_of(2) { k + 1 } else { k - 1 })
    }
}

/// Sample `s` of packed words.
pub fn get(w: &[u16], s: usize) -> bool {
    w.get(s >> 4).is_some_and(|x| x & (0x8000 >> (s & 15)) != 0)
}

/// Sets sample `s` of packed words.
pub fn set(w: &mut [u16], s: usize, v: bool) {
    if let Some(x) = w.get_mut(s >> 4) {
        let m = 0x8000 >> (s & 15);
        if v {
            *x |= m;
        } else {
            *x &= !m;
        }
    }
}

/// Inverts sample `s` of packed words.
pub fn flip(w: &mut [u16], s: usize) {
    if let Some(x) = w.get_mut(s >> 4) {
        *x ^= 0x8000 >> (s & 15);
    }
}
