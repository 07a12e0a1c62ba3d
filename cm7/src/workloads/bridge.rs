//! Workloads of the bridge engine: one input frame event plus one output slot per
//! frame (translation, supervision, counters), the per-frame work between the
//! receivers and the transmitters.

use super::{Window, Workload, FRAMES};
use crate::tests::prng::Prng;
use core::hint::black_box;
use shared::bridge::{Bridge, Config, Protocol};
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
];

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
