//! Confirmation of a frame's tail on its last mid-pair edges, before the frame is
//! published ([`super::HansRx`]'s `confirmed`, with the start-edge windows).
//!
//! # Why
//! A frame is read at the bit centres its timing puts 0.5 to 124.5 bits after its
//! start edge. The start-edge confirmation checks that timing at two single edges:
//! the frame's own and its successor's, each within 3/8 of a bit. A tail read a
//! third of a bit or more off (the phase drifted, or jumped, within the frame)
//! still passes there when the successor's edge is jittered towards the
//! prediction, and its centres then lie near bit boundaries: random content whose
//! complement pairs pass at 2^-n. Small changes to the tracking made the HANS
//! campaign forward 13 to 14 such frames in 250 000 (README "Known limits", docs/engineering-log.md).
//!
//! Every complement pair changes level in its middle (spec "数据传输协议", sender
//! item 2), so the last [`TAIL_PAIRS`] pairs give that many edges at known bit
//! boundaries whatever the data, in the part of the frame where a rate error has
//! moved the phase furthest. They are measured as the young lock's fit measures
//! them (`phase::PairEdges`: from the start of the bit time centred on the
//! boundary, the level before the edge taken from the pattern as read; not
//! saturated at the window's end, which only makes an edge further off count
//! further off, and saves the bound per edge) and two means of
//! their deviations from where the timing puts them are bounded: the **mean
//! deviation** within [`tail_window`], a quarter bit (a phase error), and the
//! **mean size** of the deviations within 3/8 bit (pairs read with the wrong
//! level, or a tail read partly one bit late and partly right, whose deviations
//! have both signs and cancel in the mean).
//!
//! # Why means, and why a quarter bit
//! A single edge of a good line already lies up to its jitter (a quarter bit at
//! ±25 %) plus the half-sample measurement step (a sixth of a bit at 3x) off, so
//! any per-edge bound that sees a quarter-bit phase error would reject clean
//! frames. The mean of 8 edges has its jitter (σ about 0.17 bit a single edge at
//! ±25 % and 3x, uniform jitter and quantisation) down to about 0.06 bit, so a
//! quarter bit is about four of those beyond the tracking error (~0.03 bit); a
//! good line's mean size is about 0.14 bit there. A tail read a third of a bit
//! or more off (where ±15 % jitter starts to misread it) is out.
//!
//! # What it cannot see
//! A slip of most of a bit over a tail of repeated data bits (`0 1 0 1 ...`: an
//! edge every bit) reads valid pairs whose edges lie near where the timing puts
//! them; a drift that large also moves the successor's start edge by most of a
//! bit, which the start-edge window rejects, but a transient excursion of the
//! line's phase that the stop field takes back up is invisible to both. At 4x
//! (50 MHz) two bits are eight samples, so on a line without jitter every
//! checked edge is measured with the same rounding, up to half a sample (an
//! eighth of a bit) towards the timing: a tail read 0.35 bit off can measure a
//! quarter bit and pass there (with jitter the roundings differ and average out).
//! Measuring against the samples the bits were read at (the rounded centres)
//! instead of the exact boundaries would see that margin, but at 3x it charges a
//! clean line up to half a sample of centre rounding and lost frames at ±20 %
//! jitter (`limits_over_many_locks`, tried and dropped).
//!
//! # A second look: the edges between the pairs
//! At 3x (37.5 MHz) two bits are six samples, so all 8 checked edges sit at one
//! sub-sample phase and round alike. With the edges half a sample off the
//! sampling grid, ±25 % jitter (±0.75 sample) makes each edge measure a sample
//! early, on time or a sample late (1/6, 2/3, 1/6): a coarse step, a third of a
//! bit, and 7 of 8 a sample early (the same picture as a whole-bit read of 7
//! pairs, 0.29 bit) come about once in 10^4 good frames (`limits_over_many_locks`,
//! seed 20023; README "Known limits", docs/engineering-log.md). A wider bound or
//! the mean over the last 16 pairs took those and published whole-bit reads
//! too (`tests::tail`). So a tail whose mean alone is beyond a quarter bit (its
//! mean size within 3/8: the mean is too) gets a second look
//! ([`tail_again`], `between_pairs`) at edges its mid-pair edges' jitter says
//! nothing about: the level changes between its pairs (pair `i`'s first bit
//! against pair `i - 1`'s second, where the pattern as read changes level). On a
//! good line they jitter on their own, and their mean lies within an eighth of
//! a bit; on a tail read a bit off they moved with the slip (a whole-bit read
//! yields valid pairs only where the data repeats, i.e. where the pattern has
//! such a change between the pairs). The look passes when they lie on average
//! within an eighth of a bit (one at least), every edge of the last 16 bits
//! within half a bit (an edge the line does not make lies beyond its window)
//! and all of them on average within a quarter bit. Measured: seed 20023
//! recovered (13 edges, mean -0.18 bit; between the pairs within the eighth),
//! no further line publishing a frame not sent in `tests::tail` (pinned) nor in
//! 103 680 excursion lines on 30 more seeds (2 647 with it and without); a
//! bound of 5/32 bit between the pairs published one more in `tests::tail`.
//! The eighth of a bit binds on the side the mid-pair edges lie on (a slip
//! moves both groups that way); on the other side the edges between the pairs
//! contradict the slip, and there they may lie up to a quarter bit off on
//! average: seed 10627 (37.5 MHz, ±25 %, frame 66, `limits_over_many_locks`)
//! had 7 of its 8 mid-pair edges a sample early (mean -0.33 bit) and its only
//! 2 edges between the pairs on time and a sample late (+0.13 bit), and was
//! lost (docs/engineering-log.md 2026-12-03 `tol25`). Cold: the steady state
//! never calls it.
//!
//! # A short excursion: far edges on a clean line
//! The same slip over only the last 4..7 pairs, undone before the stop field,
//! leaves the other checked edges on time, and 4 slipped edges of 8 put the mean
//! near 0.2 bit: inside the bounds. Each slipped edge measures 5/16 bit or more
//! off ([`far_edge`]; half a bit less up to a sample), which an edge of a line
//! within ±10 % jitter never does; so [`tail`] also counts them, and the receiver
//! rejects a tail with [`FAR_EDGES`] of them when its line's recent tails had
//! (nearly) none ([`excursion`], `Timing::clean`). A line with ±25 % jitter at
//! 3x measures 4 and more far edges on about 1 % of its frames (it cannot be
//! told from a slip there, at three samples a bit), but it shows far edges on
//! a third of them, so the check stays off for it. Counted on the
//! reference's settled tails; one subtract and add an edge.
//!
//! The record and the frame count far edges at one bound, so a jittered line
//! whose edges a sample off measure a hair under it counts as clean, and loses
//! a frame once the timing moves them a hair over (at 4x with the timing a
//! quarter sample off the sampling grid those edges measure the bound to a
//! hundredth). On a line that is not steady, a reference tail rejected so is
//! counted again with the bound [`FAR_SLACK`] further out
//! (`HansRx::recounted`, cold): a hysteresis between record and judgement.
//!
//! A slip of only the last 3 pairs leaves 3 far edges. On a line whose
//! checked edges all measure within 3/4 sample of the timing ([`OFF_EDGE`],
//! `Timing::steady`: no jitter to speak of) a good tail has no far edge
//! unless a glitch moved it, so there 3, with the last 3 edges off the line,
//! are an excursion ([`STEADY_FAR_EDGES`]); the record counts off edges as it
//! counts the far ones (~4 instructions an edge more, ~48 a frame in all).
//! It took the 3-pair slips of the lines without jitter at 3x and most at
//! 3.2x (`tests::tail::BEYOND`). A slip read a whole bit off at 4x measures
//! its edges a sample early (0.35 bit less the rounding), under the far
//! bound: counting edges a sample off on a steady line would see it, but one
//! polarity's rounding step on a line with asymmetric edges near a whole
//! ratio makes the same picture on good frames (successor's edge on time),
//! which then were lost (`tests::rounding`; tried and dropped 2026-12-03).
//!
//! # A rounding step
//! Within a few hundred ppm of a whole number of samples a bit (3.0003 at 37.5
//! MHz), every edge of a clean line sits at nearly the same sub-sample phase, so
//! every measured edge has the same rounding (up to half a sample), which steps
//! by a whole sample each time that phase crosses a sample (every 1 / (125 x
//! 0.0003) = 27 frames). The timing has followed the plateau between two steps
//! exactly; after a step the tail measures a sample off it, while the bits are
//! read half a sample off (the line crossed the sample between the two
//! roundings). No bound on the mean alone tells that from a tail read 0.45 bit
//! (1.35 samples) off whose edges round towards the timing: both measure 0.85 to
//! 1 sample. What only the step shows is [`stepped`]: every measured edge of
//! the frame, its start edge, the checked mid-pair edges and its successor's
//! start edge, lies within [`STEP_SLACK`] of one rounding, the successor's, or
//! (the edges before the step, in line order) of the one a sample before it. A
//! jittered line spreads its edges over a sample and more, so ten of them fit
//! that only on a line without jitter; an excursion of the line within the frame
//! (the stop field taking it back up) leaves the successor's edge at the
//! earlier rounding. The receiver then re-reads the frame at the successor's
//! phase and publishes it only if it reads the same pattern there and passes
//! every check at that phase at the bounds above (`HansRx::rephased`): the tail
//! is still judged against a phase it had no say in, a single start edge that
//! the nine other edges of the frame agree with within a quarter sample.
//!
//! # Cost
//! One edge is ~21 instructions on the M7 (two window loads, a funnel shift, a
//! count, two sums), ~230 per checked channel and frame with the set-up and the
//! start-edge part `HansRx::confirmed` shares (`cargo xtask profile`); the channels that
//! matched the reference centre for centre hold its pattern and share one check
//! (the first of them that confirms, normally the reference).

use super::phase::{PairEdges, PAIRS};
use super::ring::{Ring, FRAC, HALF};

/// Mid-pair edges checked at the end of every frame: the data pairs of DATA3's
/// last 8 bits. Eight bring the mean's jitter to a quarter of a single edge's
/// (see the module docs) at ~21 instructions each; the 8 edges span the last 16
/// bits, where a rate error has moved the phase as far as at the stop bits.
pub const TAIL_PAIRS: u32 = 8;

/// The first pair checked.
const FIRST: u32 = PAIRS - TAIL_PAIRS;

// The checked pairs' first bits lie in the pattern's low 32 bits (pair `i`'s first
// bit is pattern bit `124 - 2i`), so one `u32` holds them.
const _: () = assert!(124 - 2 * FIRST <= 31);

/// Largest mean deviation (Q16 samples) of the last [`TAIL_PAIRS`] mid-pair edges
/// from where the timing puts them: a quarter of a bit (0.75 to 1 sample at 3x to
/// 4x); their mean size may be half as much again (3/8 bit). A good line's mean
/// lies within about 0.06 bit plus the tracking error at ±25 % jitter, its mean
/// size near 0.14 bit (module docs).
pub fn tail_window(ratio: i32) -> u32 {
    (ratio / 4) as u32
}

/// A tail that passed [`tail`]'s bounds.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Tail {
    /// The summed deviation (Q16 samples, signed: later than the timing positive;
    /// [`TAIL_PAIRS`] times their mean).
    pub sum: i32,
    /// How many of the edges lie [`far_edge`] or more off, whichever way
    /// ([`excursion`]).
    pub far: u32,
    /// How many of the edges lie [`OFF_EDGE`] or more off, whichever way: what
    /// the line's record counts to tell a steady line (`Timing::steady`).
    pub off: u32,
    /// The last [`STEADY_FAR_EDGES`] edges all lie [`OFF_EDGE`] or more off
    /// ([`excursion`] on a steady line).
    pub end: bool,
}

/// The summed deviation of the last [`TAIL_PAIRS`] mid-pair edges
/// of the frame whose start edge is at `head` (Q16, the channel's own: shared
/// start plus its delay), read with `ratio` (Q16 samples per bit) on `ring`,
/// from where that timing puts them, when their mean lies within
/// [`tail_window`] and their deviations' mean size within 1.5 times that,
/// with the count of edges [`far_edge`] or more off ([`Tail`]);
/// `None` otherwise. The mean is also the settled timing's best phase
/// measurement (`Timing::advance`): its jitter is about a third of a single
/// start edge's. `pattern` is the frame's pattern as read
/// (first bit at bit 124): it says which level comes before each edge; a pair
/// read with the wrong level measures its edge half a bit early (at its window's
/// start), an edge beyond its window where the level really changes (up to 32
/// samples on).
// Inlined into its one caller (`HansRx::confirmed`), as it was before
// `tail_again` shared its body: not inlined, it cost ~40 instructions a frame.
#[inline(always)]
pub fn tail(ring: &Ring, head: u32, ratio: i32, pattern: u128) -> Option<Tail> {
    measured::<false>(ring, head, ratio, pattern)
}

/// [`tail`] with the second look at a tail whose mean alone is beyond
/// [`tail_window`] (`between_pairs`, module docs). A separate entry, so that
/// the steady state's [`tail`] holds no call: one there (however cold) doubled
/// the stack spills in its unrolled loop (~40 instructions a frame, QEMU).
pub fn tail_again(ring: &Ring, head: u32, ratio: i32, pattern: u128) -> Option<Tail> {
    measured::<true>(ring, head, ratio, pattern)
}

/// [`tail`] (`AGAIN` false) and [`tail_again`].
#[inline(always)]
fn measured<const AGAIN: bool>(ring: &Ring, head: u32, ratio: i32, pattern: u128) -> Option<Tail> {
    let mut edges = TailEdges::new(head, ratio, pattern);
    let far_at = far_edge(ratio);
    // Sums of the edges' deviations and of their sizes (Q16 samples; each below
    // 32 samples, so the sums fit), and the count of near ones: a size below
    // `far_at` wraps its difference to it into the top bit (exact for any size,
    // `far_at` being below 2^31). One subtract and a shifted add an edge; a
    // compare and conditional add per edge cost ~13 instructions more a frame
    // (QEMU), the compiler keeping every edge's size for them past the bounds.
    // The same for edges within `OFF_EDGE` (`on`), and which of them were
    // (`ons`, the last edge at bit 0): ~4 instructions an edge more. `on` is
    // `ons.count_ones()`, counted as it goes because the M7 has no population
    // count: deriving it cost ~14 instructions a frame more (QEMU).
    let (mut sum, mut spread, mut near, mut on, mut ons) = (0i32, 0u32, 0u32, 0u32, 0u32);
    for _ in 0..TAIL_PAIRS {
        let r = edges.next(ring);
        let size = r.unsigned_abs();
        sum = sum.wrapping_add(r);
        spread = spread.wrapping_add(size);
        near = near.wrapping_add(size.wrapping_sub(far_at) >> 31);
        let is_on = size.wrapping_sub(OFF_EDGE) >> 31;
        ons = ons << 1 | is_on;
        on = on.wrapping_add(is_on);
    }
    let w = tail_window(ratio);
    let wide = spread <= TAIL_PAIRS.wrapping_mul(w.wrapping_add(w / 2));
    // The mean size bounds the mean deviation too (to 3/8 bit): a tail within
    // it whose mean alone is beyond a quarter bit gets the second look.
    let centred = if AGAIN {
        wide && (sum.unsigned_abs() <= TAIL_PAIRS.wrapping_mul(w)
            || between_pairs(ring, head, ratio, pattern as u32))
    } else {
        sum.unsigned_abs() <= TAIL_PAIRS.wrapping_mul(w) && wide
    };
    centred.then_some(Tail {
        sum,
        far: TAIL_PAIRS.wrapping_sub(near),
        off: TAIL_PAIRS.wrapping_sub(on),
        end: ons & ((1 << STEADY_FAR_EDGES) - 1) == 0,
    })
}

/// Largest mean deviation (Q16 samples) of the edges between the last
/// [`TAIL_PAIRS`] pairs for `between_pairs`: an eighth of a bit.
pub fn between_window(ratio: i32) -> u32 {
    (ratio / 8) as u32
}

/// The second look at a tail whose mid-pair edges' mean lies beyond
/// [`tail_window`] (their mean size within 3/8 bit) (module docs): true when
/// the level changes between the last [`TAIL_PAIRS`] pairs (at bit
/// boundaries `2i` where the pattern as read changes level; one at least)
/// lie on average within [`between_window`] of where the timing puts them
/// towards the side the mid-pair edges' mean lies on (within [`tail_window`]
/// the other way),
/// every edge of the last `2 TAIL_PAIRS` bits (those and the mid-pair ones)
/// within half a bit, and all of them on average within [`tail_window`].
/// Measured as [`tail`] measures the mid-pair edges. Cold: a good line at ±25
/// % jitter needs it about once in 10^4 frames.
fn between_pairs(ring: &Ring, head: u32, ratio: i32, pattern: u32) -> bool {
    let mut mid = TailEdges::new(head, ratio, u128::from(pattern));
    // The boundary before pair `i` is where a frame starting a bit earlier has
    // pair `i`'s mid-pair edge, the level before it one pattern bit higher.
    let mut between = TailEdges::new(
        head.wrapping_sub(ratio as u32),
        ratio,
        u128::from(pattern >> 1),
    );
    let half = (ratio / 2).unsigned_abs();
    // Sums and counts of all the edges and of those between the pairs (each
    // deviation below 32 samples: the sums fit).
    let (mut sum, mut n, mut inside) = (0i32, TAIL_PAIRS, true);
    let (mut between_sum, mut between_n, mut mid_sum) = (0i32, 0u32, 0i32);
    for i in FIRST..PAIRS {
        let r = mid.next(ring);
        sum = sum.wrapping_add(r);
        mid_sum = mid_sum.wrapping_add(r);
        inside &= r.unsigned_abs() <= half;
        let r = between.next(ring);
        // Bits 2i - 1 and 2i (pattern bits 125 - 2i and 124 - 2i) differ: a
        // level change the line must show there.
        if ((pattern >> (124 - 2 * i)) ^ (pattern >> (125 - 2 * i))) & 1 != 0 {
            sum = sum.wrapping_add(r);
            n = n.wrapping_add(1);
            between_sum = between_sum.wrapping_add(r);
            between_n = between_n.wrapping_add(1);
            inside &= r.unsigned_abs() <= half;
        }
    }
    // The between-pair edges' summed deviation towards the side the mid-pair
    // edges lie on (where a slip moves both groups): within an eighth of a bit
    // on average there, within a quarter bit away from it.
    let toward = if mid_sum < 0 {
        between_sum.wrapping_neg()
    } else {
        between_sum
    };
    let toward_ok = toward <= between_n.wrapping_mul(between_window(ratio)) as i32;
    let away_ok = toward.wrapping_neg() <= between_n.wrapping_mul(tail_window(ratio)) as i32;
    inside
        && between_n > 0
        && toward_ok
        && away_ok
        && sum.unsigned_abs() <= n.wrapping_mul(tail_window(ratio))
}

/// Smallest deviation (Q16 samples) of a checked edge that counts as far for
/// [`excursion`]: 5/16 bit, beyond what an edge of a line within ±10 % jitter
/// can measure (its jitter plus half a sample of rounding, a sixth of a bit at
/// 3x: 0.27 bit) and within what a pair read a whole bit off measures (half a
/// bit less up to a sample: a third of a bit at 3x).
pub fn far_edge(ratio: i32) -> u32 {
    (ratio as u32 / 16).wrapping_mul(5)
}

/// How far (Q16 samples) beyond [`far_edge`] an edge of a tail that
/// [`excursion`] rejected on a line that is not steady must lie to count on
/// the second count (`HansRx::recounted`, [`far_beyond`]): 1/32 sample, a
/// hysteresis between the line's record (`Timing::clean`, counted at the
/// bound) and the frame's judgement. Measured (`limits_over_many_locks` at 640
/// locks a point, docs/engineering-log.md 2026-12-04): the three locks that
/// lost a frame to edges a hundredth of a sample over the bound keep it, and
/// `tests::tail`'s tables and `tests::rounding` are unchanged.
pub const FAR_SLACK: u32 = 1 << (FRAC - 5);

/// How many of the last [`TAIL_PAIRS`] mid-pair edges of the frame at `head`
/// (as for [`tail`]) lie [`far_edge`] plus `slack` (Q16 samples) or more off,
/// whichever way: [`Tail::far`] with a wider bound. Cold (`HansRx::recounted`).
pub fn far_beyond(ring: &Ring, head: u32, ratio: i32, pattern: u128, slack: u32) -> u32 {
    let mut edges = TailEdges::new(head, ratio, pattern);
    let at = far_edge(ratio).wrapping_add(slack);
    let mut far = 0;
    for _ in 0..TAIL_PAIRS {
        far += u32::from(edges.next(ring).unsigned_abs() >= at);
    }
    far
}

/// Far edges ([`far_edge`]) of one tail from which it is an excursion on a line
/// whose recent tails had (nearly) none ([`excursion`]): half of the
/// [`TAIL_PAIRS`], what a whole-bit read of the last 4 pairs leaves.
pub const FAR_EDGES: u32 = TAIL_PAIRS / 2;

/// True when `tail` is rejected as a short excursion of the line's phase: on a
/// line whose recent tails were `clean` (`Timing::clean`: on average under one
/// far edge in 32 frames) when [`FAR_EDGES`] of its edges are far, and on a
/// line that is also `steady` (`Timing::steady`: the same for edges
/// [`OFF_EDGE`] off) when [`STEADY_FAR_EDGES`] are and its last that many
/// edges are off ([`Tail::end`]).
///
/// Why: a whole-bit read of a few pairs over repeated data reads valid pairs
/// whose edges measure half a bit off less up to a sample, and on only the last
/// 4 of the 8 checked pairs the tail's mean stays near 0.2 bit, inside
/// [`tail_window`] (README "Known limits", docs/engineering-log.md). At 3x the samples only say which of
/// three places an edge lies at, so a single edge a sample off is the same
/// picture on a good line with ±25 % jitter as on a slipped one, and a good
/// ±25 % line at 3x has 4 and more of 8 such edges on about 1 % of its frames
/// (measured: 152 of 15 300); no bound on one frame's edges tells them apart.
/// The line's own record does: a line within ±15 % jitter (±20 % at 4x)
/// measures a far edge on under 1.5 % of its frames (none in 54 576 tails
/// within ±10 %), so 4 at once there is an excursion, while a line that
/// shows them keeps the check as it was. A line whose edges all measure
/// within [`OFF_EDGE`] of the timing (no jitter to speak of: one rounding, or
/// two with the timing between them) has a far edge only where something
/// else moved it: a slip, or a glitch or noise burst next to an edge (a
/// sample early). 3 far edges there are rejected when the tail ends off the
/// line, as an excursion undone only by the stop field does; 3 anywhere cost
/// the HANS campaign 19 good frames in vote3 / vote5 (glitches, a sample off,
/// scattered over the tail), this none. A steady line is clean (an off edge
/// counts wherever a far one does).
pub fn excursion(tail: Tail, clean: bool, steady: bool) -> bool {
    clean && (tail.far >= FAR_EDGES || (steady && tail.end && tail.far >= STEADY_FAR_EDGES))
}

/// Smallest deviation (Q16 samples) of a checked edge that makes a line not
/// steady (`Timing::steady`): 3/4 sample. An edge of a line without jitter
/// measures within half a sample of where it lies, plus the timing's error (a
/// few hundredths of a sample on a settled lock); a jittered line whose edges
/// happen to stay on one rounding (or two, the timing between them) for ~16
/// frames measures the same and is as steady (some ±15..25 % lines of
/// `tests::tail::BEYOND` are, for a while). At 5/8 sample fewer lines counted
/// as steady (measured 2026-12-03 on 3 far edges anywhere: `BEYOND` 458 lines
/// against 394 at 3/4); 3/4 sample lost nothing more anywhere. Counting edges
/// this far off as the excursion (not only the far ones) lost good frames on
/// asymmetric lines near a whole ratio, where one polarity's rounding steps a
/// sample (`rounding::ASYM_KNOWN_LOST`, at 5/8 and 3/4 sample alike).
pub const OFF_EDGE: u32 = 3 << (FRAC - 2);

/// Far edges ([`far_edge`]) of one tail, its last that many edges off
/// ([`Tail::end`]), from which it is an excursion on a steady line
/// ([`excursion`]): what a whole-bit read of the last 3 pairs leaves (a good
/// frame on such a line has none).
pub const STEADY_FAR_EDGES: u32 = 3;

/// How far (Q16 samples) each edge of a frame may lie from the rounding the others
/// show for [`stepped`]: a quarter sample, what the edges' sub-sample phase drifts
/// over a frame within 0.07 % of a whole ratio (125 bits x 0.002 sample), where
/// the timing follows a plateau for several frames (from 0.1 % on the roundings
/// change every frame or two, and the timing follows the line: 3.003 lost nothing
/// before `stepped`), and far below a jittered line's spread (a sample and more
/// at ±15 %).
pub const STEP_SLACK: u32 = 1 << (FRAC - 2);

/// True when the edges of the frame whose start edge is at `head` (as for
/// [`tail`]) show a rounding step (module docs): its start edge, measured
/// `start` (Q16) from `head`, its last [`TAIL_PAIRS`] mid-pair edges and its
/// successor's start edge, measured `next` from where the timing puts it, each
/// lie within [`STEP_SLACK`] of `next`, or of a sample nearer the timing than
/// `next` as long as no earlier one lay at `next` (a step within the frame).
pub fn stepped(ring: &Ring, head: u32, ratio: i32, pattern: u128, start: i32, next: i32) -> bool {
    let before = next.wrapping_sub(next.signum() << FRAC);
    let near = |r: i32, to: i32| r.wrapping_sub(to).unsigned_abs() <= STEP_SLACK;
    // Set from the first edge at the successor's rounding on.
    let mut stepped = false;
    let mut on = |r: i32| {
        if near(r, next) {
            stepped = true;
            true
        } else {
            !stepped && near(r, before)
        }
    };
    if !on(start) {
        return false;
    }
    // The tail's deviations as [`tail`] measures them.
    let mut edges = TailEdges::new(head, ratio, pattern);
    (0..TAIL_PAIRS).all(|_| on(edges.next(ring)))
}

/// The deviations of a frame's last [`TAIL_PAIRS`] mid-pair edges from where the
/// timing puts them, one per [`TailEdges::next`], as [`tail`] and [`stepped`]
/// measure them.
struct TailEdges {
    edges: PairEdges,
    /// Where the timing puts the next edge (Q16), plus the half sample of the
    /// measuring convention.
    at: u32,
    /// Two bits (Q16 samples).
    step: u32,
    /// The next pair's first bit at bit 31, the later pairs' every two bits below.
    bits: u32,
}

impl TailEdges {
    /// The edges of the frame whose start edge is at `head` (as for [`tail`]).
    #[inline(always)]
    fn new(head: u32, ratio: i32, pattern: u128) -> TailEdges {
        TailEdges {
            edges: PairEdges::new(head, ratio, FIRST),
            // Pair FIRST's edge is bit boundary 2 FIRST + 1.
            at: head
                .wrapping_add((ratio as u32).wrapping_mul(2 * FIRST + 1))
                .wrapping_add(HALF),
            step: (ratio as u32).wrapping_mul(2),
            // Pair FIRST's first bit is pattern bit 124 - 2 FIRST.
            bits: (pattern as u32) << (2 * FIRST - 93),
        }
    }

    /// The next edge's deviation (Q16 samples).
    #[inline(always)]
    fn next(&mut self, ring: &Ring) -> i32 {
        let r = (self.edges.count_on(ring, self.bits) << FRAC).wrapping_sub(self.at) as i32;
        self.at = self.at.wrapping_add(self.step);
        self.bits <<= 2;
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hans::Frame;
    use proptest::prelude::*;

    const Q: f64 = 65536.0;

    fn q(v: f64) -> i32 {
        (v * Q).round() as i32
    }

    use crate::hans::rx::phase::tests::ring_of_edges as ring_of;

    /// The start edge the receiver measures for a line edge at `t` (samples): half a
    /// sample before the first sample at the new level.
    fn measured(t: f64) -> u32 {
        q(t.ceil() - 0.5) as u32
    }

    /// The pattern the receiver reads from `ring` with that timing: the sample
    /// nearest each bit centre (first bit at bit 124).
    fn read(ring: &Ring, head: u32, ratio: i32) -> u128 {
        (0..125u32).fold(0u128, |p, k| {
            let s = head
                .wrapping_add(ratio as u32 / 2 + HALF)
                .wrapping_add(k * ratio as u32)
                >> FRAC;
            p << 1 | u128::from((ring.window(s / 32) >> (31 - s % 32)) & 1)
        })
    }

    fn pattern() -> u128 {
        Frame::new(0x5A3C1, 0xF0F0F, 0x12345).unwrap().encode()
    }

    /// The mean deviation and the mean size of the deviations (bits) `tail`
    /// compares, recomputed edge by edge in f64 from the samples: each checked
    /// pair's edge (half a sample before the first sample at the second level
    /// from the start of the bit time centred on the boundary) against that
    /// boundary.
    fn mean_offset(ring: &Ring, head: u32, ratio: i32, pattern: u128) -> (f64, f64) {
        let sample = |s: i64| {
            let s = s.rem_euclid(1024) as u32;
            (ring.window(s / 32) >> (31 - s % 32)) & 1 == 1
        };
        let (head, ratio) = (f64::from(head) / Q, f64::from(ratio) / Q);
        let (mut sum, mut spread) = (0.0, 0.0);
        for i in FIRST..PAIRS {
            let at = head + f64::from(2 * i + 1) * ratio;
            let lo = (at - ratio / 2.0).ceil() as i64;
            let first = (pattern >> (124 - 2 * i)) & 1 == 1;
            // Not bounded by the window's end (`PairEdges::count_on`): up to 32.
            let c = (lo..lo + 32)
                .find(|&s| sample(s) != first)
                .unwrap_or(lo + 32);
            let d = c as f64 - 0.5 - at;
            sum += d;
            spread += d.abs();
        }
        let bits = f64::from(TAIL_PAIRS) * ratio;
        (sum / bits, spread / bits)
    }

    /// The second look (`between_pairs`) recomputed edge by edge in f64, as
    /// [`mean_offset`]: the mean deviation (bits) of the edges between the last
    /// 8 pairs (`None` without one), that of all the edges of the last 16 bits,
    /// and the largest deviation of any of them (bits).
    fn between_offset(
        ring: &Ring,
        head: u32,
        ratio: i32,
        pattern: u128,
    ) -> (Option<f64>, f64, f64) {
        let sample = |s: i64| {
            let s = s.rem_euclid(1024) as u32;
            (ring.window(s / 32) >> (31 - s % 32)) & 1 == 1
        };
        let (head, ratio) = (f64::from(head) / Q, f64::from(ratio) / Q);
        // Bit `b` of the frame (pattern bit 124 - b).
        let bit = |b: u32| (pattern >> (124 - b)) & 1 == 1;
        // The edge at boundary `b`, the level before it that of bit `b - 1`.
        let deviation = |b: u32| {
            let at = head + f64::from(b) * ratio;
            let lo = (at - ratio / 2.0).ceil() as i64;
            let c = (lo..lo + 32)
                .find(|&s| sample(s) != bit(b - 1))
                .unwrap_or(lo + 32);
            (c as f64 - 0.5 - at) / ratio
        };
        let (mut between, mut n_between, mut all, mut n, mut worst) = (0.0, 0, 0.0, 0, 0.0f64);
        for b in 2 * FIRST..2 * PAIRS {
            if b % 2 == 1 || bit(b - 1) != bit(b) {
                let d = deviation(b);
                all += d;
                n += 1;
                worst = worst.max(d.abs());
                if b % 2 == 0 {
                    between += d;
                    n_between += 1;
                }
            }
        }
        let between = (n_between > 0).then(|| between / f64::from(n_between));
        (between, all / f64::from(n), worst)
    }

    /// The checked edges at least `at` samples off (edge by edge in f64, as
    /// [`mean_offset`]): the fewest and most counts within the Q16 rounding.
    fn far_count(ring: &Ring, head: u32, ratio: i32, pattern: u128, at: f64) -> (u32, u32) {
        let sample = |s: i64| {
            let s = s.rem_euclid(1024) as u32;
            (ring.window(s / 32) >> (31 - s % 32)) & 1 == 1
        };
        let (head, ratio) = (f64::from(head) / Q, f64::from(ratio) / Q);
        let (mut fewest, mut most) = (0, 0);
        for i in FIRST..PAIRS {
            let edge = head + f64::from(2 * i + 1) * ratio;
            let lo = (edge - ratio / 2.0).ceil() as i64;
            let first = (pattern >> (124 - 2 * i)) & 1 == 1;
            let c = (lo..lo + 32)
                .find(|&s| sample(s) != first)
                .unwrap_or(lo + 32);
            let d = (c as f64 - 0.5 - edge).abs();
            fewest += u32::from(d >= at + 1e-3);
            most += u32::from(d >= at - 1e-3);
        }
        (fewest, most)
    }

    #[test]
    fn a_frame_where_its_timing_puts_it_is_confirmed() {
        for ratio in [3.0, 3.2, 3.75, 4.0] {
            for t0 in [20.0, 20.3, 20.5, 20.9] {
                let ring = ring_of(pattern(), |k| t0 + k as f64 * ratio);
                let (head, r) = (measured(t0), q(ratio));
                assert_eq!(read(&ring, head, r), pattern());
                assert!(tail(&ring, head, r, pattern()).is_some(), "{ratio} {t0}");
            }
        }
    }

    #[test]
    fn a_tail_read_near_its_edges_is_not() {
        // The line's edges from bit 100 on are moved late (or early) against the
        // timing, the start edge is where it should be; the pattern is what the
        // receiver reads there. 0.45 bit puts the read samples within 0.05 bit
        // (plus their rounding, half a sample) of an edge, or past it: no pattern
        // read there may pass both its checks and this one. A tenth of a bit
        // leaves them well inside their bits: confirmed. The second frame's DATA3
        // ends in 16 zeros (pairs `0 1`: a square wave), so that a tail read a bit
        // late still holds valid pairs.
        let square = Frame::new(0x5A3C1, 0xF0F0F, 0x10000).unwrap().encode();
        for sent in [pattern(), square] {
            for ratio in [3.0, 3.2, 3.75, 4.0] {
                // Start edges half a sample (±0.1) before a sample: measured where
                // they are, so the shift is the timing's error.
                for t0 in [20.43, 20.52, 20.58] {
                    for shift in [-0.6, -0.45, -0.1, 0.1, 0.45, 0.6] {
                        let ring = ring_of(sent, |k| {
                            t0 + k as f64 * ratio + if k >= 100 { shift * ratio } else { 0.0 }
                        });
                        let (head, r) = (measured(t0), q(ratio));
                        let got = read(&ring, head, r);
                        let at = format!("{ratio} {t0} {shift}");
                        if f64::abs(shift) < 0.2 {
                            assert_eq!(got, sent, "{at}");
                            assert!(tail(&ring, head, r, got).is_some(), "{at}");
                        } else {
                            let passed = Frame::decode(got).is_ok()
                                && tail_again(&ring, head, r, got).is_some();
                            assert!(!passed, "{at}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn a_rate_error_shows_at_the_tail() {
        // Timing 3.2 samples a bit, the line 3.2 * (1 ± 0.4 %): 0.46 bit off on
        // average over the checked pairs; 0.1 % (0.11 bit) is fine.
        let square = Frame::new(0x5A3C1, 0xF0F0F, 0x10000).unwrap().encode();
        for (rate, ok) in [
            (0.004, false),
            (-0.004, false),
            (0.001, true),
            (-0.001, true),
        ] {
            let ring = ring_of(square, |k| 20.5 + k as f64 * 3.2 * (1.0 + rate));
            let (head, r) = (measured(20.5), q(3.2));
            let got = read(&ring, head, r);
            let passed = Frame::decode(got).is_ok() && tail_again(&ring, head, r, got).is_some();
            assert_eq!(passed, ok, "{rate}");
        }
    }

    #[test]
    fn a_wrong_level_is_half_a_bit_off() {
        // The checked pairs inverted in the pattern (DATA3's last 8 data bits and
        // their complements, pattern bits 18..3): every checked pair's first level
        // is wrong, so each edge reads at its window's start. Six of them wrong:
        // deviations of half a bit and more on six of eight edges, out too.
        let ring = ring_of(pattern(), |k| 20.0 + k as f64 * 3.5);
        assert!(tail(&ring, measured(20.0), q(3.5), pattern()).is_some());
        assert!(tail_again(&ring, measured(20.0), q(3.5), pattern() ^ 0xFFFF << 3).is_none());
        assert!(tail_again(&ring, measured(20.0), q(3.5), pattern() ^ 0xFFF << 3).is_none());
    }

    #[test]
    fn the_edges_between_the_pairs_take_a_second_look() {
        // 3 samples a bit, every edge half a sample before a sample (the
        // timing on the line): measured where the timing puts it. DATA3's last
        // 16 bits zero: pairs `0 1`, an edge at every boundary of the tail.
        let square = Frame::new(0x5A3C1, 0xF0F0F, 0x10000).unwrap().encode();
        let (head, r) = (measured(20.5), q(3.0));
        // The mid-pair edges of pairs 53..=59 (boundaries 107..=119, odd) and the
        // first `between` boundaries before pairs 53.. (106, 108, ...) 0.6
        // sample early: each measures a sample early. `late` moves them as
        // far the other way.
        let confirmed = |between: u32, late: bool| {
            let off = if late { 0.6 } else { -0.6 };
            let ring = ring_of(square, |k| {
                let k32 = k as u32;
                let moved = (k32 % 2 == 1 && (107..=119).contains(&k32))
                    || (k32.is_multiple_of(2) && (106..106 + 2 * between).contains(&k32));
                20.5 + 3.0 * k as f64 + if moved { off } else { 0.0 }
            });
            assert_eq!(read(&ring, head, r), square);
            // The first look alone rejects it.
            assert!(tail(&ring, head, r, square).is_none());
            tail_again(&ring, head, r, square).is_some()
        };
        for late in [false, true] {
            // 7 of 8 mid-pair edges a sample off: 0.29 bit, beyond a quarter. The
            // edges between the pairs on time (or 2 of 8 a sample off, 1/12 bit
            // on average) confirm the timing: jitter, not a slip.
            assert!(confirmed(0, late), "{late}");
            assert!(confirmed(2, late), "{late}");
            // Half of them a sample off: 1/6 bit on average, beyond an eighth;
            // all of them (the tail read a sample off, a slip's picture): out.
            assert!(!confirmed(4, late), "{late}");
            assert!(!confirmed(8, late), "{late}");
        }
        // Without an edge between the pairs (data alternating: `0 1 1 0 ...`)
        // there is no second look.
        let alternating = Frame::new(0x5A3C1, 0xF0F0F, 0x1AAAA).unwrap().encode();
        // The last 7 mid-pair edges 0.6 sample early, nothing else moved.
        let early_mids = |k: usize| {
            20.5 + 3.0 * k as f64
                + if k % 2 == 1 && (107..=119).contains(&k) {
                    -0.6
                } else {
                    0.0
                }
        };
        let ring = ring_of(alternating, early_mids);
        assert_eq!(read(&ring, head, r), alternating);
        assert!(tail_again(&ring, head, r, alternating).is_none());
        // The same line with pair 60 read as `1 0` (the line's `0 1`): its edge
        // measures at its window's start, two samples early, beyond half a bit:
        // no second look.
        let ring = ring_of(square, early_mids);
        assert!(tail_again(&ring, head, r, square).is_some());
        assert!(tail_again(&ring, head, r, square ^ 0b11 << 3).is_none());
    }

    #[test]
    fn a_rounding_step_is_told_from_an_excursion() {
        // Timing at 3 samples a bit from 20.5. The line's boundary `k` lies at
        // 20.5 + 3k + `off(k)`; 0.52 rounds a sample late (the edge just after a
        // sample: the step), 0.02 onto the timing (the plateau before it).
        let head = q(20.5) as u32;
        let (r, one) = (q(3.0), q(1.0));
        let on = |off: &dyn Fn(usize) -> f64, start: i32, next: i32| {
            let ring = ring_of(pattern(), |k| 20.5 + 3.0 * k as f64 + off(k));
            stepped(&ring, head, r, read(&ring, head, r), start, next)
        };
        // The whole frame a sample off (its start edge and tail), or from any
        // point before or within the tail on; the successor too.
        assert!(on(&|_| 0.52, one, one));
        assert!(on(&|_| 0.52, q(0.9), q(1.1)));
        for step in [1, 60, 107, 108, 110, 121] {
            assert!(
                on(&|k| if k < step { 0.02 } else { 0.52 }, 0, one),
                "{step}"
            );
        }
        // The same downwards (a line slower than the timing).
        assert!(on(&|_| -0.98, -one, -one));
        assert!(on(&|k| if k < 110 { 0.02 } else { -0.98 }, 0, -one));
        // A tail a sample off between start edges on time: an excursion.
        assert!(!on(&|_| 0.52, 0, 0));
        assert!(!on(&|_| 0.52, one, 0));
        // Back to the earlier rounding after the step, or a tail half on each.
        assert!(!on(&|k| if k < 110 { 0.52 } else { 0.02 }, one, one));
        assert!(!on(&|k| if k % 4 < 2 { 0.02 } else { 0.52 }, 0, one));
        // Two samples off, or the start edge a third of a sample from the rest.
        assert!(!on(&|_| 1.52, one, one));
        assert!(!on(&|_| 0.52, q(0.6), one));
        // Jitter of ±0.2 sample around a step's rounding: the edges fall on
        // either side of a sample, not on one rounding.
        assert!(!on(&|k| if k % 3 == 0 { 0.32 } else { 0.72 }, one, one));
    }

    #[test]
    fn garbage_never_panics() {
        let words: Vec<u16> = (0..64u16).map(|w| w.wrapping_mul(0x9E37)).collect();
        let mut ring = Ring::default();
        ring.write(0, &words);
        for s in (0..70_000u32).step_by(997) {
            for ratio in [0, -1, q(3.3), i32::MAX, i32::MIN] {
                let _ = tail(&ring, s.wrapping_mul(40_503), ratio, u128::MAX);
                let _ = tail_again(&ring, s.wrapping_mul(40_503), ratio, u128::MAX);
                let d = s.wrapping_mul(7_919) as i32;
                let _ = stepped(&ring, s.wrapping_mul(40_503), ratio, u128::MAX, d, -d);
            }
        }
    }

    proptest! {
        /// The word-level count is the edge-by-edge mean, at any sampling phase, ratio,
        /// timing error and jitter: the bound is the one the docs state.
        #[test]
        fn same_as_the_edge_by_edge_mean(
            data in (0u32..1 << 20, 0u32..1 << 20, 0u32..1 << 20),
            t0 in 1.0f64..400.0,
            ratio in 2.9f64..4.2,
            off in -1.0f64..1.0,
            jitter in prop::collection::vec(-0.3f64..0.3, 126),
        ) {
            let Ok(frame) = Frame::new(data.0, data.1, data.2) else {
                return Err(TestCaseError::fail("frame"));
            };
            let pattern = frame.encode();
            let ring = ring_of(pattern, |k| t0 + (k as f64 + jitter[k]) * ratio);
            let (head, r) = (q(t0 + off) as u32, q(ratio));
            let (mean, spread) = mean_offset(&ring, head, r, pattern);
            let got = tail_again(&ring, head, r, pattern);
            let first = tail(&ring, head, r, pattern);
            // Away from the bounds by more than the Q16 rounding, the two agree;
            // beyond a quarter bit, the second look decides.
            let w = tail_window(r);
            let (bound, wide) = (f64::from(w) / f64::from(r), f64::from(w + w / 2) / f64::from(r));
            let (between, all, worst) = between_offset(&ring, head, r, pattern);
            let clear = |v: f64, b: f64| (v.abs() - b).abs() > 1e-3;
            // The between-pair mean towards the mid-pair edges' side: within
            // an eighth of a bit there, a quarter bit the other way.
            let second = between.map(|b| {
                let toward = if mean < 0.0 { -b } else { b };
                let near = |v: f64, at: f64| (v - at).abs() <= 1e-3;
                (!near(toward, 0.125) && !near(toward, -bound) && clear(all, bound) && clear(worst, 0.5))
                    .then_some(toward <= 0.125 && toward >= -bound && all.abs() <= bound && worst <= 0.5)
            });
            if clear(mean, bound) && clear(spread, wide) {
                let expect = if spread > wide {
                    Some(false)
                } else if mean.abs() <= bound {
                    Some(true)
                } else {
                    second.unwrap_or(Some(false))
                };
                if let Some(expect) = expect {
                    prop_assert_eq!(got.is_some(), expect, "{} {} {:?}", mean, spread, second);
                }
                // The first look alone: both means within their bounds.
                prop_assert_eq!(first.is_some(), mean.abs() <= bound && spread <= wide);
            }
            // Whatever the first look passes, the second passes the same.
            if first.is_some() {
                prop_assert_eq!(first, got);
            }
            // The sum it returns is the edge-by-edge one (Q16 samples).
            if let Some(Tail { sum, far, off, .. }) = got {
                let exact = mean * f64::from(r) * f64::from(TAIL_PAIRS);
                prop_assert!((f64::from(sum) - exact).abs() <= 1.0, "{} {}", sum, exact);
                // The far ones are those at least `far_edge` off (samples).
                let at = f64::from(far_edge(r)) / Q;
                let (fewest, most) = far_count(&ring, head, r, pattern, at);
                prop_assert!((fewest..=most).contains(&far), "{} {} {}", far, fewest, most);
                // The second count: at the bound, the same; `FAR_SLACK`
                // further out, those at least that far off.
                prop_assert_eq!(far_beyond(&ring, head, r, pattern, 0), far);
                let at = f64::from(far_edge(r) + FAR_SLACK) / Q;
                let (fewest, most) = far_count(&ring, head, r, pattern, at);
                let beyond = far_beyond(&ring, head, r, pattern, FAR_SLACK);
                prop_assert!((fewest..=most).contains(&beyond), "{} {} {}", beyond, fewest, most);
                // The off ones those at least `OFF_EDGE` off.
                let at = f64::from(OFF_EDGE) / Q;
                let (fewest, most) = far_count(&ring, head, r, pattern, at);
                prop_assert!((fewest..=most).contains(&off), "{} {} {}", off, fewest, most);
            }
        }
    }
}
