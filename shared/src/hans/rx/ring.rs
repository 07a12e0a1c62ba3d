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

use super::table::Table;
use crate::hans::FRAME_BITS;

/// Words kept per channel: 1 024 samples, twice the longest frame at 4x plus its
/// search windows and skew, so a frame is always whole when it is decoded.
pub const RING_WORDS: usize = 64;
/// Fraction bits of the positions.
pub const FRAC: u32 = 16;
/// Half a sample (Q16).
pub const HALF: u32 = 1 << (FRAC - 1);
/// Most 32-sample windows a frame's centres can touch: 125 bits at 4.2 samples per
/// bit (4x and 5 % off) are 525 samples, 17 windows, plus partial ones at both ends.
pub const MAX_WINDOWS: usize = 20;

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
    /// plus half a sample so that truncation rounds), `ratio` (Q16) apart, gathered
    /// window by window with `table` ([`super::table`]): the raw pattern (first bit
    /// at bit 124) and, when `centres` is given, the masks and values the other
    /// channels are checked against.
    pub fn gather(
        &self,
        table: &mut Table,
        first: u32,
        ratio: u32,
        mut centres: Option<&mut Centres>,
    ) -> u128 {
        let mut j = first >> (FRAC + 5);
        if let Some(c) = centres.as_deref_mut() {
            c.first = j;
        }
        // The first window starts anywhere before the first centre: its entry is the
        // one of the phase `skip` bit times earlier, minus those `skip` centres.
        let phase = first.wrapping_sub(j << (FRAC + 5));
        let skip = phase / ratio.max(1);
        let mut pos = first.wrapping_sub(skip.wrapping_mul(ratio));
        let mut skip = skip.min(12);
        let mut left = FRAME_BITS as u32;
        let mut words = [0u32; 4];
        let mut full = 0;
        let mut cur = 0u32;
        let mut used = 0u32;
        let mut k = 0;
        while left > 0 && k < MAX_WINDOWS {
            let e = table.entry(diff(pos, j << (FRAC + 5)));
            let x = self.window(j);
            let mut all = e.all;
            for _ in 0..skip {
                all &= !0x8000_0000u32.checked_shr(all.leading_zeros()).unwrap_or(0);
            }
            let n = e.count.saturating_sub(skip).min(left);
            let bits = (e.bits(x) << skip) & !(u32::MAX >> n);
            for _ in n + skip..e.count {
                all &= all.wrapping_sub(1);
            }
            if let Some(c) = centres.as_deref_mut() {
                if let (Some(m), Some(v)) = (c.masks.get_mut(k), c.values.get_mut(k)) {
                    *m = all;
                    *v = x & all;
                }
            }
            // Append the n bits, left-aligned, to the pattern words.
            cur |= bits >> used;
            used += n;
            if used >= 32 {
                if let Some(w) = words.get_mut(full) {
                    *w = cur;
                }
                full += 1;
                used -= 32;
                cur = if used == 0 { 0 } else { bits << (n - used) };
            }
            pos = pos.wrapping_add((n + skip).wrapping_mul(ratio));
            left -= n;
            skip = 0;
            j = j.wrapping_add(1);
            k += 1;
        }
        if let Some(c) = centres {
            c.count = k;
        }
        let [a, b, c, _] = words;
        (u128::from(a) << 96 | u128::from(b) << 64 | u128::from(c) << 32 | u128::from(cur)) >> 3
    }

    /// True when this channel, `d` samples later than the reference (at most ±31),
    /// has the reference's value at every centre of `centres`.
    pub fn agrees(&self, centres: &Centres, d: i32) -> bool {
        let mut bad = 0u32;
        let mut j = centres.first;
        let windows = centres
            .masks
            .iter()
            .zip(&centres.values)
            .take(centres.count);
        if d > 0 {
            let (l, r) = (d as u32 & 31, 31 - (d as u32 & 31));
            let mut here = self.window(j);
            for (m, v) in windows {
                j = j.wrapping_add(1);
                let next = self.window(j);
                bad |= ((here << l | (next >> 1) >> r) & m) ^ v;
                here = next;
            }
        } else if d < 0 {
            let (l, r) = (31 - (d.unsigned_abs() & 31), d.unsigned_abs() & 31);
            let mut prev = self.window(j.wrapping_sub(1));
            for (m, v) in windows {
                let here = self.window(j);
                bad |= ((((prev << 1) << l) | here >> r) & m) ^ v;
                prev = here;
                j = j.wrapping_add(1);
            }
        } else {
            for (m, v) in windows {
                bad |= (self.window(j) & m) ^ v;
                j = j.wrapping_add(1);
            }
        }
        bad == 0
    }
}
