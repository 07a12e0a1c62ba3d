//! The head-side waveform encoder of the bridge loop: the bridge's neutral frames ->
//! BSRR words of one frame slot (`shared::xy2::tx` / `shared::xy3::tx`), and the
//! board's head-side port-D wiring.

use shared::bridge::{Config, Protocol, ZSource};
use shared::model::{Axis, ForwardFrame};
use shared::xy3::neutral::{command_frame, position_frame};
use shared::xy3::FrameSize;
use shared::{xy2, xy3};

use crate::config::Head;

/// Port-D bit of each head-side pair (board wiring).
const PAIR_BITS: [u32; 7] = [0, 1, 2, 3, 10, 14, 15];
/// Pair index (0-based) carrying XY3's SYNC (pair 1; XY2's SYNC on pair 2 idles low
/// like every other line).
const XY3_SYNC_PAIR: usize = 0;

/// Idle BSRR word: every output low (reset half), except XY3's SYNC, which idles high
/// (`layouts.md` §4). It pre-fills the ring before the first batch.
pub(super) fn idle_word(head: Head) -> u32 {
    let resets = PAIR_BITS.iter().fold(0u32, |w, b| w | 1 << (b + 16));
    match head {
        Head::Xy3 => {
            let sync = PAIR_BITS[XY3_SYNC_PAIR];
            (resets & !(1 << (sync + 16))) | 1 << sync
        }
        Head::Xy2 | Head::Hans => resets,
    }
}

/// Ticks per XY2-100 bit: two (layouts.md §4).
const XY2_TICKS_PER_BIT: u32 = 2;
/// XY2-100 bit clock.
const XY2_BIT_HZ: u32 = 2_000_000;
/// Idle ticks after a 32-bit XY3-100 frame: 64 + 16 = 80 ticks make 8 MHz at 100 kHz,
/// an exact division of the 240 MHz timer clock (24-bit frames: the minimum, 50 ticks
/// = 5 MHz, already exact).
const XY3_IDLE_32: u8 = 16;

/// The head-side encoder: neutral frames -> BSRR words of one frame slot.
pub(super) enum Encoder {
    /// XY2-100 with the head's position mode; `z` = the Z line is driven.
    Xy2(xy2::tx::Transmitter, xy2::Mode, bool),
    /// XY3-100 with the head's frame size; `z` = the Z line is driven.
    Xy3(xy3::tx::Transmitter, FrameSize, bool),
}

impl Encoder {
    /// The encoder for the configured head, or why there is none.
    pub(super) fn new(config: &Config) -> Result<Encoder, &'static str> {
        let rate = config.output.frame_rate_hz;
        let z = config.z.source != ZSource::None;
        match config.head.protocol {
            Protocol::Xy2 => {
                let h = config.head.xy2;
                let tick_hz = XY2_BIT_HZ * XY2_TICKS_PER_BIT;
                let ticks = (tick_hz / rate.max(1)) as usize;
                let pins = xy2::tx::OutPinMap {
                    clk: 0,
                    sync: 1,
                    x: 2,
                    y: 3,
                    z: z.then_some(10),
                };
                let link = xy2::LinkConfig {
                    mode: h.mode,
                    parity: h.parity,
                };
                xy2::tx::Transmitter::new(pins, ticks, link)
                    .map(|t| Encoder::Xy2(t, h.mode, z))
                    .map_err(|_| "XY2-100 transmitter refused the frame rate")
            }
            Protocol::Xy3 => {
                let size = config.head.xy3.frame_size;
                let idle_ticks = match size {
                    FrameSize::Bits24 => xy3::tx::MIN_IDLE_TICKS,
                    FrameSize::Bits32 => XY3_IDLE_32,
                };
                let pins = xy3::tx::OutPinMap {
                    clk: 1,
                    sync: 0,
                    data: [Some(2), Some(3), z.then_some(10), None, None],
                };
                let tx = xy3::tx::TxConfig {
                    pins,
                    size,
                    idle_ticks,
                };
                xy3::tx::Transmitter::new(&tx)
                    .map(|t| Encoder::Xy3(t, size, z))
                    .map_err(|_| "XY3-100 transmitter configuration refused")
            }
            Protocol::Hans => Err("HANS-100 head is not a waveform output"),
        }
    }

    pub(super) fn ticks_per_frame(&self) -> usize {
        match self {
            Encoder::Xy2(t, ..) => t.ticks_per_frame(),
            Encoder::Xy3(t, ..) => t.ticks_per_frame(),
        }
    }

    /// The timer tick rate for `rate` frames per second.
    pub(super) fn tick_hz(&self, rate: u32) -> u32 {
        let ticks = self.ticks_per_frame() as u64;
        u32::try_from(ticks.saturating_mul(u64::from(rate))).unwrap_or(u32::MAX)
    }

    /// Encodes `frame` into `slot`, or idles the slot for `None` and for a frame the
    /// head cannot take (an axis without a position): the head then sees no frame in
    /// this slot rather than a guessed one. Returns whether a frame was written.
    pub(super) fn encode(&self, frame: Option<&ForwardFrame>, slot: &mut [u32]) -> bool {
        match self {
            Encoder::Xy2(t, mode, z) => {
                let f = frame.and_then(|f| {
                    let pos = |a: Axis| f.axis(a).map(|p| xy2::Frame::from_position(p, *mode));
                    // A command rides on X in place of the position (XY2-100 enhanced).
                    let x = f
                        .command
                        .and_then(xy2::Frame::from_command)
                        .or(pos(Axis::X))?;
                    // A driven Z line needs a Z frame: all-zero bits would be an
                    // invalid frame on the head's Z channel.
                    let z = if *z { Some(pos(Axis::Z)?) } else { None };
                    Some(xy2::tx::TxFrame {
                        x,
                        y: pos(Axis::Y)?,
                        z,
                    })
                });
                match f {
                    Some(f) => t.write_frame(slot, &f).is_ok(),
                    None => {
                        slot.fill(t.idle_word());
                        false
                    }
                }
            }
            Encoder::Xy3(t, size, z) => {
                let frames = frame.and_then(|f| {
                    let pos = |a: Axis| f.axis(a).map(|p| position_frame(p, *size));
                    let x = match f.command {
                        Some(c) => command_frame(&c, *size).ok(),
                        None => pos(Axis::X),
                    }?;
                    let zf = if *z { Some(pos(Axis::Z)?) } else { None };
                    Some([Some(x), Some(pos(Axis::Y)?), zf, None, None])
                });
                if let Some(fr) = frames {
                    if t.encode(&fr, slot).is_ok() {
                        return true;
                    }
                }
                // `slot` is exactly one frame period long, which is all `idle` checks.
                let _ = t.idle(slot);
                false
            }
        }
    }
}
