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
