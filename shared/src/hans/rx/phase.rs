//! A precise phase and rate estimate for a young lock: a least-squares line through
//! every edge the receiver has measured since it locked, start edges and the
//! mid-pair transitions of the frames that verified.
//!
//! # Why
//! A lock fitted on start edges alone (one per frame) knows its phase to about
//! `2σ/√k` after `k` frames, σ ≈ 0.5 sample at ±25 % jitter: ~0.35 sample after
//! 8 frames, while at 3x a centre sample's margin against a ±25 % edge is 0.25 to
//! 0.75 sample depending on the sampling phase. Every complement pair (spec
//! "数据传输协议", sender item 2: each bit is followed by its complement) has an edge
//! in its middle, so a frame holds 61 edges (the start pair's and the 60 data
//! pairs') at known bit boundaries whatever the data: measuring them on a verified
//! frame gives 61 more points for the fit, and the lock is precise (a few
//! hundredths of a sample of phase, a few thousandths of a sample of period) after
//! a few frames instead of a few hundred. Once the fit holds a few frames of them
//! it takes every other pair only ([`even_mid_pairs`], [`super::timing::DENSE`]):
//! later frames mostly add lever arm for the rate, at half the cost; the last 8
//! pairs' edges then come from the tail confirmation, which measured them
//! already ([`head_mid_pairs`], [`Points::tail`]).
//!
//! # The fit in information form
//! The points are residuals against the current timing line `start + k·ratio`
//! (`k` = bit boundary index from the current frame's start edge). After each
//! update the timing is moved to the least-squares line, so the residual sums of
//! all earlier points are zero against it: only the normal-equation matrix
//! (`Σ1`, `Σk`, `Σk²`) has to be kept. A new batch of points adds its own
//! geometry and residual sums, one 2x2 solve gives the phase (at `k` = 0) and
//! slope corrections, and moving on to the next frame shifts `k` by 125. With
//! start edges only, this is the same line fit the alpha-beta filter of
//! [`super::timing`] approximates.
//!
//! # Measuring an edge
//! A pair's edge lies half a bit from both its bits' centres; with jitter and
//! phase error below half a bit it is the only edge in the bit-wide window
//! centred on its expected position. The samples in that window before the edge
//! hold the pair's first bit: their count puts the edge between the last of them
//! and the next sample, half a sample after the last (the convention of
//! [`super::ring::Ring::first_fall`]). An edge outside the window saturates at its
//! border, so one glitch moves a frame's sum by at most half a bit.

use super::confirm::TAIL_PAIRS;
use super::ring::{Ring, FRAC, HALF};
use crate::hans::FRAME_BITS;

/// Pairs per frame: the start pair and 3 x 20 data pairs.
pub(super) const PAIRS: u32 = 61;
/// Bits per frame, the shift of the bit index from one frame to the next.
const BITS: i64 = FRAME_BITS as i64;

/// Points of a line fit: count, bit indices, and the residuals (Q16 samples)
/// against the current timing line.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Points {
    /// Number of points.
    n: i64,
    /// Sum of the bit indices.
    k: i64,
    /// Sum of their squares.
    kk: i64,
    /// Sum of the residuals.
    r: i64,
    /// Sum of index times residual.
    kr: i64,
}

impl Points {
    /// The same points with bit indices counted from the next frame's start edge
    /// (a frame later): the frame a new lock was measured over, whose own start
    /// edge is the lock's earlier one.
    pub fn frame_before(&self) -> Points {
        Points {
            n: self.n,
            k: self.k - BITS * self.n,
            kk: self.kk - 2 * BITS * self.k + BITS * BITS * self.n,
            r: self.r,
            kr: self.kr - BITS * self.r,
        }
    }

    /// One start edge measured `err` (Q16) after the timing's prediction of it (bit
    /// index 0 of the new frame).
    pub fn start_edge(err: i32) -> Points {
        Points {
            n: 1,
            r: i64::from(err),
            ..Points::default()
        }
    }

    /// The current frame's last [`TAIL_PAIRS`] mid-pair edges as the tail
    /// confirmation measured them, `sum` their summed deviation (Q16) from the
    /// timing ([`super::confirm::Tail`]): as many points at their mean bit index,
    /// each at their mean residual. Only their sum is known, so the fit takes
    /// the mean's phase and none of the within-tail slope (16 bits of lever arm
    /// against a young fit's frames of it).
    pub fn tail(sum: i32) -> Points {
        // Pair `i`'s edge is bit boundary `2i + 1`; the tail's pairs are the
        // last `TAIL_PAIRS` of `PAIRS`.
        const MEAN: i64 = 2 * (PAIRS - TAIL_PAIRS) as i64 + TAIL_PAIRS as i64;
        const N: i64 = TAIL_PAIRS as i64;
        let r = i64::from(sum);
        Points {
            n: N,
            k: N * MEAN,
            kk: N * MEAN * MEAN,
            r,
            kr: MEAN * r,
        }
    }

    /// These points and `other` together (residuals against the same line,
    /// bit indices from the same start edge).
    pub fn and(&self, other: &Points) -> Points {
        Points {
            n: self.n + other.n,
            k: self.k + other.k,
            kk: self.kk + other.kk,
            r: self.r + other.r,
            kr: self.kr + other.kr,
        }
    }
}

/// The 61 mid-pair edges of the frame that starts at `start` (Q16, the channel's
/// own start edge) with `ratio` (Q16) samples per bit, on `ring`, as residuals
/// against that line; `pattern` is that frame's verified pattern (first bit at
/// bit 124), which says which level comes before each edge. (The level must come
/// from the verified pattern: a window's own first sample can already lie after
/// an edge jittered early, and then reads a late edge; and an unverified frame's
/// centres, or a young lock's drifting tail, misplace points.)
///
/// The residual of pair `i` is `edge_i - at_i` with `edge_i = c_i·2^16 - HALF`
/// (`c_i` the sample count of the edge) and `at_i = at_0 + i·2·ratio`, all
/// modulo 2^32. The sums are taken modulo 2^32 too (they fit i32, see below), so
/// they split exactly into `Σc_i` and `Σk_i·c_i`, which is all the loop keeps,
/// and the sums of the `at_i` and `HALF` terms, closed forms of `at_0` and the
/// step: a short loop whose state stays in registers (~30 instructions an edge
/// on the M7, where the per-edge residuals, unrolled, took ~67).
pub fn mid_pairs(ring: &Ring, start: u32, ratio: i32, pattern: u128) -> Points {
    let mut edges = PairEdges::new(start, ratio, 0);
    // The pairs' first bits, left-aligned: the line's first bit at bit 127.
    let p = pattern << 3;
    let words = [
        ((p >> 96) as u32, 16u32),
        ((p >> 64) as u32, 16),
        ((p >> 32) as u32, 16),
        (p as u32, PAIRS - 48),
    ];
    // Σc_i and Σk_i·c_i, modulo 2^32.
    let (mut c_sum, mut kc_sum) = (0u32, 0u32);
    let mut k = 1u32;
    for (w, count) in words {
        let mut bits = w;
        for _ in 0..count {
            let c = edges.count(ring, bits);
            c_sum = c_sum.wrapping_add(c);
            kc_sum = kc_sum.wrapping_add(k.wrapping_mul(c));
            k += 2;
            bits <<= 2;
            // Keeps this a loop: LLVM unrolls loops for M-class cores, and the
            // unrolled copies kept each copy's positions live and spilled them
            // (30 instructions an edge as a loop, 35 to 37 unrolled). A hint only:
            // the result does not depend on it.
            core::hint::black_box(());
        }
    }
    Geometry::of(1, PAIRS).points(start, ratio, edges.step, c_sum, kc_sum)
}

/// [`mid_pairs`] on the even pairs only (0, 2, ... 60: 31 edges spread evenly
/// over the frame, its first pair and its last), at half the cost: the young
/// lock's fit once it holds a few frames' edges ([`super::timing`]).
///
/// One loop over the 31 pairs, their first bits gathered into one word first
/// (the pattern's bits 124, 120, ... 4): ~27 instructions an edge on the M7, ~930
/// a frame. As four loops of eight pairs over the pattern's words, like
/// [`mid_pairs`], LLVM unrolled them and spilled (~1 030), and with the trip
/// counts hidden from it the per-word set-up cost as much.
pub fn even_mid_pairs(ring: &Ring, start: u32, ratio: i32, pattern: u128) -> Points {
    even_pairs(ring, start, ratio, pattern, 31)
}

/// [`even_mid_pairs`] before the tail's pairs ([`TAIL_PAIRS`], pairs 53 to 60):
/// the 27 pairs 0, 2, ... 52. With [`Points::tail`] of the same frame (the
/// tail confirmation measured those 8 edges already) they are 35 points of the
/// young fit for 27 edges ([`super::timing`]).
pub fn head_mid_pairs(ring: &Ring, start: u32, ratio: i32, pattern: u128) -> Points {
    even_pairs(
        ring,
        start,
        ratio,
        pattern,
        (PAIRS - TAIL_PAIRS - 1) / 2 + 1,
    )
}

/// The `n` even pairs 0, 2, ... `2n - 2` (`n` at most 31, a constant at every
/// call). One loop over them, their first bits gathered into one word first
/// (the pattern's bits 124, 120, ... 4).
#[inline(always)]
fn even_pairs(ring: &Ring, start: u32, ratio: i32, pattern: u128, n: u32) -> Points {
    let mut edges = PairEdges::new(start, ratio, 0).every(2);
    // Bit 31 - j: the first bit of pair 2j, pattern bit 124 - 4j.
    let bits = [
        (pattern >> 96) as u32,
        (pattern >> 64) as u32,
        (pattern >> 32) as u32,
        pattern as u32,
    ]
    .into_iter()
    .fold(0u32, |acc, w| acc << 8 | every_fourth(w));
    let (mut c_sum, mut kc_sum) = (0u32, 0u32);
    let (mut k, mut bits) = (1u32, bits);
    for _ in 0..n {
        let c = edges.count(ring, bits);
        c_sum = c_sum.wrapping_add(c);
        kc_sum = kc_sum.wrapping_add(k.wrapping_mul(c));
        k += 4;
        bits <<= 1;
        // As in `mid_pairs`: keeps this a loop.
        core::hint::black_box(());
    }
    Geometry::of(2, n).points(start, ratio, edges.step, c_sum, kc_sum)
}

/// Bits 28, 24, ... 0 of `w` as bits 7, 6, ... 0: the odd ones of each byte
/// moved next to the even one (bits 8b + 1 and 8b), then the four two-bit groups
/// gathered by one multiply (group b shifted by 24 - 6b; the other partial
/// products land below bit 24 without overlapping, or above bit 31).
#[inline(always)]
fn every_fourth(w: u32) -> u32 {
    let x = w & 0x1111_1111;
    let x = (x | x >> 3) & 0x0303_0303;
    x.wrapping_mul(1 << 24 | 1 << 18 | 1 << 12 | 1 << 6) >> 24
}

/// The pairs 0, `stride`, 2·`stride`, ... that a frame's fit takes (pair `s·j`
/// with bit index `k_j = 2·s·j + 1` for `j` = 0..`n`): the sums of their
/// geometry and of their expected edges' positions.
struct Geometry {
    /// Pairs taken.
    n: u32,
    /// Σj.
    j: u32,
    /// Σk_j.
    k: u32,
    /// Σk_j².
    kk: u32,
    /// Σj·k_j.
    jk: u32,
}

impl Geometry {
    /// `n` pairs, every `stride`th; all 61 at 1: Σk_j = 3 721, Σj = 1 830,
    /// Σj·k_j = 2·Σj² + Σj = 149 450.
    const fn of(stride: u32, n: u32) -> Geometry {
        // Σj and Σj² for j = 0..n.
        let j = n * (n - 1) / 2;
        let jj = (n - 1) * n * (2 * n - 1) / 6;
        let s = 2 * stride;
        Geometry {
            n,
            j,
            k: s * j + n,
            kk: s * s * jj + 2 * s * j + n,
            jk: s * jj + j,
        }
    }

    /// The points of these pairs of the frame at `start` with `ratio`, whose
    /// edges' sample counts sum to `c_sum` and, weighted by their bit indices, to
    /// `kc_sum` (modulo 2^32), the windows moving on by `step` a pair taken.
    /// Σ(edge_j - at_j) and Σk_j·(edge_j - at_j) with `at_j = at_0 + j·step`.
    #[inline(always)]
    fn points(&self, start: u32, ratio: i32, step: u32, c_sum: u32, kc_sum: u32) -> Points {
        // Edge of pair 0 (bit boundary 1).
        let at0 = start.wrapping_add(ratio as u32);
        let r_sum = (c_sum << FRAC)
            .wrapping_sub(self.n.wrapping_mul(HALF))
            .wrapping_sub(self.n.wrapping_mul(at0))
            .wrapping_sub(self.j.wrapping_mul(step));
        let kr_sum = (kc_sum << FRAC)
            .wrapping_sub(self.k.wrapping_mul(HALF))
            .wrapping_sub(self.k.wrapping_mul(at0))
            .wrapping_sub(self.jk.wrapping_mul(step));
        // A residual lies within half a bit and a sample of its edge (< 2^18 for
        // any ratio up to 4.2), so the sums fit i32: 61 * 2^18 and 3 721 * 2^18 <
        // 2^31 (and for any other input they are what the wrapping per-point sums
        // were).
        Points {
            n: i64::from(self.n),
            k: i64::from(self.k),
            kk: i64::from(self.kk),
            r: i64::from(r_sum as i32),
            kr: i64::from(kr_sum as i32),
        }
    }
}

/// Measures a frame's mid-pair edges one pair after the other (the module docs,
/// "Measuring an edge"): shared by the young lock's fit ([`mid_pairs`]) and the
/// tail confirmation ([`super::confirm`]). Register-only state, inlined into the
/// callers' loops.
#[derive(Clone, Copy, Debug)]
pub(super) struct PairEdges {
    /// The next pair's window: the samples from `at - ratio/2` (rounded up) to
    /// before `at + ratio/2`, both bounds kept rounded-up-to-be (`+ 2^16 - 1`) so
    /// a shift gives the sample.
    lo_q: u32,
    hi_q: u32,
    /// Two bits (Q16): from one pair's edge to the next.
    step: u32,
}

impl PairEdges {
    /// The edges of pairs `first`, `first + 1`, ... of the frame whose start edge
    /// is at `start` (Q16, the channel's own) with `ratio` (Q16) samples per bit:
    /// pair `i`'s edge is expected at bit boundary `2i + 1`, its window is the bit
    /// time centred there.
    #[inline(always)]
    pub(super) fn new(start: u32, ratio: i32, first: u32) -> PairEdges {
        let ratio = ratio as u32;
        let half = ratio / 2;
        let step = ratio.wrapping_mul(2);
        let at = start
            .wrapping_add(ratio)
            .wrapping_add(first.wrapping_mul(step));
        let round = (1 << FRAC) - 1;
        PairEdges {
            lo_q: at.wrapping_sub(half).wrapping_add(round),
            hi_q: at.wrapping_add(half).wrapping_add(round),
            step,
        }
    }

    /// The same, moving on `stride` pairs at a time (pairs `first`, `first +
    /// stride`, ...).
    #[inline(always)]
    fn every(self, stride: u32) -> PairEdges {
        PairEdges {
            step: self.step.wrapping_mul(stride),
            ..self
        }
    }

    /// The next pair's edge as a sample count `c` (the edge lies half a sample
    /// before sample `c`): its window's samples at the pair's first level, which
    /// is bit 31 of `bits`, counted from the window's start (an edge outside the
    /// window saturates at its border); then moves on to the pair after it.
    #[inline(always)]
    pub(super) fn count(&mut self, ring: &Ring, bits: u32) -> u32 {
        let lo = self.lo_q >> FRAC;
        let n = (self.hi_q >> FRAC).wrapping_sub(lo) & 0xFFFF;
        self.hi_q = self.hi_q.wrapping_add(self.step);
        lo.wrapping_add(self.run(ring, bits).min(n))
    }

    /// [`PairEdges::count`] without the window's end: the samples at the first
    /// level from the window's start up to the next level change, however far (at
    /// most 32). The same count for an edge inside the window, and a larger one
    /// for an edge beyond it: a check that wants edges near their place (the
    /// tail confirmation) needs no saturation, and skips its per-edge cost.
    #[inline(always)]
    pub(super) fn count_on(&mut self, ring: &Ring, bits: u32) -> u32 {
        let lo = self.lo_q >> FRAC;
        lo.wrapping_add(self.run(ring, bits))
    }

    /// The samples at the level of bit 31 of `bits` from the next window's start
    /// (at most 32); moves the window's start on to the next pair.
    #[inline(always)]
    fn run(&mut self, ring: &Ring, bits: u32) -> u32 {
        let lo = self.lo_q >> FRAC;
        // Window `lo >> 5` and the next (`window` takes them modulo the ring).
        let (j, s) = (lo >> 5, lo & 31);
        let next = self.lo_q.wrapping_add(1 << (FRAC + 5)) >> (FRAC + 5);
        let x = ring.window(j) << s | (ring.window(next) >> 1) >> (31 - s);
        // Samples at the pair's first level, counted from the window's start.
        let first = 0u32.wrapping_sub(bits >> 31);
        self.lo_q = self.lo_q.wrapping_add(self.step);
        (x ^ first).leading_zeros()
    }
}

/// The normal-equation matrix of the fit (see the module docs), bit indices from
/// the current frame's start edge.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Fit {
    n: i64,
    k: i64,
    kk: i64,
}

/// A correction of the timing line: phase at the current start edge and frame
/// period, both Q16 samples.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Correction {
    /// Add to the current frame's start edge.
    pub start: i32,
    /// Add to the frame period.
    pub period: i32,
}

impl Fit {
    /// The fit of a new lock: two start edges one frame apart, the later one the
    /// current frame's (the line through them is the lock's timing).
    pub const fn lock() -> Fit {
        Fit {
            n: 2,
            k: -BITS,
            kk: BITS * BITS,
        }
    }

    /// The fit of a settled lock that has just coasted across skipped input
    /// ([`super::gap`]): `edges` start edges, one per frame, the latest `back`
    /// frames before the current one (every residual zero: the timing is their
    /// line). Weighs what the alpha-beta filter knows (it approximates the line
    /// fit of its last `edges` start edges) against the points measured after the
    /// gap, so the first verified frames' mid-pair edges move the phase most and
    /// the rate by their lever arm across the gap.
    pub fn prior(edges: u32, back: u32) -> Fit {
        // Σj and Σj² for j = back .. back + edges - 1, from the sums from 0.
        let sq = |m: i64| m * (m + 1) * (2 * m + 1) / 6;
        let (n, b) = (i64::from(edges), i64::from(back));
        let sum = n * b + n * (n - 1) / 2;
        let squares = sq(b + n - 1) - sq(b - 1);
        Fit {
            n,
            k: -BITS * sum,
            kk: BITS * BITS * squares,
        }
    }

    /// Points in the fit.
    pub fn points(&self) -> i64 {
        self.n
    }

    /// Moves the origin to the next frame's start edge: every point is a frame
    /// further back.
    pub fn next_frame(&mut self) {
        self.kk += BITS * (BITS * self.n - 2 * self.k);
        self.k -= BITS * self.n;
    }

    /// Adds `p` (residuals against the current line) and returns the correction
    /// that moves the line to the least-squares fit of every point so far. No
    /// correction when the points do not determine a line.
    pub fn add(&mut self, p: &Points) -> Correction {
        self.n += p.n;
        self.k += p.k;
        self.kk += p.kk;
        let det = self.n * self.kk - self.k * self.k;
        if det <= 0 {
            return Correction::default();
        }
        // The sums stay far inside i64 over a young lock (`timing::YOUNG` frames of
        // at most 62 points): n < 2^12, |Σk| < 2^24, Σk² < 2^36, |Σr| < 2^24,
        // |Σkr| < 2^30, so each product is below 2^61. A `prior` of up to 128
        // edges reaching 256 frames back adds n < 2^8, |Σk| < 2^22, Σk² < 2^37
        // (a few frames of points after it: |Σr| < 2^20), still below 2^61.
        let det = Divisor::new(det.unsigned_abs());
        let start = det.quotient(self.kk * p.r - self.k * p.kr);
        let period = det.quotient(BITS * (self.n * p.kr - self.k * p.r));
        Correction {
            start: clamp(start),
            period: clamp(period),
        }
    }
}

/// A divisor prepared for [`Divisor::quotient`]: [`Fit::add`] divides twice
/// by its determinant.
///
/// Dividing by the divisor's top 16 bits, rounded up, takes one 32-bit hardware
/// division when the quotient is below about 2^16 (a young fit's are: its
/// determinant is ~2^40, its corrections a fraction of a sample, ~2^15). With
/// `s` the shift that leaves those bits, `t = a >> s` below 2^32 and
/// `dh = (d >> s) + 1`, the estimate `q = t / dh` satisfies
/// `q·d < q·dh·2^s ≤ t·2^s ≤ a`, so it never exceeds the quotient, and falls
/// short of it by less than `1 + (t + dh) / (dh·(dh - 1)) < 6`
/// (`a/d < (t + 1)/(dh - 1)`, `dh > 2^15`): a few subtractions finish it. A
/// quotient below 2^16 always takes this path (`a < 2^16·d < 2^(s + 32)`).
/// Otherwise the library's 64-bit division (~70 instructions on the M7, ~90
/// signed). Exact on every input either way (`tests::quotient_is_division`).
#[derive(Clone, Copy, Debug)]
struct Divisor {
    /// The divisor.
    d: u64,
    /// Shift that leaves its top 16 bits (0 for a divisor below 2^16).
    s: u32,
    /// Its top 16 bits, plus 1 when `s` is above 0 (rounded up; at most 2^16).
    dh: u32,
}

impl Divisor {
    /// `d` prepared; `d` 0 gives quotients 0 (never used: [`Fit::add`] divides
    /// by a positive determinant).
    fn new(d: u64) -> Divisor {
        let s = (u64::BITS - d.leading_zeros()).saturating_sub(16);
        let top = d >> s;
        // `top` is below 2^16.
        let dh = if s == 0 { top } else { top + 1 } as u32;
        Divisor { d, s, dh }
    }

    /// `n / d` (rounded towards zero, as `/`), on the magnitudes: on the M7 the
    /// signed 64-bit division's library path (`__aeabi_ldivmod`,
    /// `__divmoddi4`) cost ~43 instructions a division around the ~47 of the
    /// unsigned one it calls.
    #[inline(always)]
    fn quotient(&self, n: i64) -> i64 {
        let q = self.unsigned(n.unsigned_abs()) as i64;
        // `q` is 2^63 (as `i64::MIN`) only for `i64::MIN / 1`: negated, itself.
        if n < 0 {
            q.wrapping_neg()
        } else {
            q
        }
    }

    /// `a / d` (0 for `d` 0).
    #[inline(always)]
    fn unsigned(&self, a: u64) -> u64 {
        // The library's division: a quotient from ~2^16 on, and `d` 0.
        let slow = || a.checked_div(self.d).unwrap_or(0);
        let Ok(t) = u32::try_from(a >> self.s) else {
            return slow();
        };
        let Some(q) = t.checked_div(self.dh) else {
            return slow();
        };
        let mut q = u64::from(q);
        if self.s == 0 {
            // The divisor is exact.
            return q;
        }
        // Never short (`q·d ≤ a`, the type docs); kept total all the same.
        let Some(mut r) = a.checked_sub(q.wrapping_mul(self.d)) else {
            return slow();
        };
        while r >= self.d {
            q += 1;
            r -= self.d;
        }
        q
    }
}

/// `v` saturated to `i32`.
fn clamp(v: i64) -> i32 {
    i32::try_from(v).unwrap_or(if v < 0 { i32::MIN } else { i32::MAX })
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::hans::Frame;
    use proptest::prelude::*;

    const Q: f64 = 65536.0;

    /// The per-edge implementation `mid_pairs` replaced (before the sums were split
    /// into sample counts and closed forms), on every `stride`th pair below pair
    /// `pairs`: it must give the same points.
    fn mid_pairs_reference(
        ring: &Ring,
        start: u32,
        ratio: i32,
        pattern: u128,
        (stride, pairs): (u32, u32),
    ) -> Points {
        let ratio = ratio as u32;
        let half = ratio / 2;
        // A residual lies within half a bit and a sample of its edge (< 2^18 for any
        // ratio up to 4.2), so the sums fit i32: 61 * 2^18 and 3 721 * 2^18 < 2^31.
        let (mut r_sum, mut kr_sum) = (0i32, 0i32);
        let (mut n, mut k_sum, mut kk_sum) = (0i64, 0i64, 0i64);
        for i in (0..pairs).step_by(stride as usize) {
            // Edge of pair i (bit boundary 2i + 1), its first bit at line bit 2i.
            let k = 2 * i + 1;
            let at = start.wrapping_add(ratio.wrapping_mul(k));
            let level = (pattern >> (124 - 2 * i)) & 1 == 1;
            // Window: the samples from `at - half` (rounded up) to before `at + half`.
            let lo = at.wrapping_sub(half).wrapping_add((1 << FRAC) - 1) >> FRAC;
            let hi = at.wrapping_add(half).wrapping_add((1 << FRAC) - 1) >> FRAC;
            let width = hi.wrapping_sub(lo) & 0xFFFF;
            let (j, s) = (lo >> 5, lo & 31);
            let x = ring.window(j) << s | (ring.window(j.wrapping_add(1)) >> 1) >> (31 - s);
            // Samples at the pair's first level, counted from the window's start.
            let first = if level { u32::MAX } else { 0 };
            let before = (x ^ first).leading_zeros().min(width);
            let edge = (lo.wrapping_add(before) << FRAC).wrapping_sub(HALF);
            let r = edge.wrapping_sub(at) as i32;
            r_sum = r_sum.wrapping_add(r);
            kr_sum = kr_sum.wrapping_add((k as i32).wrapping_mul(r));
            n += 1;
            k_sum += i64::from(k);
            kk_sum += i64::from(k * k);
        }
        Points {
            n,
            k: k_sum,
            kk: kk_sum,
            r: i64::from(r_sum),
            kr: i64::from(kr_sum),
        }
    }

    /// Samples of a line that idles high, then sends `pattern` from `t0` (samples)
    /// at `ratio` samples per bit, each bit boundary `k` moved by `jitter(k)`
    /// samples; the words are written to a ring from stream word 0.
    fn ring_of(pattern: u128, t0: f64, ratio: f64, jitter: impl Fn(usize) -> f64) -> Ring {
        ring_of_edges(pattern, |k| t0 + k as f64 * ratio + jitter(k))
    }

    /// Samples of a line that idles high, then sends `pattern` with bit boundary
    /// `k` at `edge(k)` (samples, increasing), written to a ring from stream word
    /// 0 (also `confirm`'s tests).
    pub(in crate::hans::rx) fn ring_of_edges(pattern: u128, edge: impl Fn(usize) -> f64) -> Ring {
        let bits: Vec<bool> = (0..125).rev().map(|i| (pattern >> i) & 1 == 1).collect();
        let level = |t: f64| {
            if t < edge(0) || t >= edge(125) {
                return true;
            }
            let b = (0..125).rfind(|&b| t >= edge(b)).unwrap_or(0);
            bits[b]
        };
        let words: Vec<u16> = (0..64)
            .map(|w| {
                (0..16).fold(0u16, |acc, i| {
                    acc << 1 | u16::from(level(f64::from(w * 16 + i)))
                })
            })
            .collect();
        let mut ring = Ring::default();
        ring.write(0, &words);
        ring
    }

    fn q(v: f64) -> i32 {
        (v * Q).round() as i32
    }

    fn pattern() -> u128 {
        Frame::new(0x5A3C1, 0xF0F0F, 0x12345).unwrap().encode()
    }

    #[test]
    fn exact_line_has_no_residual() {
        // Edges exactly where the timing puts them, at a whole-sample ratio with the
        // edges half a sample before a sample (the measurement convention).
        let ring = ring_of(pattern(), 20.5, 4.0, |_| 0.0);
        let p = mid_pairs(&ring, q(20.5) as u32, q(4.0), pattern());
        assert_eq!((p.n, p.r, p.kr), (61, 0, 0));
        assert_eq!(p.k, (0..61).map(|i| 2 * i + 1).sum::<i64>());
    }

    #[test]
    fn phase_and_rate_errors_are_measured() {
        // The timing believes start 20.0, 3.2 samples per bit; the line starts at
        // 20.4 and runs at 3.205 (1 sample late at the last pair). One frame's 61
        // edges on their own give the line back to within the quantisation.
        let (t0, ratio) = (20.4, 3.205);
        let ring = ring_of(pattern(), t0, ratio, |_| 0.0);
        let p = mid_pairs(&ring, q(20.0) as u32, q(3.2), pattern());
        let c = Fit::default().add(&p);
        let start = f64::from(c.start) / Q;
        let period = f64::from(c.period) / Q;
        assert!((start - 0.4).abs() < 0.1, "start {start}");
        assert!((period - 0.625).abs() < 0.1, "period {period}");
    }

    #[test]
    fn jittered_edges_average_out() {
        // ±25 % of a bit of jitter (deterministic pseudo-random) at 3x: a single
        // frame's estimate is within a small part of a sample, where one start edge
        // is off by up to 0.75 + 0.5 samples.
        let mut x = 0x2545_F491u32;
        let jit: Vec<f64> = (0..=125)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                (f64::from(x) / f64::from(u32::MAX) - 0.5) * 1.5
            })
            .collect();
        for (t0, off) in [(30.0, 0.0), (30.37, 0.2), (29.9, -0.3)] {
            let ring = ring_of(pattern(), t0, 3.0, |k| jit[k]);
            let p = mid_pairs(&ring, q(t0 - off) as u32, q(3.0), pattern());
            let mut fit = Fit::lock();
            let c = fit.add(&p);
            let got = f64::from(c.start) / Q;
            assert!((got - off).abs() < 0.2, "t0 {t0}: {got} vs {off}");
        }
    }

    #[test]
    fn start_edges_alone_fit_a_line() {
        // The lock measured its period (375) over edges at -375 and 0; the line then
        // runs at 375.5 per frame. After each new edge the timing must be the
        // least-squares line through all edges so far (computed here in f64).
        let mut fit = Fit::lock();
        let (mut start, mut period) = (0.0f64, 375.0f64);
        let mut xs = vec![-1.0, 0.0];
        let mut ys = vec![-375.0, 0.0];
        for n in 1..=6 {
            fit.next_frame();
            let truth = 375.5 * f64::from(n) + if n % 2 == 0 { 0.3 } else { -0.3 };
            let pred = start + period;
            let c = fit.add(&Points::start_edge(q(truth - pred)));
            start = pred + f64::from(c.start) / Q;
            period += f64::from(c.period) / Q;
            xs.push(f64::from(n));
            ys.push(truth);
            let m = xs.len() as f64;
            let (sx, sy) = (xs.iter().sum::<f64>(), ys.iter().sum::<f64>());
            let sxx = xs.iter().map(|x| x * x).sum::<f64>();
            let sxy = xs.iter().zip(&ys).map(|(x, y)| x * y).sum::<f64>();
            let slope = (m * sxy - sx * sy) / (m * sxx - sx * sx);
            let at_n = (sy - slope * sx) / m + slope * f64::from(n);
            assert!(
                (period - slope).abs() < 0.002,
                "{n}: period {period} vs {slope}"
            );
            assert!((start - at_n).abs() < 0.002, "{n}: start {start} vs {at_n}");
        }
    }

    #[test]
    fn garbage_never_panics_and_stays_bounded() {
        let mut ring = Ring::default();
        let words: Vec<u16> = (0..64u16).map(|w| w.wrapping_mul(0x9E37)).collect();
        ring.write(0, &words);
        for s in (0..800u32).step_by(7) {
            let p = mid_pairs(&ring, (s << FRAC).wrapping_add(12_345), q(3.7), u128::MAX);
            // Every residual is within half a bit plus a sample of its edge.
            assert!(p.r.abs() <= 61 * i64::from(q(2.9)), "{p:?}");
            let mut fit = Fit::lock();
            let c = fit.add(&p);
            assert!(c.start.abs() < q(4.0) && c.period.abs() < q(500.0), "{c:?}");
        }
        // A fit without points corrects nothing.
        assert_eq!(
            Fit::default().add(&Points::default()),
            Correction::default()
        );
    }

    /// Every pair ([`mid_pairs`]), every other one ([`even_mid_pairs`]), and
    /// every other one before the tail ([`head_mid_pairs`]): stride and the
    /// pairs below which they are taken.
    const STRIDES: [(u32, u32); 3] = [(1, PAIRS), (2, PAIRS), (2, PAIRS - TAIL_PAIRS)];

    /// The function that takes the pairs of `which` (one of [`STRIDES`]).
    fn strided(which: (u32, u32), ring: &Ring, start: u32, ratio: i32, pattern: u128) -> Points {
        match which {
            (1, _) => mid_pairs(ring, start, ratio, pattern),
            (2, PAIRS) => even_mid_pairs(ring, start, ratio, pattern),
            _ => head_mid_pairs(ring, start, ratio, pattern),
        }
    }

    #[test]
    fn the_tail_counts_as_its_pairs_at_their_mean() {
        // Every edge 0.3 sample after the timing's at a whole-sample ratio: each
        // of the tail's pairs has the same residual, so its points are the pairs' own
        // but for Σk² (all at the mean bit index: no within-tail slope).
        let ring = ring_of(pattern(), 20.3, 3.0, |_| 0.0);
        let start = q(20.0) as u32;
        let Some(tail) = super::super::confirm::tail(&ring, start, q(3.0), pattern()) else {
            panic!("tail failed");
        };
        let points = Points::tail(tail.sum);
        let all = mid_pairs_reference(&ring, start, q(3.0), pattern(), (1, PAIRS));
        let head = mid_pairs_reference(&ring, start, q(3.0), pattern(), (1, PAIRS - TAIL_PAIRS));
        assert_eq!(points.n, all.n - head.n);
        assert_eq!(points.k, all.k - head.k);
        assert_eq!(points.r, all.r - head.r);
        assert_eq!(points.kr, all.kr - head.kr);
        // Edges at 20.3 + 3k read as 20.5 + 3k (half a sample before the first
        // sample after them), against a timing at 20 + 3k.
        assert_eq!(points.r, 8 * i64::from(HALF));
        assert!(points.kk < all.kk - head.kk);
    }

    /// A ring holding `words` from stream word 0.
    fn ring_with(words: &[u16]) -> Ring {
        let mut ring = Ring::default();
        ring.write(0, words);
        ring
    }

    /// `Divisor::quotient` against the signed division it replaces, in `i128`
    /// (where `i64::MIN / 1` does not overflow).
    fn divided(n: i64, d: u64) -> i64 {
        let q = i128::from(n) / i128::from(d);
        i64::try_from(q).unwrap_or(i64::MIN)
    }

    #[test]
    fn quotient_is_division_at_the_extremes() {
        let quotient = |n, d| Divisor::new(d).quotient(n);
        let ns = [
            0,
            1,
            -1,
            2,
            -2,
            i64::MAX,
            i64::MIN,
            i64::MIN + 1,
            1 << 32,
            -(1 << 32),
        ];
        let ds = [
            1,
            2,
            3,
            1 << 32,
            (1 << 32) - 1,
            1 << 63,
            (1 << 63) + 1,
            u64::MAX,
        ];
        for n in ns {
            for d in ds {
                assert_eq!(quotient(n, d), divided(n, d), "{n} / {d}");
            }
            // Documented, never used: no panic.
            assert_eq!(quotient(n, 0), 0);
        }
        assert_eq!(quotient(i64::MIN, 1), i64::MIN);
        assert_eq!(quotient(-7, 2), -3);
    }

    proptest! {
        /// Any numerator and positive divisor, and the fit's own: divisors a
        /// few points' determinant (< 2^32) to a young lock's (< 2^50).
        #[test]
        fn quotient_is_division(
            n in prop_oneof![any::<i64>(), -(1i64 << 61)..1 << 61, -(1i64 << 40)..1 << 40],
            d in prop_oneof![1..=u64::MAX, 1u64..1 << 32, 1u64..1 << 50],
        ) {
            prop_assert_eq!(Divisor::new(d).quotient(n), divided(n, d));
        }

        /// Quotients around the fast path's limits (2^16 and the divisor's 16
        /// top bits: `dh` 2^15 + 1 to 2^16), where its estimate falls shortest.
        #[test]
        fn quotient_is_division_near_the_fast_paths_limits(
            d in prop_oneof![1u64 << 15..1 << 17, 1u64 << 32..1 << 34, 1u64 << 46..1 << 49,
                (16u32..49).prop_map(|b| (1u64 << b) - 1), (16u32..49).prop_map(|b| 1u64 << b)],
            q in prop_oneof![0u64..1 << 18, (1u64 << 15)..(1 << 17) + 64],
            r in any::<u64>(),
            negative in any::<bool>(),
        ) {
            // `q·d + r` with `r` below `d`, as far as `i64` reaches.
            let a = q.saturating_mul(d).saturating_add(r % d).min(i64::MAX as u64) as i64;
            let n = if negative { -a } else { a };
            prop_assert_eq!(Divisor::new(d).quotient(n), divided(n, d));
        }

        /// Any ratio, half of the cases within the line's 2.85..4.2 samples a bit.
        #[test]
        fn same_points_as_reference_on_any_input(
            words in prop::collection::vec(any::<u16>(), 64),
            start in any::<u32>(),
            ratio in prop_oneof![any::<i32>(), q(2.85)..=q(4.2)],
            pattern in any::<u128>(),
        ) {
            let ring = ring_with(&words);
            for stride in STRIDES {
                prop_assert_eq!(
                    strided(stride, &ring, start, ratio, pattern),
                    mid_pairs_reference(&ring, start, ratio, pattern, stride)
                );
            }
        }

        #[test]
        fn same_points_as_reference_on_real_frames(
            data in (0u32..1 << 20, 0u32..1 << 20, 0u32..1 << 20),
            t0 in 1.0f64..400.0,
            ratio in 2.85f64..4.2,
            off in -1.5f64..1.5,
            rate in -0.02f64..0.02,
        ) {
            let Ok(frame) = Frame::new(data.0, data.1, data.2) else {
                return Err(TestCaseError::fail("frame"));
            };
            let pattern = frame.encode();
            let ring = ring_of(pattern, t0, ratio, |_| 0.0);
            let (start, ratio) = (q(t0 + off) as u32, q(ratio * (1.0 + rate)));
            for stride in STRIDES {
                prop_assert_eq!(
                    strided(stride, &ring, start, ratio, pattern),
                    mid_pairs_reference(&ring, start, ratio, pattern, stride)
                );
            }
        }
    }

    #[test]
    fn same_points_as_reference_across_ring_and_position_wraps() {
        // Windows across the ring's end (sample 1 024 = window 0 again) and
        // positions across 2^32 (sample 65 535 to 0), at the ratio range's ends.
        let words: Vec<u16> = (0..64u16)
            .map(|w| w.wrapping_mul(0x9E37) ^ 0x5A5A)
            .collect();
        let ring = ring_with(&words);
        for ratio in [q(2.85), q(3.0), q(3.7), q(4.0), q(4.2)] {
            for base in [0u32, 1_024 - 300, 1_024 - 40, 65_536 - 300, 65_536 - 5] {
                for frac in [0u32, 1, 0x7FFF, 0x8000, 0xFFFF] {
                    let start = (base << FRAC).wrapping_add(frac);
                    for (pattern, stride) in [0, u128::MAX, pattern(), !pattern()]
                        .into_iter()
                        .flat_map(|p| STRIDES.map(|s| (p, s)))
                    {
                        assert_eq!(
                            strided(stride, &ring, start, ratio, pattern),
                            mid_pairs_reference(&ring, start, ratio, pattern, stride),
                            "start {start:#x} ratio {ratio:#x} pairs {stride:?}"
                        );
                    }
                }
            }
        }
    }
}
