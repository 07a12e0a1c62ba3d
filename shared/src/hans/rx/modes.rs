//! The decode modes (spec "decoding modes" 1-4) applied to the patterns the channels
//! recovered for one frame period.

use crate::hans::Frame;

/// Bitwise 2-of-3 majority.
pub const fn majority3(a: u128, b: u128, c: u128) -> u128 {
    (a & b) | (c & (a | b))
}

/// Bitwise 3-of-5 majority: a bit is set when at least three inputs have it.
pub const fn majority5(v: [u128; 5]) -> u128 {
    let [a, b, c, d, e] = v;
    // Count to three with two "at least one / two / three" accumulators.
    let mut one = 0u128;
    let mut two = 0u128;
    let mut three = 0u128;
    let mut i = 0;
    let all = [a, b, c, d, e];
    while i < 5 {
        let x = all[i];
        three |= two & x;
        two |= one & x;
        one |= x;
        i += 1;
    }
    three
}

/// What super mode makes of the verified frames of one period.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum SuperOutcome {
    /// No channel verified.
    Nothing,
    /// `frame` is held by a strict majority of the verified channels; `minority` has
    /// a bit set (bit n-1 for channel n) for every verified channel that disagreed.
    Publish {
        /// The frame to publish.
        frame: Frame,
        /// Verified channels that disagreed with it.
        minority: u8,
    },
    /// Verified channels disagree and no frame has a strict majority.
    Disagree,
}

/// Super mode's rule: among the channels whose pattern passed every check, publish
/// the frame a **strict majority** of them carries; otherwise reject the period.
/// One verified channel alone is a majority of one; 2 against 2 (or 1 against 1) is
/// rejected. `verified[n]` is channel n+1's frame if it verified.
pub fn super_vote(verified: &[Option<Frame>; 5]) -> SuperOutcome {
    let total = verified.iter().flatten().count();
    for f in verified.iter().flatten() {
        let agree = verified.iter().flatten().filter(|g| *g == f).count();
        if agree * 2 > total {
            let mut minority = 0u8;
            for (j, g) in verified.iter().enumerate() {
                if matches!(g, Some(g) if g != f) {
                    minority |= 1 << j;
                }
            }
            return SuperOutcome::Publish {
                frame: *f,
                minority,
            };
        }
    }
    if total == 0 {
        SuperOutcome::Nothing
    } else {
        SuperOutcome::Disagree
    }
}
