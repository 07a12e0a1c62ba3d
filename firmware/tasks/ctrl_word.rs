//! XY2-100 STATUS word towards the controller (`controller.xy2.status = "word"`):
//! keeps the [`StatusWordOut`] ring filled with back-to-back status frames of the
//! word the bridge reports, aligned to the controller's frames. Run by `line::xy2_in`
//! after every sampler half (high priority), because the frame phase comes from those
//! halves and a refill must land well before the DMA plays it.
//!
//! * **Phase**: the newest well-formed frame end in the half (SYNC high for exactly 19
//!   samples, then low: `shared::xy2::rx`'s framing) gives the edge whose falling edge
//!   the status frame's first bit (bit 19) is written on; the controller reads it one
//!   edge later, with the first bit of its next frame (bridge-sim's
//!   `status_word_signal` does the same). Its status ring index follows from the
//!   sampler index (`drivers::status_word_out`, "Ring length and frame alignment").
//!   A half whose position is unknown (after a sampler overrun that could not be
//!   resynchronised) or that is more than half a ring old keeps the last phase.
//! * **Word**: `channels::CTRL_STATUS_WORD`, the bridge's `xy2_status_word` of its
//!   last batch; "input lost" (bit 7 = 0) while the supervisor sees no valid input or
//!   the bridge has published nothing yet (a stalled bridge cannot report itself),
//!   like the level output.
//! * **Writes**: only when the word or the phase changed, whole frames at least
//!   `GUARD` edges ahead of the DMA, so a frame is never played half old, half new;
//!   the frames that were too close to the DMA are written after the next half.
//!   Frames sent while the phase changes (the controller paused mid-frame, or runs
//!   its clock between frames) are broken: the controller's own check rejects them.

use core::sync::atomic::Ordering;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::watch::AnonReceiver;
use shared::bridge::Xy2Controller;
use shared::model::Alarms;
use shared::xy2::status_line::StatusOut;
use shared::xy2::{LinkConfig, StatusLevel, StatusWord};

use crate::channels::{Health, CTRL_STATUS_WORD, HEALTH};
use crate::drivers::status_word_out::{StatusWordOut, FRAME_BITS, GUARD};

/// Port bit of the controller-side STATUS driver input (PA0, board wiring).
pub(super) const STATUS_PIN: u8 = 0;
/// Port-G bit of the XY2 SYNC input (PG0, board wiring; `bridge_core::xy2_in_pins`).
const SYNC_BIT: u16 = 1 << 0;
/// High SYNC samples of a well-formed frame.
const SYNC_HIGH: usize = 19;

/// The idle word of the STATUS ring before the first phase is known: the pin low.
pub(super) fn idle_word() -> u32 {
    1 << (u32::from(STATUS_PIN) + 16)
}

/// What the ring holds: the frame words and the phase (status ring index mod 20 of
/// a frame's first bit).
#[derive(Clone, Copy, PartialEq, Eq)]
struct Content {
    words: [u32; FRAME_BITS],
    phase: usize,
}

/// Ring sweeps after a change: the first leaves out the frames near the DMA, the
/// second (at least [`SWEEP_APART`] edges later) writes those.
const SWEEPS: u8 = 2;
/// Edges between the two sweeps, so that the frames the first left out are out of
/// the second's guard.
const SWEEP_APART: usize = GUARD + 2 * FRAME_BITS;

/// The controller-side STATUS word writer.
pub(super) struct CtrlWord {
    out: StatusWordOut<'static>,
    encoder: StatusOut,
    link: LinkConfig,
    health: AnonReceiver<'static, CriticalSectionRawMutex, Health, 1>,
    /// Phase of the controller's frames (status ring index mod 20), once found.
    phase: Option<usize>,
    /// The content the ring is being brought to.
    content: Option<Content>,
    /// Sweeps still due for `content`, and where the DMA was at the last one.
    sweeps_due: u8,
    last_sweep: usize,
}

impl CtrlWord {
    /// The writer for `out` with the controller link `c`.
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
            phase: None,
            content: None,
            sweeps_due: 0,
            last_sweep: 0,
        })
    }

    /// After a sampler half: `half` are its samples, `start` its sampler ring index
    /// (`None` if unknown) in a ring of `sampler_len` samples.
    pub(super) fn after_half(&mut self, half: &[u16], start: Option<usize>, sampler_len: usize) {
        let ring = self.out.len();
        let p = self.out.position();
        if let (Some(start), Some(end)) = (start, frame_end(half)) {
            // Edges since the half's last sample and since the frame end; both are
            // below a sampler ring while the half is fresh.
            let half_end = (start + half.len()) % sampler_len;
            let since_half = (p + sampler_len - half_end) % sampler_len;
            if since_half < sampler_len / 2 {
                let since_end = since_half + half.len() - end;
                let phase = (p + ring - since_end % ring) % FRAME_BITS;
                self.phase = Some(phase);
            }
        }
        let Some(phase) = self.phase else { return };
        let mut words = [0u32; FRAME_BITS];
        let word = self.word();
        self.encoder.word_frame(word, &self.link, &mut words);
        let want = Content { words, phase };
        if self.content != Some(want) {
            self.content = Some(want);
            self.sweeps_due = SWEEPS;
        }
        let apart = (p + ring - self.last_sweep) % ring;
        if self.sweeps_due == SWEEPS || (self.sweeps_due > 0 && apart >= SWEEP_APART) {
            self.sweep(want, p);
            self.last_sweep = p;
            self.sweeps_due -= 1;
        }
    }

    /// The word to send now (module docs).
    fn word(&mut self) -> StatusWord {
        let healthy = self
            .health
            .try_get()
            .is_some_and(|h| h.input_valid && !h.fault);
        let published = CTRL_STATUS_WORD.load(Ordering::Relaxed);
        match u16::try_from(published).ok().map(StatusWord::from_word) {
            Some(Ok(w)) if healthy => w,
            _ => StatusWord::from_alarms(Alarms::INPUT_LOST),
        }
    }

    /// Writes `c` into every whole frame slot from `GUARD` edges ahead of the DMA (at
    /// `p`) up to where it would lap: the frames the DMA plays next are left as they
    /// are (a frame is never changed while it may be playing).
    fn sweep(&mut self, c: Content, p: usize) {
        let ring = self.out.len();
        // Offsets from `p`; the first frame start at or after GUARD.
        let mut k = GUARD + (c.phase + FRAME_BITS - (p + GUARD) % FRAME_BITS) % FRAME_BITS;
        while k + FRAME_BITS <= ring {
            self.out.write_frame((p + k) % ring, &c.words);
            k += FRAME_BITS;
        }
    }
}

/// Index in `half` of the newest well-formed frame end (SYNC low after exactly 19
/// high samples that follow a low one), scanning back from the end.
fn frame_end(half: &[u16]) -> Option<usize> {
    let high = |i: usize| half.get(i).is_some_and(|s| s & SYNC_BIT != 0);
    (SYNC_HIGH + 1..half.len())
        .rev()
        .find(|&i| !high(i) && !high(i - SYNC_HIGH - 1) && (i - SYNC_HIGH..i).all(high))
}
