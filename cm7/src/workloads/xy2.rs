//! Workloads of the XY2-100 line level: the receiver on clean port samples (as the
//! input DMA delivers them) and the transmitter filling BSRR slots.

use super::{Window, Workload, FRAMES};
use crate::tests::prng::Prng;
use core::hint::black_box;
use shared::model::LineEvent;
use shared::xy2::rx::{Event, PinMap, Receiver};
use shared::xy2::tx::{OutPinMap, Transmitter, TxFrame, FRAME_TICKS};
use shared::xy2::{Frame, LinkConfig};

/// Output pins; the bench's "wire" maps them one to one onto the input port.
const OUT: OutPinMap = OutPinMap {
    clk: 0,
    sync: 3,
    x: 5,
    y: 9,
    z: Some(12),
};
const IN: PinMap = PinMap {
    sync: 3,
    x: 5,
    y: 9,
    z: Some(12),
};
/// Samples per frame: back-to-back frames, one sample per bit.
const SAMPLES: usize = 20 * FRAMES;

/// Every workload, in the order they run.
pub const WORKLOADS: &[Workload] = &[
    Workload {
        name: "xy2 rx: 3 channels",
        frames: FRAMES as u32,
        run: |w| receive(w, false),
    },
    Workload {
        name: "xy2 rx: 3 channels + LineEvent",
        frames: FRAMES as u32,
        run: |w| receive(w, true),
    },
    Workload {
        name: "xy2 tx: 3 channels",
        frames: FRAMES as u32,
        run: transmit,
    },
];

fn frames() -> [TxFrame; FRAMES] {
    let mut rng = Prng::new(0x0000_0C72);
    core::array::from_fn(|_| {
        let mut p = || Frame::Position16(rng.bits(16) as u16);
        TxFrame {
            x: p(),
            y: p(),
            z: Some(p()),
        }
    })
}

fn transmitter() -> Transmitter {
    match Transmitter::new(OUT, FRAME_TICKS, LinkConfig::default()) {
        Ok(tx) => tx,
        Err(e) => panic!("bench transmitter: {e}"),
    }
}

/// Plays the transmitter's BSRR words on a port and samples it at every CLK falling
/// edge, as the input timer's DMA would.
fn samples() -> [u16; SAMPLES] {
    let tx = transmitter();
    let mut out = [0u16; SAMPLES];
    let mut port: u16 = 0;
    let mut n = 0;
    let mut slot = [0u32; FRAME_TICKS];
    for f in frames() {
        if tx.write_frame(&mut slot, &f).is_err() {
            panic!("bench frame does not encode");
        }
        for w in slot {
            let next = (port & !((w >> 16) as u16)) | w as u16;
            if port & 1 != 0 && next & 1 == 0 {
                if let Some(s) = out.get_mut(n) {
                    *s = next;
                }
                n += 1;
            }
            port = next;
        }
    }
    out
}

/// Feeds the samples of [`FRAMES`] frames in one call (one DMA half), summing the
/// decoded values; with `neutral`, also converts every event to [`LineEvent`]s.
fn receive(w: &mut Window, neutral: bool) -> u32 {
    // One low sample first: the line was idle before the first frame.
    let mut rx = match Receiver::new(IN, LinkConfig::default()) {
        Ok(rx) => rx,
        Err(e) => panic!("bench receiver: {e}"),
    };
    rx.feed(&[0], &mut |_| {});
    let input = black_box(samples());
    let mut sum = 0u32;
    w.measure(|| {
        rx.feed(&input, &mut |e| {
            if neutral {
                e.line_events(&mut |le| {
                    if let LineEvent::Frame(f) = le {
                        for p in f.axes.iter().flatten() {
                            sum = sum.wrapping_add(p.aligned());
                        }
                    }
                });
            } else if let Event::Frame(p) = e {
                for f in [p.x, p.y].into_iter().chain(p.z).flatten() {
                    if let Frame::Position16(v) = f {
                        sum = sum.wrapping_add(u32::from(v));
                    }
                }
            }
        })
    });
    if rx.counters().frames != FRAMES as u32 {
        panic!("bench receiver lost frames");
    }
    sum
}

/// Encodes [`FRAMES`] frames into a half-buffer of back-to-back slots.
fn transmit(w: &mut Window) -> u32 {
    let tx = transmitter();
    let input = black_box(frames());
    let mut half = [0u32; FRAME_TICKS * FRAMES];
    let ok = w.measure(|| tx.write_half(&mut half, &input).is_ok());
    let half = black_box(half);
    half.iter()
        .fold(u32::from(ok), |a, &x| a.rotate_left(1) ^ x)
}
