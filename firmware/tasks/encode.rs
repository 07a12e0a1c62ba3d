//! The head-side waveform encoder of the bridge loop: the board's head-side port-D
//! wiring and timing around `shared::bridge::head_out`, which turns the bridge's
//! neutral frames into BSRR words of one frame slot.

use shared::bridge::head_out::HeadTx;
use shared::bridge::{Config, Protocol, ZSource};
use shared::model::{Axis, ForwardFrame};
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

/// The head-side encoder: neutral frames -> BSRR words of one frame slot
/// ([`HeadTx`], shared with the host pipeline).
pub(super) struct Encoder(HeadTx);

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
                    .map(|tx| {
                        Encoder(HeadTx::Xy2 {
                            tx,
                            mode: h.mode,
                            z,
                        })
                    })
                    .map_err(|_| "XY2-100 transmitter refused the frame rate")
            }
            Protocol::Xy3 => {
                let size = config.head.xy3.frame_size;
                let idle_ticks = match size {
                    FrameSize::Bits24 => xy3::tx::MIN_IDLE_TICKS,
                    FrameSize::Bits32 => XY3_IDLE_32,
                };
                // Z on pair 5 (PD10), U / W on pairs 7 / 8 (PD14 / PD15), each only
                // while it has a value to carry (`Config::xy3_head_lines`); an
                // undriven pair stays low.
                let lines = config.xy3_head_lines();
                let pin = |axis: Axis, bit: u8| lines.has(axis).then_some(bit);
                let pins = xy3::tx::OutPinMap {
                    clk: 1,
                    sync: 0,
                    data: [
                        Some(2),
                        Some(3),
                        pin(Axis::Z, 10),
                        pin(Axis::U, 14),
                        pin(Axis::W, 15),
                    ],
                };
                let tx = xy3::tx::TxConfig {
                    pins,
                    size,
                    idle_ticks,
                };
                xy3::tx::Transmitter::new(&tx)
                    .map(|tx| Encoder(HeadTx::Xy3 { tx, lines }))
                    .map_err(|_| "XY3-100 transmitter configuration refused")
            }
            Protocol::Hans => Err("HANS-100 head is not a waveform output"),
        }
    }

    pub(super) fn ticks_per_frame(&self) -> usize {
        self.0.ticks_per_frame()
    }

    /// The timer tick rate for `rate` frames per second.
    pub(super) fn tick_hz(&self, rate: u32) -> u32 {
        let ticks = self.ticks_per_frame() as u64;
        u32::try_from(ticks.saturating_mul(u64::from(rate))).unwrap_or(u32::MAX)
    }

    /// Encodes `frame` into `slot`, or idles the slot for `None` and for a frame the
    /// head cannot take (see [`HeadTx::encode`]). Returns whether a frame was written.
    pub(super) fn encode(&self, frame: Option<&ForwardFrame>, slot: &mut [u32]) -> bool {
        self.0.encode(frame, slot)
    }
}
