//! The receiver's copy of one channel's sample ring, and the word-level operations on
//! it: finding a falling edge in a window, gathering the 125 bit-centre samples of a
//! frame, and checking another channel against those centres.
//!
//! # Time base
//! Positions are Q16 sample counts (16 fraction bits) in a wrapping `u32`: sample `s`
//! of the stream is at `s << 16`, so a position wraps every 65 536 samples (4 096
//! words). Every distance the receiver works with is far below half of that, so
//! differences are taken with wrapping arithmetic and read as `i32`. Word `i` of the
//! stream (its 16 samples start at `i << 20`) lives in slot `i % RING_WORDS`.
//!
//! # Windows
//! Window `j` is the 32 samples from `32 j`, i.e. words `2j` and `2j + 1` (earlier word
//! in the high half), so sample `32 j + b` is bit `31 - b` of it.

use crate::hans::FRAME_BITS;

/// Words kept per channel: 1 024 samples, twice the longest frame at 4x plus its
/// search windows and skew, so a frame is always whole when it is decoded.
pub const RING_WORDS: usize = 64;
/// Fraction bits of the positions.
pub const FRAC: u32 = 16;
/// Half a sample (Q16).
pub const HALF: u32 = 1 << (FRAC - 1);
/// Most 32-sample windows a frame's centres can touch: 125 bits at 4.2 samples per
/// bit (4x and 5 % off) are 525 samples, 17 windows; one more for a partial start.
pub const MAX_WINDOWS: usize = 18;

/// `a - b` of two wrapping positions (or word counts), as a signed distance.
pub const fn diff(a: u32, b: u32) -> i32 {
    a.wrapping_sub(b) as i32
}

/// One channel's samples.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Ring {
    words: [u16; RING_WORDS],
}

/// The centre samples of one frame on the reference channel, per window: which
/// samples are bit centres and the reference's value there.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Centres {
    /// First window.
    pub first: u32,
    /// Windows used (at most [`MAX_WINDOWS`]).
    pub count: usize,
    /// Bit-centre masks of the windows.
    pub masks: [u32; MAX_WINDOWS],
    /// The reference's samples under the masks.
    pub values: [u32; MAX_WINDOWS],
}

impl Default for Ring {
    fn default() -> Self {
        Ring {
            words: [0; RING_WORDS],
        }
    }
}

impl Ring {
    /// Stores `src` as stream words `at`, `at + 1`, ... (`src` no longer than the
    /// ring; older words are overwritten).
    pub fn write(&mut self, at: u32, src: &[u16]) {
        let slot = at as usize % RING_WORDS;
        let first = src.len().min(RING_WORDS - slot);
        let (a, b) = src.split_at(first);
        if let Some(dst) = self.words.get_mut(slot..slot + a.len()) {
            dst.copy_from_slice(a);
        }
        if let Some(dst) = self.words.get_mut(..b.len()) {
            dst.copy_from_slice(b);
        }
    }

    /// Stream word `i`.
    fn word(&self, i: u32) -> u32 {
        self.words
            .get(i as usize % RING_WORDS)
            .map_or(0, |&w| u32::from(w))
    }

    /// Window `j` (32 samples from sample `32 j`).
    pub fn window(&self, j: u32) -> u32 {
        self.word(j.wrapping_mul(2)) << 16 | self.word(j.wrapping_mul(2).wrapping_add(1))
    }

    /// The 32 samples from sample `32 j + d` (`d` in -31..=31).
    fn shifted(&self, j: u32, d: i32) -> u32 {
        let here = self.window(j);
        if d > 0 {
            let next = self.window(j.wrapping_add(1));
            here << d | (next >> 1) >> (31 - d)
        } else if d < 0 {
            let prev = self.window(j.wrapping_sub(1));
            (prev << 1) << (31 + d) | here >> -d
        } else {
            here
        }
    }

    /// The first falling edge (a low sample right after a high one) whose low sample
    /// lies in `lo..=hi` (Q16 positions, rounded down to samples; at most a few words
    /// apart). Returns the edge position, half a sample before that low sample.
    pub fn first_fall(&self, lo: u32, hi: u32) -> Option<u32> {
        let s_lo = lo >> FRAC;
        let s_hi = hi >> FRAC;
        // Samples are numbered modulo 65 536 (positions wrap), words modulo 4 096.
        let span = s_hi.wrapping_sub(s_lo) & 0xFFFF;
        if span > 64 {
            return None;
        }
        let mut word = s_lo >> 4;
        let last = s_hi >> 4;
        let mut prev = self.word(word.wrapping_sub(1));
        for _ in 0..6 {
            let w = self.word(word);
            let x = prev << 16 | w;
            // Bit k of `falls`: sample 15 - k of this word is low, the one before high.
            let mut falls = !x & (x >> 1) & 0xFFFF;
            if word == s_lo >> 4 {
                falls &= 0xFFFF >> (s_lo & 15);
            }
            if word == last {
                falls &= !(0x7FFF >> (s_hi & 15));
            }
            if falls != 0 {
                let s = (word << 4) + falls.leading_zeros() - 16;
                return Some((s << FRAC).wrapping_sub(HALF));
            }
            if word == last {
                break;
            }
            prev = w;
            word = (word + 1) & 0xFFF;
        }
        None
    }

    /// The 125 bit-centre samples of a frame whose first centre is at `first` (Q16,
    /// plus half a sample so that truncation rounds), `ratio` (Q16) apart: the raw
    /// pattern (first bit at bit 124) and, when `centres` is given, the masks and
    /// values the other channels are checked against.
    pub fn gather(&self, first: u32, ratio: u32, mut centres: Option<&mut Centres>) -> u128 {
        let mut pos = first;
        let mut j = pos >> (FRAC + 5);
        if let Some(c) = centres.as_deref_mut() {
            c.first = j;
            c.count = 0;
        }
        let mut x = self.window(j);
        let mut mask = 0u32;
        let mut k = 0usize;
        let mut acc = 0u32;
        let mut pattern = 0u128;
        for bit in 0..FRAME_BITS as u32 {
            let s = pos >> FRAC;
            if s >> 5 != j {
                if let Some(c) = centres.as_deref_mut() {
                    if let (Some(m), Some(v)) = (c.masks.get_mut(k), c.values.get_mut(k)) {
                        *m = mask;
                        *v = x & mask;
                    }
                }
                k += 1;
                j = s >> 5;
                x = self.window(j);
                mask = 0;
            }
            let b = s & 31;
            acc = acc << 1 | (x << b) >> 31;
            mask |= 0x8000_0000 >> b;
            pos = pos.wrapping_add(ratio);
            if bit % 32 == 31 {
                pattern = pattern << 32 | u128::from(acc);
                acc = 0;
            }
        }
        pattern = pattern << 29 | u128::from(acc);
        if let Some(c) = centres {
            if let (Some(m), Some(v)) = (c.masks.get_mut(k), c.values.get_mut(k)) {
                *m = mask;
                *v = x & mask;
            }
            c.count = (k + 1).min(MAX_WINDOWS);
        }
        pattern
    }

    /// True when this channel, `d` samples later than the reference, has the
    /// reference's value at every centre of `centres`.
    pub fn agrees(&self, centres: &Centres, d: i32) -> bool {
        let mut bad = 0u32;
        let mut j = centres.first;
        for (m, v) in centres
            .masks
            .iter()
            .zip(&centres.values)
            .take(centres.count)
        {
            bad |= (self.shifted(j, d) & m) ^ v;
            j = j.wrapping_add(1);
        }
        bad == 0
    }
}
