//! The head-side waveform encoder of the bridge loop: the board's head-side port-D
//! wiring and timing (`shared::head_port`, which the host pipeline encodes with too)
//! around `shared::bridge::head_out`, which turns the bridge's neutral frames into
//! BSRR words of one frame slot.

use shared::bridge::head_out::HeadTx;
use shared::bridge::{Config, Protocol, ZSource};
use shared::head_port::{self, PAIR_BITS, XY3_PINS};
use shared::model::ForwardFrame;
use shared::{xy2, xy3};

use crate::config::{Head, BAKED_ROLES};

/// Idle BSRR word: every output low (reset half), except XY3's SYNC, which idles high
/// (`layouts.md` §4; XY2's SYNC idles low like every other line). It pre-fills the
/// ring before the first batch.
pub(super) fn idle_word(head: Head) -> u32 {
    let resets = PAIR_BITS.iter().fold(0u32, |w, b| w | 1 << (b + 16));
    match head {
        Head::Xy3 => {
            let sync = XY3_PINS.sync;
            (resets & !(1 << (sync + 16))) | 1 << sync
        }
        Head::Xy2 | Head::Hans => resets,
    }
}

/// The head-side encoder: neutral frames -> BSRR words of one frame slot
/// ([`HeadTx`], shared with the host pipeline).
pub(super) struct Encoder(HeadTx);

impl Encoder {
    /// The encoder for the configured head, or why there is none.
    pub(super) fn new(config: &Config) -> Result<Encoder, &'static str> {
        let rate = config.output.frame_rate_hz;
        let z = config.z.source != ZSource::None;
        // Only the baked head's transmitter is built (as the controller's receiver,
        // `bridge_core::Core::new`): the other one is then never linked.
        let baked = BAKED_ROLES.head;
        match config.head.protocol {
            Protocol::Xy2 if baked == Head::Xy2 => {
                let h = config.head.xy2;
                let ticks = (head_port::XY2_TICK_HZ / rate.max(1)) as usize;
                let pins = head_port::xy2_pins(z);
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
            Protocol::Xy3 if baked == Head::Xy3 => {
                let size = config.head.xy3.frame_size;
                // Z, U and W each only while it has a value to carry
                // (`Config::xy3_head_lines`).
                let lines = config.xy3_head_lines();
                let tx = xy3::tx::TxConfig {
                    pins: head_port::xy3_pins(lines),
                    size,
                    idle_ticks: head_port::xy3_idle_ticks(size),
                };
                xy3::tx::Transmitter::new(&tx)
                    .map(|tx| Encoder(HeadTx::Xy3 { tx, lines }))
                    .map_err(|_| "XY3-100 transmitter configuration refused")
            }
            Protocol::Hans => Err("HANS-100 head is not a waveform output"),
            Protocol::Xy2 | Protocol::Xy3 => Err("head protocol is not the baked one"),
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
        // A constant (`new` builds only the baked head's transmitter): the other
        // transmitter's encoder is dropped. Never false in practice; it would idle
        // the slot, as `encode` does with a frame the head cannot take.
        let baked = match &self.0 {
            HeadTx::Xy2 { .. } => BAKED_ROLES.head == Head::Xy2,
            HeadTx::Xy3 { .. } => BAKED_ROLES.head == Head::Xy3,
        };
        if baked {
            self.0.encode(frame, slot)
        } else {
            self.0.idle(slot);
            false
        }
    }
}
