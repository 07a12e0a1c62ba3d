//! XY2-100 STATUS word towards the controller (`controller.xy2.status = "word"`):
//! after every sampler half, `line::xy2_in` hands the half to
//! [`StatusWordOut::refresh`] (frame phase + ring writes, see that driver) with the
//! frame of the word to send now:
//! `channels::CTRL_STATUS_WORD`, the bridge's `xy2_status_word` of its last batch;
//! "input lost" (bit 7 = 0) while the supervisor sees no valid input or the bridge
//! has published nothing yet (a stalled bridge cannot report itself), like the level
//! output. It runs in the high-priority line task because the phase comes from the
//! halves and the writes must land well before the DMA plays them.

use core::sync::atomic::Ordering;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::watch::AnonReceiver;
use shared::bridge::Xy2Controller;
use shared::model::Alarms;
use shared::xy2::status_line::StatusOut;
use shared::xy2::{LinkConfig, StatusLevel, StatusWord};

use crate::channels::{Health, CTRL_STATUS_WORD, HEALTH};
use crate::drivers::status_word_out::{StatusWordOut, FRAME_BITS};

/// Port bit of the controller-side STATUS driver input (PA0, board wiring).
const STATUS_PIN: u8 = 0;
/// Port-G bit of the XY2 SYNC input (PG0, board wiring; `bridge_core::xy2_in_pins`).
pub(super) const SYNC_BIT: u8 = 0;

/// The idle word of the STATUS ring before the first phase is known: the pin low.
pub(super) fn idle_word() -> u32 {
    1 << (u32::from(STATUS_PIN) + 16)
}

/// The controller-side STATUS word source.
pub(super) struct CtrlWord {
    out: StatusWordOut<'static>,
    encoder: StatusOut,
    link: LinkConfig,
    health: AnonReceiver<'static, CriticalSectionRawMutex, Health, 1>,
}

impl CtrlWord {
    /// The source for `out` with the controller link `c`.
    pub(super) fn new(out: StatusWordOut<'static>, c: Xy2Controller) -> Result<Self, &'static str> {
        let encoder = StatusOut::new(
            STATUS_PIN,
            StatusLevel {
                polarity: c.polarity,
            },
        )
        .map_err(|_| "status pin refused")?;
        Ok(CtrlWord {
            out,
            encoder,
            link: LinkConfig {
                mode: c.mode,
                parity: c.parity,
            },
            health: HEALTH.anon_receiver(),
        })
    }

    /// After a sampler half (`start`: its sampler ring index, if known).
    pub(super) fn after_half(&mut self, half: &[u16], start: Option<usize>) {
        let mut words = [0u32; FRAME_BITS];
        let word = self.word();
        self.encoder.word_frame(word, &self.link, &mut words);
        self.out.refresh(half, start, &words);
    }

    /// The word to send now (module docs).
    fn word(&mut self) -> StatusWord {
        let healthy = self.health.try_get().is_some_and(|h| h.input_valid);
        let published = CTRL_STATUS_WORD.load(Ordering::Relaxed);
        match u16::try_from(published).ok().map(StatusWord::from_word) {
            Some(Ok(w)) if healthy => w,
            _ => StatusWord::from_alarms(Alarms::INPUT_LOST),
        }
    }
}
