//! Added latency of the bridge, measured on the pipeline: from the middle of the
//! last bit of a controller frame (where the receiver samples it) to the first bit
//! of the first head frame that carries its positions.
//!
//! The controller's buffers are fed one sample (XY2-100 CLK edge, XY3-100 byte or
//! SYNC edge, HANS-100 16-sample word) at a time, so the figures are the bridge's
//! own: receiver, engine, output slot phase and output buffering as modelled by
//! [`Options`] (free-running XY2 / XY3 slots computed one slot ahead, the HANS-100
//! ring written two slots ahead, slaved frames 1 us after the input event). The
//! firmware's batch loop (250 us batches of output slots) adds its own buffering
//! on top. Free-running figures depend on the phase between the two clocks: each
//! pairing is run with the controller's frames starting at several phases across
//! the output slot.

use shared::bridge::{Config, LinkState, Protocol, Timing, ZSource};
use shared::model::ForwardFrame;

use super::check::expected;
use super::stimulus::{self, GenTiming};
use super::{Options, Pipeline, PipelineError};
use crate::wave::Ps;

/// Latency figures of one pairing and timing mode, ns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latency {
    /// Shortest.
    pub min_ns: f64,
    /// Mean.
    pub mean_ns: f64,
    /// Longest.
    pub max_ns: f64,
    /// Frames measured.
    pub frames: usize,
}

/// The configuration measured: defaults, Z from the input, 100 kHz, 24-bit XY3.
pub fn config(ctrl: Protocol, head: Protocol, timing: Timing) -> Config {
    let mut c = Config::default();
    c.controller.protocol = ctrl;
    c.head.protocol = head;
    c.z.source = ZSource::Input;
    c.output.timing = timing;
    c.failsafe.recovery_frames = 10;
    c
}

/// Frames with positions unique at 16 bits, at the controller's widths.
fn frames(c: &Config, t: &GenTiming, n: u32) -> Vec<ForwardFrame> {
    let w = stimulus::controller_widths(c, t.xy3_size);
    (0..n)
        .map(|i| {
            let v16 = [
                (700 + i * 41) & 0xFFFF,
                (50_000 + i * 29) & 0xFFFF,
                (i * 13) & 0xFFFF,
            ];
            stimulus::frame(c, t, [0, 1, 2].map(|k| v16[k] << (w[k] - 16)), None)
        })
        .collect()
}

/// Measures `config` with `frames_per_phase` frames at each of `phases` start
/// phases spread over one 10 us frame period.
pub fn measure(
    config: &Config,
    phases: u32,
    frames_per_phase: u32,
) -> Result<Latency, PipelineError> {
    let mut all: Vec<f64> = Vec::new();
    for ph in 0..phases.max(1) {
        let t = GenTiming {
            start_ps: 2_000_000 + Ps::from(ph) * 10_000_000 / Ps::from(phases.max(1)),
            ..GenTiming::default()
        };
        let sent = frames(config, &t, frames_per_phase);
        let stim = stimulus::controller_signal(config, &sent, &t)?;
        let opts = Options::default();
        let items = stimulus::capture(config, &stim.wave, opts.hans_sample_hz, 0.5)?;
        let mut p = Pipeline::new(config, opts)?;
        let end = stim.wave.end_time() / 1000 + 60_000;
        stimulus::run(&mut p, &items, end)?;
        let out: Vec<_> = p
            .sent()
            .iter()
            .filter(|s| s.state == LinkState::Running)
            .collect();
        for s_in in &stim.sent {
            let want = expected(config, &s_in.frame);
            let first = out
                .iter()
                .find(|o| super::check::raw(config, &o.frame) == want);
            if let Some(o) = first {
                all.push(o.start_ps as f64 / 1000.0 - s_in.last_bit_ps as f64 / 1000.0);
            }
        }
    }
    let n = all.len();
    if n == 0 {
        return Err(PipelineError::BadInput("no frame reached the head".into()));
    }
    Ok(Latency {
        min_ns: all.iter().copied().fold(f64::INFINITY, f64::min),
        mean_ns: all.iter().sum::<f64>() / n as f64,
        max_ns: all.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        frames: n,
    })
}

/// One row per pairing and timing mode (HANS-100 heads are free-running only).
pub fn table(phases: u32, frames_per_phase: u32) -> Result<Vec<(String, Latency)>, PipelineError> {
    let ps = [Protocol::Xy2, Protocol::Xy3, Protocol::Hans];
    let name = |p: Protocol| match p {
        Protocol::Xy2 => "XY2-100",
        Protocol::Xy3 => "XY3-100",
        Protocol::Hans => "HANS-100",
    };
    let mut rows = Vec::new();
    for timing in [Timing::FreeRunning, Timing::Slaved] {
        for ctrl in ps {
            for head in ps {
                if head == Protocol::Hans && timing == Timing::Slaved {
                    continue;
                }
                let c = config(ctrl, head, timing);
                let mode = match timing {
                    Timing::FreeRunning => "free-running",
                    Timing::Slaved => "slaved",
                };
                let l = measure(&c, phases, frames_per_phase)?;
                rows.push((format!("{} -> {}, {mode}", name(ctrl), name(head)), l));
            }
        }
    }
    Ok(rows)
}

/// The firmware's batch loop (`firmware/tasks/bridge.rs`) on top of the bridge's
/// own latency: the input DMA half a frame ends in is handed over when the half is
/// full, waits for the next batch, is placed on that batch's slots by position
/// (`shared::bridge::pacing::batch_slot`) and plays after the two ring halves ahead
/// of it (the playing and the queued batch). Input geometry (units per half, per
/// frame period, unit time) and the head's batch (slots of 10 us) as in the
/// firmware; the loop's own run time is left out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatchLoop {
    /// Input units (XY2-100 samples, XY3-100 X bytes) per DMA half.
    pub half_units: u32,
    /// Units per input frame period.
    pub period_units: u32,
    /// Time of one unit, ns.
    pub unit_ns: f64,
    /// Output slots per batch.
    pub slots: usize,
    /// Output slot, ns.
    pub slot_ns: f64,
}

impl BatchLoop {
    /// XY2-100 input (512-sample halves at 2 MHz) to an XY2-100 head (25 slots).
    pub const XY2_TO_XY2: BatchLoop = BatchLoop {
        half_units: 512,
        period_units: 20,
        unit_ns: 500.0,
        slots: 25,
        slot_ns: 10_000.0,
    };
    /// XY3-100 24-bit input (64-byte halves, 3 bytes per 10 us frame) to a 24-bit
    /// XY3-100 head (20 slots).
    pub const XY3_TO_XY3: BatchLoop = BatchLoop {
        half_units: 64,
        period_units: 3,
        unit_ns: 10_000.0 / 3.0,
        slots: 20,
        slot_ns: 10_000.0,
    };

    /// Latency added by the loop from the end of each input frame to the start of
    /// its output slot, over `frames` frames at `phases` phases of the batch clock
    /// against the input: `slaved` hands each slot at most one frame (the rest wait,
    /// `SlotQueue`), free-running the newest frame due (the others are skipped and
    /// not measured).
    pub fn measure(&self, slaved: bool, phases: u32, frames: u32) -> Latency {
        use shared::bridge::pacing::{batch_slot, SlotQueue};
        use shared::model::{ForwardFrame, LineEvent};
        let batch_ns = self.slot_ns * self.slots as f64;
        let half_ns = f64::from(self.half_units) * self.unit_ns;
        let halves = (frames * self.period_units).div_ceil(self.half_units);
        let mut all = Vec::new();
        for ph in 0..phases.max(1) {
            let phase = batch_ns * f64::from(ph) / f64::from(phases.max(1));
            let mut queue: SlotQueue<1024> = SlotQueue::new(1024);
            // Frame k ends with unit (k + 1) * period_units; its end time is kept
            // in the queue's frame (X carries k).
            let mut drained = 0u32;
            let mut batch = 0u64;
            let mut due_frames = 0u32;
            while drained < halves || !queue.is_empty() {
                let t_batch = phase + batch as f64 * batch_ns;
                let ready = (((t_batch / half_ns).floor()) as u32).min(halves);
                let units = (ready - drained) * self.half_units;
                let first_unit = drained * self.half_units;
                while due_frames < frames {
                    let end = (due_frames + 1) * self.period_units;
                    if end > ready * self.half_units {
                        break;
                    }
                    let pos = end - first_unit;
                    let due = batch * self.slots as u64 + batch_slot(pos, units, self.slots) as u64;
                    let mut f = ForwardFrame::default();
                    f.axes[0] = shared::model::Position::from_raw(due_frames, 20).ok();
                    // Capacity is ample here: a refusal would only lose a sample.
                    let _ = queue.push(due, LineEvent::Frame(f));
                    due_frames += 1;
                }
                drained = ready;
                for i in 0..self.slots {
                    let slot = batch * self.slots as u64 + i as u64;
                    let plays = t_batch + 2.0 * batch_ns + i as f64 * self.slot_ns;
                    let mut newest = None;
                    for e in queue.take(slot, slaved) {
                        if let LineEvent::Frame(f) = e {
                            newest = f.axes[0].map(|p| p.to_raw(20));
                        }
                    }
                    if let Some(k) = newest {
                        let end_ns = f64::from((k + 1) * self.period_units) * self.unit_ns;
                        all.push(plays - end_ns);
                    }
                }
                batch += 1;
            }
        }
        let n = all.len();
        Latency {
            min_ns: all.iter().copied().fold(f64::INFINITY, f64::min),
            mean_ns: all.iter().sum::<f64>() / n.max(1) as f64,
            max_ns: all.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            frames: n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The loop's latency is at least the two ring batches and at most those plus
    /// a half and a batch (slaved: plus the queue's wait, bounded); free-running
    /// never waits longer than slaved.
    #[test]
    fn batch_loop_latency_is_bounded() {
        for l in [BatchLoop::XY2_TO_XY2, BatchLoop::XY3_TO_XY3] {
            let batch = l.slot_ns * l.slots as f64;
            let half = f64::from(l.half_units) * l.unit_ns;
            let s = l.measure(true, 8, 2_000);
            let f = l.measure(false, 8, 2_000);
            assert!(s.frames >= 7 * 2_000, "{l:?}: {s:?}");
            assert!(s.min_ns >= 2.0 * batch - half, "{l:?}: {s:?}");
            assert!(s.max_ns <= 4.0 * batch + half, "{l:?}: {s:?}");
            assert!(
                f.max_ns <= s.max_ns && f.mean_ns <= s.mean_ns,
                "{f:?} {s:?}"
            );
        }
    }
}
