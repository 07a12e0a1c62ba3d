//! Workloads of the HANS-100 line receiver and transmitter: instructions per 10 us
//! frame for each decode mode on clean, realistic sample buffers.
//!
//! The buffers come from a tiny fixed-point line model (no std): random frames sent
//! back to back, sampled at `fs` with an odd start phase and a fixed skew of up to
//! ±1 sample per channel. The receiver first locks and settles on [`WARM_FRAMES`]
//! frames outside the window; the window then decodes [`MEASURED`] frames.

use super::{Window, Workload};
use crate::tests::prng::Prng;
use core::hint::black_box;
use shared::hans::rx::{HansRx, Mode, RxEvent};
use shared::hans::tx::Transmitter;
use shared::hans::{Frame, RING_BYTES};

/// Frames decoded before the window: acquisition (hunt, rate measurement), the
/// young lock that fits its timing on every frame's mid-pair edges (until
/// `shared::hans::rx::timing::YOUNG`) and the settling of the per-channel delays,
/// so the window shows the steady state.
const WARM_FRAMES: usize = 100;
/// Frames decoded inside the window.
const MEASURED: usize = 32;
/// Words per channel for all frames at up to 4x (500 samples per frame), plus slack.
const WORDS: usize = (WARM_FRAMES + MEASURED + 1) * 500 / 16 + 2;

/// Every workload, in the order they run.
pub const WORKLOADS: &[Workload] = &[
    Workload {
        name: "hans rx: normal, 1 ch, 3x (37.5 MHz)",
        frames: MEASURED as u32,
        run: |w| rx(w, 37_500_000, Mode::Normal { channel: 1 }, WHOLE),
    },
    Workload {
        name: "hans rx: normal, 1 ch, 4x (50 MHz)",
        frames: MEASURED as u32,
        run: |w| rx(w, 50_000_000, Mode::Normal { channel: 1 }, WHOLE),
    },
    Workload {
        name: "hans rx: vote3, 3x",
        frames: MEASURED as u32,
        run: |w| {
            rx(
                w,
                37_500_000,
                Mode::Vote3 {
                    channels: [1, 3, 5],
                },
                WHOLE,
            )
        },
    },
    Workload {
        name: "hans rx: vote5, 3x",
        frames: MEASURED as u32,
        run: |w| rx(w, 37_500_000, Mode::Vote5, WHOLE),
    },
    Workload {
        name: "hans rx: super, 5 ch, 3x",
        frames: MEASURED as u32,
        run: |w| rx(w, 37_500_000, Mode::Super, WHOLE),
    },
    Workload {
        name: "hans rx: firmware, normal, 40 MHz, 64-word chunks",
        frames: MEASURED as u32,
        run: |w| rx(w, FW_FS_HZ, Mode::Normal { channel: 1 }, FW_CHUNK),
    },
    Workload {
        name: "hans rx: firmware, super, 40 MHz, 64-word chunks",
        frames: MEASURED as u32,
        run: |w| rx(w, FW_FS_HZ, Mode::Super, FW_CHUNK),
    },
    Workload {
        name: "hans rx: firmware, super, young lock (frames 4..36)",
        frames: MEASURED as u32,
        run: |w| rx_from(w, FW_FS_HZ, Mode::Super, FW_CHUNK, YOUNG_FROM),
    },
    Workload {
        name: "hans rx: STATUS half, new receiver",
        frames: STATUS_FRAMES,
        run: |w| status_half(w, false),
    },
    Workload {
        name: "hans rx: STATUS half, after a skipped half",
        frames: STATUS_FRAMES,
        run: |w| status_half(w, true),
    },
    Workload {
        name: "hans tx: slot update",
        frames: MEASURED as u32,
        run: tx,
    },
];

/// The sample words of five channels and how many of them hold the warm-up frames.
struct Capture {
    words: [[u16; WORDS]; 5],
    len: usize,
    /// Bits per sample, Q16.
    step: u64,
}

impl Capture {
    /// The first word at or after the start of frame `k`.
    fn word_of_frame(&self, k: usize) -> usize {
        (((k as u64 * 125) << 16) / self.step / 16) as usize
    }
}

/// Samples back-to-back random frames at `fs_hz` (Q16 fixed point throughout).
fn capture(fs_hz: u32) -> Capture {
    let mut rng = Prng::new(0x4A45_5300);
    let mut frames = [Frame::CENTRE; WARM_FRAMES + MEASURED + 1];
    for f in frames.iter_mut() {
        *f = Frame::new(rng.bits(20), rng.bits(20), rng.bits(20)).unwrap_or(Frame::CENTRE);
    }
    // Bits per sample, Q16.
    let step = (12_500_000u64 << 16) / u64::from(fs_hz);
    let total_bits = (frames.len() * 125) as u64;
    let mut cap = Capture {
        words: [[0; WORDS]; 5],
        len: 0,
        step,
    };
    // Skew per channel in Q16 bits (about -0.3..+0.3 bit, i.e. about ±1 sample).
    let skews: [u64; 5] = [0x4000, 0x0000, 0x9000, 0x2000, 0x7000];
    let bit_at = |t: u64| -> bool {
        let i = (t >> 16) as usize;
        frames
            .get(i / 125)
            .is_none_or(|f| (f.encode() >> (124 - i % 125)) & 1 == 1)
    };
    let phase = 0x5A3C;
    let mut w = 0;
    while w < WORDS {
        let t_end = phase + (w as u64 * 16 + 16) * step + 0x1_0000;
        if t_end >> 16 >= total_bits {
            break;
        }
        for (c, skew) in skews.iter().enumerate() {
            let mut word = 0u16;
            for k in 0..16u64 {
                let t = (phase + (w as u64 * 16 + k) * step + 0x1_0000).saturating_sub(*skew);
                word = word << 1 | u16::from(bit_at(t));
            }
            cap.words[c][w] = word;
        }
        w += 1;
    }
    cap.len = w;
    cap
}

/// Decodes the warm-up outside the window, then the measured frames inside it,
/// pushed `chunk` words at a time (`WHOLE`: in one push).
fn rx(w: &mut Window, fs_hz: u32, mode: Mode, chunk: usize) -> u32 {
    rx_from(w, fs_hz, mode, chunk, WARM_FRAMES)
}

/// Frame of the capture at which the young-lock workload starts measuring: the
/// hunt locks within the first two frames, so the window covers the lock's young
/// fit (`shared::hans::rx::timing::YOUNG` frames) and hardly anything after it.
const YOUNG_FROM: usize = 4;

/// [`rx`] with the window starting at frame `first` of the capture and covering
/// [`MEASURED`] frames (up to the capture's end for the steady-state window).
fn rx_from(w: &mut Window, fs_hz: u32, mode: Mode, chunk: usize, first: usize) -> u32 {
    let cap = black_box(capture(fs_hz));
    let Ok(mut rx) = HansRx::new(fs_hz, mode) else {
        return 0;
    };
    let mut sum = 0u32;
    let mut sink = |e: RxEvent| {
        if let RxEvent::Frame(f) = e {
            sum = sum.wrapping_add(f.data1() ^ f.data3()).wrapping_add(1);
        }
    };
    let chunks = |from: usize, to: usize| cap.words.each_ref().map(|c| &c[from..to]);
    let (from, end) = (
        cap.word_of_frame(first),
        cap.word_of_frame(first + MEASURED + 1).min(cap.len),
    );
    rx.push(&chunks(0, from), &mut sink);
    w.measure(|| {
        let mut at = from;
        while at < end {
            let to = at.saturating_add(chunk).min(end);
            rx.push(&chunks(at, to), &mut sink);
            at = to;
        }
    });
    sum
}

/// All measured words in one push.
const WHOLE: usize = usize::MAX;
/// The firmware's HANS-100 controller decoder (`tasks/hans_in.rs`): fs = 40 MHz
/// (TIM3, 3.2 samples per bit) and the words pushed 64 at a time, the chunk
/// `hans_decode` feeds so that each chunk's events reach the bridge at once.
const FW_FS_HZ: u32 = 40_000_000;
/// See [`FW_FS_HZ`].
const FW_CHUNK: usize = 64;

/// Words of a HANS STATUS input half (`firmware/channels.rs` `HANS_HALF`).
const STATUS_HALF: usize = 512;
/// Frame periods of a STATUS half at 40 MHz (20.48), as the window's frame count.
const STATUS_FRAMES: u32 = 20;

/// One SPI6 half of the head's HANS STATUS line as `status::hans_status` decodes
/// it beside a HANS-100 controller (normal mode, channel 1, 40 MHz, the whole half
/// in one push): with `follow`, by a receiver that decoded the three halves before
/// the one skipped (locked and past its young fit) and is told of the skipped one
/// (`HansRx::skip`); without, by a new receiver, as the task did before it
/// followed the signal (and as it does during an acquisition).
fn status_half(w: &mut Window, follow: bool) -> u32 {
    let cap = black_box(capture(FW_FS_HZ));
    let mode = Mode::Normal { channel: 1 };
    let Ok(mut rx) = HansRx::new(FW_FS_HZ, mode) else {
        return 0;
    };
    let mut sum = 0u32;
    let mut sink = |e: RxEvent| {
        if let RxEvent::Frame(f) = e {
            sum = sum.wrapping_add(f.data1() ^ f.data3()).wrapping_add(1);
        }
    };
    let half = |n: usize| [&cap.words[0][n * STATUS_HALF..(n + 1) * STATUS_HALF]];
    if follow {
        for n in 0..3 {
            rx.push(&half(n), &mut sink);
        }
        rx.skip(STATUS_HALF as u32, &mut sink);
    }
    w.measure(|| rx.push(&half(4), &mut sink));
    sum
}

/// One `Transmitter::update` per frame (slot write two ahead of the DMA).
fn tx(w: &mut Window) -> u32 {
    let mut rng = Prng::new(77);
    let mut frames = [Frame::CENTRE; MEASURED];
    for f in frames.iter_mut() {
        *f = Frame::new(rng.bits(20), rng.bits(20), rng.bits(20)).unwrap_or(Frame::CENTRE);
    }
    let frames = black_box(frames);
    let mut ring = [0u8; RING_BYTES];
    let mut t = Transmitter::new();
    let _ = t.park(&mut ring, &Frame::CENTRE);
    w.measure(|| {
        for (k, f) in frames.iter().enumerate() {
            let remaining = RING_BYTES - (k % 8) * 125 / 8;
            let _ = t.update(&mut ring, remaining, f);
        }
    });
    ring.iter().fold(0u32, |a, &b| a.wrapping_add(u32::from(b)))
}
