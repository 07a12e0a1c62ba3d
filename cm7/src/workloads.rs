//! Bench workloads: one function per per-frame job the firmware does, run over
//! [`FRAMES`] frames of prepared input so the count per frame is an average over
//! varied data. To add a workload (a receiver, an encoder, the bridge step), write a
//! `prepare` that fills the input words and a `run` that processes every frame and
//! folds its results into the returned checksum (so nothing is optimised away), then
//! list it in [`ALL`].

use crate::tests::prng::Prng;
use shared::model::{Axis, ForwardFrame, Position};

/// Frames per window.
pub const FRAMES: usize = 64;
/// Input words per frame; each workload decides what they mean.
pub const WORDS: usize = 5;
/// The input of one window: [`WORDS`] words for each of [`FRAMES`] frames.
pub type Input = [[u32; WORDS]; FRAMES];

/// One measured job.
pub struct Workload {
    /// Name printed in the table.
    pub name: &'static str,
    /// Frames the window processes (0: the empty calibration window).
    pub frames: u32,
    /// Fills the input; runs outside the window.
    pub prepare: fn(&mut Input),
    /// The measured work; returns a checksum of its results.
    pub run: fn(&Input) -> u32,
}

/// Every workload, in the order they run. The first one must stay the empty window.
pub const ALL: &[Workload] = &[
    Workload {
        name: "(call overhead)",
        frames: 0,
        prepare: random_words,
        run: |_| 0,
    },
    Workload {
        name: "model: 3 axes 26->16 bit (XY3 -> XY2)",
        frames: FRAMES as u32,
        prepare: random_words,
        run: |input| narrow_axes(input, 26, 16, 3),
    },
    Workload {
        name: "model: 3 axes 16->26 bit (XY2 -> XY3)",
        frames: FRAMES as u32,
        prepare: random_words,
        run: |input| narrow_axes(input, 16, 26, 3),
    },
    Workload {
        name: "model: 3 axes 20->18 bit (HANS -> XY2-100E)",
        frames: FRAMES as u32,
        prepare: random_words,
        run: |input| narrow_axes(input, 20, 18, 3),
    },
    Workload {
        name: "model: ForwardFrame 5 axes 26->20 + invert",
        frames: FRAMES as u32,
        prepare: random_words,
        run: forward_frame_5_axes,
    },
];

/// Fixed-seed random words, so every run measures the same data.
fn random_words(input: &mut Input) {
    let mut rng = Prng::new(0x5EED_1234);
    for frame in input.iter_mut() {
        for word in frame.iter_mut() {
            *word = rng.next_u32();
        }
    }
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
