//! Workloads of the bridge engine: one input frame event plus one output slot per
//! frame (translation, supervision, counters), the per-frame work between the
//! receivers and the transmitters.

use super::{Window, Workload, FRAMES};
use crate::tests::prng::Prng;
use core::hint::black_box;
use shared::bridge::slot_guard::SlotGuard;
use shared::bridge::{Bridge, Config, Protocol};
use shared::hans::frame::{blank_slot, FRAME_BITS, RING_BYTES, RING_SLOTS};
use shared::model::{Axis, ForwardFrame, LineEvent, Position};
use shared::xy3::FrameSize;

/// Every workload, in the order they run.
pub const WORKLOADS: &[Workload] = &[
    Workload {
        name: "bridge: XY2 16 -> XY3 32, event + tick",
        frames: FRAMES as u32,
        run: |w| run(w, xy2_to_xy3()),
    },
    Workload {
        name: "bridge: HANS -> XY2 16, axis map, event + tick",
        frames: FRAMES as u32,
        run: |w| run(w, hans_to_xy2_mapped()),
    },
    Workload {
        name: "slot guard: a run per slot, writer stalled (blank + miss)",
        frames: FRAMES as u32,
        run: slot_guard_runs,
    },
];

/// The HANS-100 head's slot ring guard as its slot timer runs it in the firmware
/// (`drivers/serial_tx.rs` "The slot timer"), one run per 10 us slot ("frame"),
/// 7 bytes into the slot, laps included, with the writer stalled: every run
/// blanks the slot the DMA just left (16 byte stores on the real ring) and counts
/// a miss, the costliest run. Not included: the interrupt's entry and exit, the
/// lock and the NDTR read.
fn slot_guard_runs(w: &mut Window) -> u32 {
    let pos = |k: usize| ((k * FRAME_BITS).div_ceil(8) + 7) % RING_BYTES;
    let mut g = SlotGuard::new();
    let mut ring = [0xA5u8; RING_BYTES];
    // Warm-up outside the window: the writer wrote once, then stalled for a lap.
    g.wrote(2, pos(0));
    for k in 0..2 * RING_SLOTS {
        g.run(pos(k));
    }
    w.measure(|| {
        let mut acc = 0u32;
        for k in 2 * RING_SLOTS..2 * RING_SLOTS + FRAMES {
            let a = g.run(black_box(pos(k)));
            for slot in (0..RING_SLOTS).filter(|s| a.blank & (1 << s) != 0) {
                // In range: `slot` < RING_SLOTS.
                let _ = blank_slot(&mut ring, slot);
            }
            acc = acc.wrapping_add(u32::from(a.blank) + u32::from(a.gate_off));
        }
        black_box(&ring);
        acc.wrapping_add(g.missed())
    })
}

fn xy2_to_xy3() -> Config {
    let mut c = Config::default();
    c.head.protocol = Protocol::Xy3;
    c.head.xy3.frame_size = FrameSize::Bits32;
    c.failsafe.recovery_frames = 1;
    c
}

fn hans_to_xy2_mapped() -> Config {
    let mut c = Config::default();
    c.controller.protocol = Protocol::Hans;
    c.axes.swap_xy = true;
    c.axes.invert_y = true;
    c.axes.offset_x = -100;
    c.failsafe.recovery_frames = 1;
    c
}

/// Feeds [`FRAMES`] random 20-bit X / Y / Z frames at 100 kHz, each followed by
/// its output slot, and sums the X positions sent.
fn run(w: &mut Window, config: Config) -> u32 {
    let mut rng = Prng::new(0xB81D_6E00);
    let mut frames = [ForwardFrame::default(); FRAMES];
    for f in frames.iter_mut() {
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            f.axes[axis.index()] = Position::from_raw(rng.next_u32() >> 12, 20).ok();
        }
    }
    let Ok(mut bridge) = Bridge::new(&config) else {
        return 0;
    };
    // Running before the window: one valid frame (recovery_frames = 1), and the
    // head's status in, so the gate is on as in steady operation.
    bridge.status_seen(0);
    bridge.on_line_event(0, LineEvent::Frame(ForwardFrame::default()));
    let frames = black_box(frames);
    w.measure(|| {
        let mut sum = 0u32;
        let mut t = 10_000u64;
        for f in frames.iter() {
            bridge.on_line_event(t, LineEvent::Frame(*f));
            let out = bridge.tick(t + 5_000);
            if let Some(p) = out.frame.and_then(|f| f.axis(Axis::X)) {
                sum = sum.wrapping_add(p.aligned());
            }
            t += 10_000;
        }
        sum
    })
}
