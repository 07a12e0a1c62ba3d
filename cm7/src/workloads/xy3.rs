//! Workloads of the XY3-100 line level: the receiver (SPI byte rings + end positions
//! -> periods -> neutral events), the same with the out-of-step watch the bridge runs
//! on every period, and the BSRR transmitter.

use super::{Window, Workload, FRAMES};
use crate::tests::prng::Prng;
use core::hint::black_box;
use shared::model::{Axis, LineEvent};
use shared::xy3::rx::{Lines, Receiver, WINDOW};
use shared::xy3::step::{StepWatch, CONFIRM_NS, OUT_OF_STEP_NS};
use shared::xy3::tx::{OutPinMap, Transmitter, TxConfig};
use shared::xy3::{encode, Frame, FrameSize};

/// Bytes per 32-bit frame.
const BPF: usize = 4;
/// Frames pushed between polls: one DMA half per line, as the firmware's input task
/// hands them to the bridge (`WINDOW / 2` bytes).
const CHUNK: usize = WINDOW / 2 / BPF;
/// Time of one 32-bit frame at 100 kHz (10 us), for the watch's clock.
const FRAME_NS: u64 = 10_000;

/// Every workload, in the order they run.
pub const WORKLOADS: &[Workload] = &[
    Workload {
        name: "xy3 rx: X Y Z 32-bit, bytes -> periods",
        frames: FRAMES as u32,
        run: |w| receive(w, false),
    },
    Workload {
        name: "xy3 rx: X Y Z 32-bit, bytes -> LineEvents",
        frames: FRAMES as u32,
        run: |w| receive(w, true),
    },
    Workload {
        name: "xy3 rx: X Y Z 32-bit, bytes -> StepWatch -> LineEvents",
        frames: FRAMES as u32,
        run: watched,
    },
    Workload {
        name: "xy3 tx: 3 lines 24-bit -> BSRR",
        frames: FRAMES as u32,
        run: |w| transmit(w, 3, FrameSize::Bits24),
    },
    Workload {
        name: "xy3 tx: 3 lines 32-bit -> BSRR",
        frames: FRAMES as u32,
        run: |w| transmit(w, 3, FrameSize::Bits32),
    },
    Workload {
        name: "xy3 tx: 5 lines 32-bit -> BSRR",
        frames: FRAMES as u32,
        run: |w| transmit(w, 5, FrameSize::Bits32),
    },
];

/// A random 32-bit position frame.
fn frame(rng: &mut Prng) -> Frame {
    Frame::Position32(rng.bits(26))
}

/// A random position frame of `size`.
fn frame_of(size: FrameSize, rng: &mut Prng) -> Frame {
    match size {
        FrameSize::Bits24 => Frame::Position24(rng.bits(20)),
        FrameSize::Bits32 => frame(rng),
    }
}

/// The X, Y, Z byte rings of `FRAMES` random 32-bit position frames as the SPI
/// slaves would hold them, and the frame-end positions (in X bytes) the input task
/// reports with them.
type Input = ([[u8; FRAMES * BPF]; 3], [u32; FRAMES]);

/// The receiver's input (see [`Input`]); the same frames for every receiver workload.
fn input() -> Input {
    let mut rng = Prng::new(0x0C0F_FEE3);
    let mut rings = [[0u8; FRAMES * BPF]; 3];
    for i in 0..FRAMES {
        for ring in rings.iter_mut() {
            let word = encode(&frame(&mut rng)).map_or(0, |(w, _)| w);
            if let Some(dst) = ring.get_mut(i * BPF..(i + 1) * BPF) {
                dst.copy_from_slice(&word.to_be_bytes());
            }
        }
    }
    let mut ends = [0u32; FRAMES];
    for (i, e) in ends.iter_mut().enumerate() {
        *e = ((i + 1) * BPF) as u32;
    }
    black_box((rings, ends))
}

/// Hands the receiver DMA half `c` of every line and its frame ends.
fn push_half(rx: &mut Receiver, (rings, ends): &Input, c: usize) {
    let bytes = c * CHUNK * BPF..(c + 1) * CHUNK * BPF;
    let [x, y, z] = rings;
    let slices = [
        x.get(bytes.clone()).unwrap_or_default(),
        y.get(bytes.clone()).unwrap_or_default(),
        z.get(bytes).unwrap_or_default(),
    ];
    let _ = rx.push_bytes(&slices);
    rx.push_ends(ends.get(c * CHUNK..(c + 1) * CHUNK).unwrap_or_default());
}

/// X's aligned position of a frame event (0 for any other event).
fn x_of(e: LineEvent) -> u32 {
    match e {
        LineEvent::Frame(f) => f.axis(Axis::X).map_or(0, |p| p.aligned()),
        _ => 0,
    }
}

/// `FRAMES` random frames on X, Y, Z as the SPI rings would hold them, then the
/// receiver fed one DMA half at a time (push bytes, push ends, poll until empty).
fn receive(w: &mut Window, events: bool) -> u32 {
    let input = input();
    let mut rx = Receiver::new(Lines::XYZ);
    w.measure(|| {
        let mut sum = 0u32;
        for c in 0..FRAMES / CHUNK {
            push_half(&mut rx, &input, c);
            while let Some(p) = rx.poll() {
                if events {
                    p.for_each_event(|e| sum = sum.wrapping_add(x_of(e)));
                } else if let Some(Some(Ok(Frame::Position32(v)))) = p.lines.first() {
                    sum = sum.wrapping_add(*v);
                }
            }
        }
        sum
    })
}

/// The receive path as the bridge loop runs it (`Xy3Decoder::feed` and `release`):
/// the receiver fed the same halves as [`receive`], every period through
/// [`StepWatch::period`] (each good period held until the next one confirms it),
/// then [`StepWatch::release`] once per half, at the time the half's last frame
/// ended. Every period here is good and directly follows the one before, so the
/// watch releases each on the next; after the last half the release is called once
/// more, [`CONFIRM_NS`] later (the stream stopped), so the last period goes out too
/// and all `FRAMES` frames reach the sum, as in the `LineEvents` workload. Any other
/// event (a `Dropped` fault) would change the sum.
fn watched(w: &mut Window) -> u32 {
    let input = input();
    let mut rx = Receiver::new(Lines::XYZ);
    let mut watch = StepWatch::new(OUT_OF_STEP_NS);
    w.measure(|| {
        let mut sum = 0u32;
        let mut now_ns = 0u64;
        for c in 0..FRAMES / CHUNK {
            push_half(&mut rx, &input, c);
            now_ns += CHUNK as u64 * FRAME_NS;
            while let Some(p) = rx.poll() {
                // A restart (never asked for on this clean input) would cost the
                // firmware a signal to the input task; count it so it is not lost.
                if watch.period(now_ns, &p, |e| sum = sum.wrapping_add(x_of(e))) {
                    sum = sum.wrapping_add(1);
                }
            }
            watch.release(now_ns, |e| sum = sum.wrapping_add(x_of(e)));
        }
        watch.release(now_ns + CONFIRM_NS, |e| sum = sum.wrapping_add(x_of(e)));
        sum
    })
}

/// `FRAMES` periods of random frames of `size` on `lines` lines encoded into BSRR
/// words (the minimum idle: 50 / 66 ticks per period).
fn transmit(w: &mut Window, lines: usize, size: FrameSize) -> u32 {
    let mut data = [None; 5];
    for (i, d) in data.iter_mut().enumerate().take(lines) {
        *d = Some(i as u8 * 2 + 2);
    }
    let config = TxConfig {
        pins: OutPinMap {
            clk: 0,
            sync: 1,
            data,
        },
        size,
        idle_ticks: 2,
    };
    let Ok(tx) = Transmitter::new(&config) else {
        return 0;
    };
    let mut rng = Prng::new(0x7A_57A5);
    let mut input = [[None; 5]; FRAMES];
    for period in input.iter_mut() {
        for slot in period.iter_mut().take(lines) {
            *slot = Some(frame_of(size, &mut rng));
        }
    }
    let input = black_box(input);
    let mut out = [0u32; 66];
    w.measure(|| {
        let mut sum = 0u32;
        for period in input.iter() {
            if tx.encode(period, &mut out).is_ok() {
                // Two words are enough to keep the work; `black_box` keeps the stores.
                let out = black_box(&mut out);
                sum = sum.wrapping_add(out[1] ^ out[47]);
            }
        }
        sum
    })
}
