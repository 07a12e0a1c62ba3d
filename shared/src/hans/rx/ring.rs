//! The receiver's copy of one channel's sample ring, and the word-level operations on
//! it: finding a falling edge in a window, gathering the 125 bit-centre samples of a
//! frame, and checking another channel against those centres.
//!
//! # Time base
//! Positions are Q16 sample counts (16 fraction bits) in a wrapping `u32`: sample `s`
//! of the stream is at `s << 16`, so a position wraps every 65 536 samples (4 096
//! words). Every distance the receiver works with is far below half of that, so
//! differences are taken with wrapping arithmetic and read as `i32`. Word `i` of the
//! stream has its 16 samples from `i << 20`.
//!
//! # Windows
//! Window `j` is the 32 samples from `32 j`, i.e. words `2j` and `2j + 1` (earlier word
//! in the high half), so sample `32 j + b` is bit `31 - b` of it. The ring stores
//! windows (slot `j % 32`), so every read is one load.

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

/// The top `n` bits (n <= 32).
fn all_top(n: u32) -> u32 {
    !u32::MAX.checked_shr(n).unwrap_or(0)
}

/// Bits appended left-aligned to four words.
struct Acc {
    words: [u32; 4],
    full: usize,
    cur: u32,
    used: u32,
}

impl Acc {
    /// Appends the top `n` bits of `bits` (the rest zero, n <= 24).
    #[inline(always)]
    fn push(&mut self, bits: u32, n: u32) {
        self.cur |= bits >> self.used;
        self.used += n;
        if self.used >= 32 {
            if let Some(w) = self.words.get_mut(self.full) {
                *w = self.cur;
            }
            self.full += 1;
            self.used -= 32;
            // `used` < n here, so the shift is 1..=24.
            self.cur = bits << (n - self.used);
        }
    }
}

/// The window of two consecutive stream words: the earlier one in the high half.
/// Both are fetched with one (unaligned) load and swapped.
#[inline(always)]
fn pair(&[x, y]: &[u16; 2]) -> u32 {
    (u32::from(x) | u32::from(y) << 16).rotate_right(16)
}

/// Stores the windows of `src` into `dst` from its start.
#[inline(always)]
fn copy(dst: &mut [u32], src: &[[u16; 2]]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = pair(s);
    }
}

/// One channel's samples, stored as windows: slot `j % 32` holds window `j` (words
/// `2j` and `2j + 1`), so reading a window is one load.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Ring {
    windows: [u32; RING_WORDS / 2],
}

/// The centre samples of one frame on the reference channel, per window: which
/// samples are bit centres and the reference's value there.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Centres {
    /// First window.
    pub first: u32,
    /// Windows used (at most [`MAX_WINDOWS`]).
    pub count: usize,
    /// Per window: the bit-centre mask and the reference's samples under it (side
    /// by side, so that a compare fetches both with one double load).
    pub windows: [[u32; 2]; MAX_WINDOWS],
}

impl Default for Ring {
    fn default() -> Self {
        Ring {
            windows: [0; RING_WORDS / 2],
        }
    }
}

impl Ring {
    /// Stores `src` as stream words `at`, `at + 1`, ... (older words are
    /// overwritten). Whole windows are written in one store, in runs of slots up
    /// to the ring's end, so the copy loop carries two pointers and no slot index
    /// (~4 instructions a window).
    pub fn write(&mut self, at: u32, src: &[u16]) {
        let mut at = at;
        let mut src = src;
        if at & 1 == 1 {
            if let Some((&w, rest)) = src.split_first() {
                self.set_later(at >> 1, w);
                src = rest;
                at = at.wrapping_add(1);
            }
        }
        let (pairs, rest) = src.as_chunks::<2>();
        let j = at >> 1;
        let t = j as usize % (RING_WORDS / 2);
        // The slots up to the ring's end, then from its start (a lap or more
        // overwrites in stream order, as one store after the other would).
        let (head, more) = pairs.split_at(pairs.len().min(RING_WORDS / 2 - t));
        copy(self.windows.get_mut(t..).unwrap_or_default(), head);
        for lap in more.chunks(RING_WORDS / 2) {
            copy(&mut self.windows, lap);
        }
        if let Some(&w) = rest.first() {
            self.set_earlier(j.wrapping_add(pairs.len() as u32), w);
        }
    }

    /// Stores `w` as the earlier word (the high half) of window `j`.
    #[inline(always)]
    fn set_earlier(&mut self, j: u32, w: u16) {
        if let Some(slot) = self.slot_mut(j) {
            *slot = *slot & 0xFFFF | u32::from(w) << 16;
        }
    }

    /// Stores `w` as the later word (the low half) of window `j`.
    #[inline(always)]
    fn set_later(&mut self, j: u32, w: u16) {
        if let Some(slot) = self.slot_mut(j) {
            *slot = *slot & 0xFFFF_0000 | u32::from(w);
        }
    }

    /// [`Ring::write`] of words `from .. from + n` of each of the first five
    /// `chunks` at once (vote5 and super mode; `chunks[k]` goes to `rings[k]`): one
    /// pass over the word pairs stores each pair of every channel, so the loop and
    /// the slot index are paid once per pair instead of once per pair and channel,
    /// and the per-call set-up once instead of five times. The range is checked
    /// once against the shortest chunk, so every source then has `n` words by
    /// construction and no length is compared again. False (nothing stored) when
    /// a chunk is missing or shorter.
    pub fn write_all(
        rings: &mut [Ring; 5],
        at: u32,
        chunks: &[&[u16]],
        from: usize,
        n: usize,
    ) -> bool {
        let Some(&[a, b, c, d, e]) = chunks.get(..5) else {
            return false;
        };
        let to = from.wrapping_add(n);
        let len = a.len().min(b.len()).min(c.len()).min(d.len()).min(e.len());
        if to < from || to > len {
            return false;
        }
        let src = [a, b, c, d, e].map(|s| s.get(from..to).unwrap_or_default());
        if n > 0 {
            Ring::store_all(rings, at, src);
        }
        true
    }

    /// The five-ring store proper: `src` nonempty and all of one length (which the
    /// loop's lookups rely on to need no checks).
    #[inline(always)]
    fn store_all(rings: &mut [Ring; 5], at: u32, src: [&[u16]; 5]) {
        let mut at = at;
        let mut src = src;
        if at & 1 == 1 {
            for (ring, s) in rings.iter_mut().zip(src.iter_mut()) {
                if let Some((&w, rest)) = s.split_first() {
                    ring.set_later(at >> 1, w);
                    *s = rest;
                }
            }
            at = at.wrapping_add(1);
        }
        let [a, b, c, d, e] = src.map(|s| s.as_chunks::<2>());
        let mut j = at >> 1;
        let pairs = [a.0, b.0, c.0, d.0, e.0];
        for p in 0..a.0.len() {
            let t = j as usize % (RING_WORDS / 2);
            // Indexed, not destructured: the five slots are then one base register
            // plus constant offsets.
            for (k, s) in pairs.iter().enumerate() {
                if let (Some(w), Some(slot)) = (
                    s.get(p),
                    rings.get_mut(k).and_then(|r| r.windows.get_mut(t)),
                ) {
                    *slot = pair(w);
                }
            }
            j = j.wrapping_add(1);
        }
        for (ring, rest) in rings.iter_mut().zip([a.1, b.1, c.1, d.1, e.1]) {
            if let Some(&w) = rest.first() {
                ring.set_earlier(j, w);
            }
        }
    }

    fn slot_mut(&mut self, j: u32) -> Option<&mut u32> {
        self.windows.get_mut(j as usize % (RING_WORDS / 2))
    }

    /// Stream word `i` and the one before it.
    pub fn word_and_prev(&self, i: u32) -> (u32, u32) {
        (self.word(i), self.word(i.wrapping_sub(1)))
    }

    /// Stream word `i`.
    fn word(&self, i: u32) -> u32 {
        let w = self.window(i >> 1);
        if i & 1 == 0 {
            w >> 16
        } else {
            w & 0xFFFF
        }
    }

    /// Window `j` (32 samples from sample `32 j`).
    #[inline(always)]
    pub fn window(&self, j: u32) -> u32 {
        self.windows
            .get(j as usize % (RING_WORDS / 2))
            .copied()
            .unwrap_or(0)
    }

    /// The first falling edge (a low sample right after a high one) whose low sample
    /// lies in `lo..=hi` (Q16 positions, rounded down to samples, at most 31 samples
    /// apart). Returns the edge position, half a sample before that low sample.
    pub fn first_fall(&self, lo: u32, hi: u32) -> Option<u32> {
        // Samples are numbered modulo 65 536 (positions wrap). The 32 samples from the
        // one before `lo` hold the whole range.
        let s0 = (lo >> FRAC).wrapping_sub(1) & 0xFFFF;
        let span = (hi >> FRAC).wrapping_sub(s0) & 0xFFFF;
        if span == 0 || span > 31 {
            return None;
        }
        let (j, off) = (s0 >> 5, s0 & 31);
        let x = self.window(j) << off | (self.window(j.wrapping_add(1)) >> 1) >> (31 - off);
        // Bit 31 - i of `falls`: sample s0 + i is low and the one before high.
        let falls = !x & (x >> 1) & (u32::MAX << (31 - span));
        if falls == 0 {
            return None;
        }
        let s = (s0 + falls.leading_zeros()) & 0xFFFF;
        Some((s << FRAC).wrapping_sub(HALF))
    }

    /// The 125 bit-centre samples of a frame whose first centre is at `first` (Q16,
    /// plus half a sample so that truncation rounds), `ratio` (Q16) apart, gathered
    /// window by window with `table` ([`super::table`]): the raw pattern (first bit
    /// at bit 124). With `KEEP`, `centres` receives the masks and values the other
    /// channels are checked against (a lone channel needs none).
    #[inline(never)]
    pub fn gather<const KEEP: bool>(
        &self,
        table: &mut Table,
        first: u32,
        ratio: u32,
        centres: &mut Centres,
    ) -> u128 {
        let slots = core::hint::black_box(table.slots);
        let mut j = first >> (FRAC + 5);
        centres.first = j;
        // The first window starts anywhere before the first centre: its entry is the
        // one of the phase `skip` bit times earlier, minus those `skip` centres.
        let phase = first.wrapping_sub(j << (FRAC + 5));
        let skip = (phase / ratio.max(1)).min(12);
        let ph0 = diff(first.wrapping_sub(skip * ratio), j << (FRAC + 5));
        // The centres from the entry's `skip`th on: those at its sample and after
        // (one mask instead of clearing the first `skip` one by one).
        let kept = if KEEP {
            u32::MAX.checked_shr(table.centre(ph0, skip)).unwrap_or(0)
        } else {
            0
        };
        let e = &table.entry(ph0).a;
        let x = self.window(j);
        let all = e.all & kept;
        let n = e.count.saturating_sub(skip);
        let mut acc = Acc {
            words: [0; 4],
            full: 0,
            cur: e.bits(x, slots) << skip,
            used: n,
        };
        let mut left = FRAME_BITS as u32 - n;
        // The next centre against the start of the next window.
        let mut ph = diff(
            first.wrapping_add(n.wrapping_mul(ratio)),
            j.wrapping_add(1) << (FRAC + 5),
        );
        if let (true, Some(w)) = (KEEP, centres.windows.first_mut()) {
            *w = [all, x & all];
        }
        let mut k = 1;
        // Whole windows, two per step ([`super::table::Pair`]): every centre is a
        // frame bit.
        while k < MAX_WINDOWS - 2 {
            let p = table.entry(ph);
            let (na, nb) = (p.a.count, p.b.count);
            let n = na + nb;
            if n >= left {
                break;
            }
            let x0 = self.window(j.wrapping_add(1));
            let x1 = self.window(j.wrapping_add(2));
            acc.push(p.a.bits(x0, slots) | p.b.bits(x1, slots) >> na, n);
            if let (true, Some([w0, w1])) = (KEEP, centres.windows.get_mut(k..k + 2)) {
                *w0 = [p.a.all, x0 & p.a.all];
                *w1 = [p.b.all, x1 & p.b.all];
            }
            ph = ph
                .wrapping_add(n.wrapping_mul(ratio) as i32)
                .wrapping_sub(64 << FRAC);
            left -= n;
            j = j.wrapping_add(2);
            k += 2;
        }
        // Usually at most two windows are left: one more whole window, if the next
        // one does not hold every remaining centre, then the last. A centre within
        // a phase slot of a window boundary can count in the pair's second window
        // but in the next one by the single entry's (quantised) phase, so this is a
        // loop: else the frame's last centre was dropped and read as 0 (a clean
        // line at 3.17x lost about one frame in a thousand locks that way).
        j = j.wrapping_add(1);
        let mut e = &table.entry(ph).a;
        while e.count < left && k < MAX_WINDOWS - 1 {
            let x = self.window(j);
            let n = e.count;
            acc.push(e.bits(x, slots), n);
            if let (true, Some(w)) = (KEEP, centres.windows.get_mut(k)) {
                *w = [e.all, x & e.all];
            }
            ph = ph
                .wrapping_add(n.wrapping_mul(ratio) as i32)
                .wrapping_sub(32 << FRAC);
            left -= n;
            j = j.wrapping_add(1);
            k += 1;
            e = &table.entry(ph).a;
        }
        // The last window: its first `left` centres.
        let x = self.window(j);
        let (e_all, count) = (e.all, e.count);
        acc.push(e.bits(x, slots) & all_top(left), left.min(count));
        if KEEP {
            // Those before the entry's `left`th centre's sample (all of them when
            // the window has no more than `left`).
            let all = e_all & !u32::MAX.checked_shr(table.centre(ph, left)).unwrap_or(0);
            if let Some(w) = centres.windows.get_mut(k) {
                *w = [all, x & all];
            }
        }
        centres.count = k + 1;
        let [a, b, c, _] = acc.words;
        (u128::from(a) << 96 | u128::from(b) << 64 | u128::from(c) << 32 | u128::from(acc.cur)) >> 3
    }

    /// True when this channel, `d` samples later than the reference, has the
    /// reference's value at every centre of `centres`.
    ///
    /// Channel window `k` is read as the 32 samples `d` after the reference's window
    /// `first + k`: bits `d mod 32` on of ring window `first + k + ⌊d / 32⌋`
    /// joined with the start of the window after it. The shifts of the common
    /// skews (up to 3 samples either way) are constants, so a window costs one
    /// funnel shift with an immediate (`lsl`, `orr ... lsr #`) instead of three
    /// register shifts. Inlined into the receiver's loop over the channels.
    #[inline(always)]
    pub fn agrees(&self, centres: &Centres, d: i32) -> bool {
        let windows = centres
            .windows
            .get(..centres.count)
            .unwrap_or(&centres.windows);
        let s = centres.first.wrapping_add((d >> 5) as u32);
        let bad = match d & 31 {
            0 => self.differences::<0>(windows, s, 0),
            1 => self.differences::<1>(windows, s, 1),
            2 => self.differences::<2>(windows, s, 2),
            3 => self.differences::<3>(windows, s, 3),
            29 => self.differences::<29>(windows, s, 29),
            30 => self.differences::<30>(windows, s, 30),
            31 => self.differences::<31>(windows, s, 31),
            l => self.differences::<32>(windows, s, l as u32),
        };
        bad == 0
    }

    /// The OR over `windows` of the centre samples that differ from the reference,
    /// window `k` read from ring windows `s + k` and `s + k + 1` shifted by `L`
    /// (`L` = 32: by `l`, 1..=31, not a constant).
    #[inline(always)]
    fn differences<const L: u32>(&self, windows: &[[u32; 2]], s: u32, l: u32) -> u32 {
        let t = s as usize % (RING_WORDS / 2);
        // The windows up to the ring's end, then (if the frame wraps around it) the
        // rest from its first slot: two plain slices, no index arithmetic per
        // window.
        let (head, rest) = windows
            .split_at_checked(RING_WORDS / 2 - 1 - t)
            .unwrap_or((windows, &[]));
        let here = self.windows.get(t).copied().unwrap_or(0);
        let after = self.windows.get(t + 1..).unwrap_or_default();
        let (bad, here) = Self::shifted::<L>(head, after, here, l);
        if rest.is_empty() {
            return bad;
        }
        bad | Self::shifted::<L>(rest, &self.windows, here, l).0
    }

    /// [`Ring::differences`] over one slice: window `k` from the ring window
    /// before `src[k]` (`here` for the first) and `src[k]` (`src` at least as long
    /// as `windows`, or the windows past it are not compared). Also returns the
    /// last ring window read.
    #[inline(always)]
    fn shifted<const L: u32>(windows: &[[u32; 2]], src: &[u32], here: u32, l: u32) -> (u32, u32) {
        let mut bad = 0u32;
        let mut here = here;
        for (&[m, v], &next) in windows.iter().zip(src) {
            let x = match L {
                0 => here,
                32 => here << l | next >> (32 - l),
                _ => here << L | next >> (32 - L),
            };
            bad |= (x & m) ^ v;
            here = next;
            // Keeps this a loop: unrolled, the copies' pointers were recomputed
            // from indices and spilled (11 and more instructions a window). A hint
            // only: the result does not depend on it.
            core::hint::black_box(());
        }
        (bad, here)
    }
}
