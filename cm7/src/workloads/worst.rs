//! The worst path of issue 4's budget as one workload: per 10 us frame, the HANS-100
//! receiver in super mode on 5 channels sampled at 3x, the bridge engine (HANS-100
//! controller -> XY3-100 32-bit head, axis map on), the XY3-100 32-bit encoder and the
//! XY2-100 encoder, chained as the firmware chains them. This is the figure the 1200
//! instruction budget applies to.
//!
//! The sample rings come from a small line model of their own (random frames back to
//! back, 3 samples per bit, a different sub-bit skew per channel), and the receiver is
//! fed one frame period's words per call, as a per-frame DMA interrupt would. Each
//! call is followed by one output slot: `Bridge::tick`, then the firmware's head
//! encoder (`shared::bridge::head_out::HeadTx`) fills the BSRR slots of both links
//! from the head frame.

use super::{Window, Workload};
use crate::tests::prng::Prng;
use core::hint::black_box;
use shared::bridge::head_out::HeadTx;
use shared::bridge::{Bridge, Config, HansDecode, Protocol};
use shared::hans::rx::{HansRx, Mode, RxEvent};
use shared::hans::Frame;
use shared::model::ForwardFrame;
use shared::xy2::tx::{OutPinMap as Xy2Pins, Transmitter as Xy2Tx, FRAME_TICKS};
use shared::xy2::{LinkConfig, Mode as Xy2Mode};
use shared::xy3::rx::Lines;
use shared::xy3::tx::{OutPinMap as Xy3Pins, Transmitter as Xy3Tx, TxConfig};
use shared::xy3::FrameSize;

/// Sample rate: 3 samples per bit, the slowest the receiver accepts.
const FS_HZ: u32 = 37_500_000;
/// Samples per frame at 3x (125 bits).
const FRAME_SAMPLES: usize = 375;
/// Frames decoded before the window (acquisition, including the receiver's young
/// lock, which publishes nothing for its first frames and fits its timing on every
/// frame's mid-pair edges until `shared::hans::rx::timing::YOUNG`, and bridge
/// recovery): the window measures the steady state.
const WARM_FRAMES: usize = 100;
/// Frame periods inside the window.
const MEASURED: usize = 32;
/// Words per channel for every frame plus one spare frame.
const WORDS: usize = (WARM_FRAMES + MEASURED + 1) * FRAME_SAMPLES / 16 + 1;
/// XY3-100 idle ticks (the minimum: 66 ticks per 32-bit frame).
const XY3_IDLE: u8 = 2;

/// Every workload, in the order they run.
pub const WORKLOADS: &[Workload] = &[Workload {
    name: "worst path: hans super 5ch 3x + bridge + xy3 32 + xy2",
    frames: MEASURED as u32,
    run,
}];

/// Five channels of samples: random frames sent back to back from sample 0, each
/// channel delayed by its own fraction of a bit (skew up to 2/3 bit = 2 samples).
fn rings() -> [[u16; WORDS]; 5] {
    let mut rng = Prng::new(0x0057_0257);
    let mut frames = [0u128; WARM_FRAMES + MEASURED + 1];
    for f in frames.iter_mut() {
        *f = Frame::new(rng.bits(20), rng.bits(20), rng.bits(20))
            .unwrap_or(Frame::CENTRE)
            .encode();
    }
    // The idle line is high (stop bits); a sample's bit index is (s - skew) / 3.
    let level = |s: usize| -> bool {
        let bit = s / 3;
        frames
            .get(bit / 125)
            .is_none_or(|f| f >> (124 - bit % 125) & 1 == 1)
    };
    let skews = [1usize, 0, 2, 1, 0];
    let mut rings = [[0u16; WORDS]; 5];
    for (ring, skew) in rings.iter_mut().zip(skews) {
        for (w, word) in ring.iter_mut().enumerate() {
            for k in 0..16 {
                let s = (w * 16 + k).checked_sub(skew);
                *word = *word << 1 | u16::from(s.is_none_or(level));
            }
        }
    }
    rings
}

fn config() -> Config {
    let mut c = Config::default();
    c.controller.protocol = Protocol::Hans;
    c.controller.hans.decode = HansDecode::Super;
    c.head.protocol = Protocol::Xy3;
    c.head.xy3.frame_size = FrameSize::Bits32;
    c.axes.swap_xy = true;
    c.axes.invert_y = true;
    c.axes.offset_x = -100;
    c.failsafe.recovery_frames = 1;
    c
}

/// The per-frame state of the chain.
struct Chain {
    rx: HansRx,
    bridge: Bridge,
    xy3: HeadTx,
    xy2: HeadTx,
    xy3_slot: [u32; 66],
    xy2_slot: [u32; FRAME_TICKS],
    /// Output slots that carried a frame on both links.
    sent: u32,
    /// Checksum of the encoded words.
    sum: u32,
}

impl Chain {
    fn new() -> Option<Chain> {
        let xy3 = Xy3Tx::new(&TxConfig {
            pins: Xy3Pins {
                clk: 0,
                sync: 1,
                data: [Some(2), Some(4), Some(6), None, None],
            },
            size: FrameSize::Bits32,
            idle_ticks: XY3_IDLE,
        })
        .ok()?;
        let xy2 = Xy2Tx::new(
            Xy2Pins {
                clk: 8,
                sync: 9,
                x: 10,
                y: 11,
                z: Some(12),
            },
            FRAME_TICKS,
            LinkConfig::default(),
        )
        .ok()?;
        Some(Chain {
            rx: HansRx::new(FS_HZ, Mode::Super).ok()?,
            // The head's status in: the gate is on as in steady operation.
            bridge: {
                let mut b = Bridge::new(&config()).ok()?;
                b.status_seen(0);
                b
            },
            xy3: HeadTx::Xy3 {
                tx: xy3,
                lines: Lines::XYZ,
            },
            xy2: HeadTx::Xy2 {
                tx: xy2,
                mode: Xy2Mode::Standard16,
                z: true,
            },
            xy3_slot: [0; 66],
            xy2_slot: [0; FRAME_TICKS],
            sent: 0,
            sum: 0,
        })
    }

    /// One frame period: the receiver's share of the rings, its events into the
    /// bridge, then one output slot on both encoders.
    fn period(&mut self, chunks: &[&[u16]; 5], now_ns: u64) {
        let bridge = &mut self.bridge;
        self.rx.push(chunks, &mut |e: RxEvent| {
            bridge.on_line_event(now_ns, e.to_line_event());
        });
        let out = self.bridge.tick(now_ns);
        if let Some(f) = out.frame {
            if self.encode(&f) {
                self.sent += 1;
            }
        }
    }

    /// Encodes the head frame on both links with the firmware's own head encoder
    /// (`shared::bridge::head_out`, the code `firmware/tasks/encode.rs` runs, with
    /// its command and Z checks); false if either link idled the slot.
    fn encode(&mut self, f: &ForwardFrame) -> bool {
        let xy3_ok = self.xy3.encode(Some(f), &mut self.xy3_slot);
        let xy2_ok = self.xy2.encode(Some(f), &mut self.xy2_slot);
        let (a, b) = black_box((&self.xy3_slot, &self.xy2_slot));
        self.sum = self.sum.rotate_left(3) ^ a[1] ^ a[63] ^ b[0] ^ b[39];
        xy3_ok && xy2_ok
    }
}

/// Runs the warm-up outside the window, then [`MEASURED`] frame periods inside it.
fn run(w: &mut Window) -> u32 {
    let rings = black_box(rings());
    let Some(mut chain) = Chain::new() else {
        return 0;
    };
    // Frame period k ends at word boundary (k + 1) * 375 / 16 (rounded down).
    let end = |k: usize| ((k + 1) * FRAME_SAMPLES / 16).min(WORDS);
    let chunks = |from: usize, to: usize| rings.each_ref().map(|r| r.get(from..to).unwrap_or(&[]));
    for k in 0..WARM_FRAMES {
        let from = if k == 0 { 0 } else { end(k - 1) };
        chain.period(&chunks(from, end(k)), (k as u64 + 1) * 10_000);
    }
    let warm_sent = chain.sent;
    let warm = *chain.bridge.counters();
    w.measure(|| {
        for k in WARM_FRAMES..WARM_FRAMES + MEASURED {
            chain.period(&chunks(end(k - 1), end(k)), (k as u64 + 1) * 10_000);
        }
    });
    // Every measured period must have carried a frame on both links, or the figure
    // would not be the worst path.
    let c = chain.bridge.counters();
    let (sent, decoded) = (chain.sent - warm_sent, c.frames_ok - warm.frames_ok);
    let idle = (c.repeated - warm.repeated) + (c.skipped - warm.skipped);
    if sent != MEASURED as u32 || decoded != MEASURED as u64 || idle != 0 {
        panic!(
            "worst path: {sent} sent, {decoded} decoded, {idle} repeated or skipped of {MEASURED}"
        );
    }
    chain.sum
}
