//! The part of the pipeline after the receivers: the [`Bridge`], the head-side
//! output clock and encoder, and the controller-side status producers, driven by
//! time and by the receivers' results. [`super::Pipeline`] and the task graph
//! ([`super::tasks`]) both run it.

use shared::bridge::{Bridge, Config, Counters, LinkState, Output as BridgeOutput};
use shared::model::{HeadStatus, LineEvent};

use super::ctrl_status::{ControllerStatus, CtrlStatus};
use super::output::{HeadOutput, Output, SentFrame};
use super::{Change, Options, PipelineCounters, PipelineError};

/// Bridge + output + status producers (see the module docs).
pub struct Core {
    bridge: Bridge,
    output: Output,
    ctrl: CtrlStatus,
    counters: PipelineCounters,
    states: Vec<Change<LinkState>>,
    gate: Vec<Change<bool>>,
    /// Time of the last call (calls must not go back in time).
    now_ns: u64,
}

impl Core {
    /// The core for `config` (validated).
    pub fn new(config: &Config, options: &Options) -> Result<Core, PipelineError> {
        let bridge = Bridge::new(config).map_err(PipelineError::Config)?;
        let mut ctrl = CtrlStatus::new(config);
        ctrl.after_event(0, &bridge);
        Ok(Core {
            output: Output::new(config, options)?,
            ctrl,
            bridge,
            counters: PipelineCounters::default(),
            states: vec![Change {
                t_ns: 0,
                value: LinkState::Safe,
            }],
            gate: vec![Change {
                t_ns: 0,
                value: false,
            }],
            now_ns: 0,
        })
    }

    /// The bridge engine.
    pub fn bridge(&self) -> &Bridge {
        &self.bridge
    }

    /// The bridge's counters.
    pub fn bridge_counters(&self) -> &Counters {
        self.bridge.counters()
    }

    /// The pipeline's own counters.
    pub fn counters(&self) -> &PipelineCounters {
        &self.counters
    }

    /// The head-side output so far (a copy of the buffers).
    pub fn head_output(&self) -> HeadOutput {
        self.output.head()
    }

    /// Every frame written to the head so far, in order.
    pub fn sent(&self) -> &[SentFrame] {
        self.output.sent()
    }

    /// The controller-side status output so far (a copy).
    pub fn controller_status(&self) -> ControllerStatus {
        self.ctrl.out()
    }

    /// Link state changes.
    pub fn states(&self) -> &[Change<LinkState>] {
        &self.states
    }

    /// Laser gate changes.
    pub fn gate(&self) -> &[Change<bool>] {
        &self.gate
    }

    /// The laser gate now.
    pub fn gate_on(&self) -> bool {
        self.gate.last().is_some_and(|c| c.value)
    }

    /// The head's expected backchannel rate.
    pub fn head_back_rate(&self) -> shared::xy3::BackRate {
        self.output.head_back_rate()
    }

    /// Time of the last call, ns.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// The next output slot or controller status step, ns.
    pub fn next_deadline_ns(&self) -> u64 {
        self.output.next_ns().min(self.ctrl.next_ns())
    }

    /// Runs the output and controller-status clocks for every step due before
    /// `now_ns`, in time order.
    pub fn run_until(&mut self, now_ns: u64) {
        let now_ns = now_ns.max(self.now_ns);
        loop {
            let out_at = self.output.next_ns();
            let ctrl_at = self.ctrl.next_ns();
            if out_at.min(ctrl_at) >= now_ns {
                break;
            }
            if out_at <= ctrl_at {
                let o = self.output.step(&mut self.bridge, &mut self.counters);
                self.note(out_at, &o);
            } else {
                self.ctrl.step(&mut self.bridge);
            }
        }
        self.now_ns = now_ns;
    }

    /// The controller-side receiver's events of one buffer chunk, at `now_ns`: the
    /// clocks run up to `now_ns` first.
    pub fn line_events(&mut self, now_ns: u64, events: &[LineEvent]) {
        self.run_until(now_ns);
        let now = self.now_ns;
        for &e in events {
            self.counters.line_events += 1;
            if matches!(e, LineEvent::Frame(_)) {
                self.counters.line_frames += 1;
                self.ctrl.on_controller_frame(now, &self.bridge);
            }
            if let Some(o) = self.bridge.on_line_event(now, e) {
                self.output.slaved(now, &o, &mut self.counters);
                self.note(now, &o);
            }
        }
        self.ctrl.after_event(now, &self.bridge);
    }

    /// The head-side status receiver's result of one chunk at `now_ns`: `seen`
    /// valid items, the head's status as it now stands, head-side faults.
    pub fn head_status(
        &mut self,
        now_ns: u64,
        seen: u32,
        status: &HeadStatus,
        faults: &[LineEvent],
    ) {
        self.run_until(now_ns);
        let now = self.now_ns;
        self.counters.status_items += u64::from(seen);
        self.counters.status_faults += faults.len() as u64;
        if seen > 0 {
            self.bridge.head_status_mut().clone_from(status);
            self.bridge.status_seen(now);
        }
        for &f in faults {
            // Head-side faults only count in the bridge; they never produce output.
            let _ = self.bridge.on_line_event(now, f);
        }
        self.ctrl.after_event(now, &self.bridge);
    }

    /// Records state and gate changes from one bridge output.
    fn note(&mut self, t_ns: u64, o: &BridgeOutput) {
        if self.states.last().map(|c| c.value) != Some(o.state) {
            self.states.push(Change {
                t_ns,
                value: o.state,
            });
        }
        if self.gate.last().map(|c| c.value) != Some(o.laser.gate) {
            self.gate.push(Change {
                t_ns,
                value: o.laser.gate,
            });
        }
        if let Some(rate) = o.controller_back_rate {
            self.ctrl.set_back_rate(t_ns, rate);
        }
        self.ctrl.after_event(t_ns, &self.bridge);
    }
}
