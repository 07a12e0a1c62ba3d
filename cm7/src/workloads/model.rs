//! Workloads of the neutral model: position rescaling and axis mapping.

use super::{Window, Workload, FRAMES};
use crate::tests::prng::Prng;
use core::hint::black_box;
use shared::model::{Axis, ForwardFrame, Position};

/// Input words per frame.
const WORDS: usize = 5;
/// The input of one window: [`WORDS`] words for each of [`FRAMES`] frames.
type Input = [[u32; WORDS]; FRAMES];

/// Every workload, in the order they run. The first one must stay the empty window.
pub const WORKLOADS: &[Workload] = &[
    Workload {
        name: "(call overhead)",
        frames: 0,
        run: |w| w.measure(|| 0),
    },
    Workload {
        name: "model: 3 axes 26->16 bit (XY3 -> XY2)",
        frames: FRAMES as u32,
        run: |w| with_random_words(w, |input| narrow_axes(input, 26, 16, 3)),
    },
    Workload {
        name: "model: 3 axes 16->26 bit (XY2 -> XY3)",
        frames: FRAMES as u32,
        run: |w| with_random_words(w, |input| narrow_axes(input, 16, 26, 3)),
    },
    Workload {
        name: "model: 3 axes 20->18 bit (HANS -> XY2-100E)",
        frames: FRAMES as u32,
        run: |w| with_random_words(w, |input| narrow_axes(input, 20, 18, 3)),
    },
    Workload {
        name: "model: ForwardFrame 5 axes 26->20 + invert",
        frames: FRAMES as u32,
        run: |w| with_random_words(w, forward_frame_5_axes),
    },
];

/// Runs `work` in the window on fixed-seed random words, so every run measures the
/// same data.
fn with_random_words(w: &mut Window, work: fn(&Input) -> u32) -> u32 {
    let mut input: Input = [[0; WORDS]; FRAMES];
    let mut rng = Prng::new(0x5EED_1234);
    for frame in input.iter_mut() {
        for word in frame.iter_mut() {
            *word = rng.next_u32();
        }
    }
    let input = black_box(input);
    w.measure(|| work(&input))
}

/// Each frame: `axes` positions arrive at `from` bits and leave at `to` bits.
fn narrow_axes(input: &Input, from: u8, to: u8, axes: usize) -> u32 {
    let mask = (1u32 << from) - 1;
    let mut sum = 0u32;
    for frame in input {
        for &word in frame.iter().take(axes) {
            sum = match Position::from_raw(word & mask, from) {
                Ok(p) => sum.wrapping_add(p.to_raw(to)),
                Err(_) => sum.wrapping_add(1),
            };
        }
    }
    sum
}

/// Each frame: a 26-bit 5-axis [`ForwardFrame`] is built, each axis inverted and
/// re-expressed at 20 bits.
fn forward_frame_5_axes(input: &Input) -> u32 {
    let mut sum = 0u32;
    for words in input {
        let mut frame = ForwardFrame::default();
        for (slot, &word) in frame.axes.iter_mut().zip(words) {
            *slot = Position::from_raw(word >> 6, 26).ok();
        }
        for axis in Axis::ALL {
            if let Some(p) = frame.axis(axis) {
                sum = sum.wrapping_add(p.inverted().to_raw(20));
            }
        }
    }
    sum
}
