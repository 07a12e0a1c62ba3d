//! The [`Bridge`]: line events in, head frames and laser outputs out, driven by the
//! caller's clock (see the [module docs](super) for the state machine).

use super::config::{AfterHold, Config, GateSource, HansDecode, Protocol, Timing};
use super::counters::{bump, Counters};
use super::status::StatusState;
use super::supervision::{Changes, LinkState, Supervisor};
use super::translate::{config_position, Translated, Translator};
use super::validate::ConfigError;
use crate::model::{Alarms, Axis, Command, ForwardFrame, LaserControl, Line, LineEvent, Position};
use crate::xy3::{self, BackRate};

/// HANS-100 code 3 with power 0 and master oscillator, power amplifier and red
/// pointer off: sent to a HANS-100 head in the first fail-safe frame after an input
/// loss if laser control had been forwarded to it.
pub const LASER_OFF: LaserControl = LaserControl::Power {
    power: 0,
    mo: false,
    pa: false,
    red_pointer: false,
    reserved: 0,
};

/// The bridge's own outputs besides the head frames.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LaserOutputs {
    /// Laser gate (enable) output: on only while running and permitted by
    /// `laser.gate` and `laser.off_on_head_alarm` (which also waits for the head's
    /// first status where the status watchdog is on).
    pub gate: bool,
    /// Laser power set-point from HANS-100 code 3 (0..=255), `None` until one was
    /// received; 0 while not running.
    pub power: Option<u8>,
}

/// What the bridge does in one output slot.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Output {
    /// The frame to send to the head, at the head's widths; `None` = send nothing in
    /// this slot (stopped output, or slaved mode with nothing due). Axes the input
    /// did not carry hold their last sent position.
    pub frame: Option<ForwardFrame>,
    /// The link state after this step.
    pub state: LinkState,
    /// The bridge's own alarms (`INPUT_LOST`, `STATUS_LOST`).
    pub alarms: Alarms,
    /// Laser gate and power outputs.
    pub laser: LaserOutputs,
    /// The frame carries an XY3-100 backchannel rate command to the head: listen to
    /// the head's backchannel at this rate from now on.
    pub head_back_rate: Option<BackRate>,
    /// The controller asked for a new backchannel rate: switch the bridge's
    /// controller-side backchannel UART to it (already applied to the packet
    /// schedule, which sends a SYNC first).
    pub controller_back_rate: Option<BackRate>,
}

/// The sans-IO bridge engine.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Bridge {
    pub(super) config: Config,
    sup: Supervisor,
    tr: Translator,
    pub(super) counters: Counters,
    pub(super) status: StatusState,
    /// Free-running: the newest translated frame not yet sent.
    pending: Option<ForwardFrame>,
    /// The last position sent on each axis.
    held: [Option<Position>; 5],
    park: ForwardFrame,
    /// Latest HANS-100 code-3 MO and PA both on (cleared on input loss, so the
    /// gate needs a fresh code 3 after recovery).
    mo_pa: bool,
    /// Laser control has reached a HANS-100 head since the last switch-off.
    laser_forwarded: bool,
    /// The next fail-safe frame must carry [`LASER_OFF`].
    laser_off_due: bool,
    power: Option<u8>,
    pub(super) controller_rate: BackRate,
    rate_changed: Option<BackRate>,
}

impl Bridge {
    /// A bridge for a validated configuration. It starts in [`LinkState::Safe`]
    /// with `INPUT_LOST` raised until the controller's link is proven.
    pub fn new(config: &Config) -> Result<Bridge, ConfigError> {
        config.validate()?;
        let f = &config.failsafe;
        let mut park = ForwardFrame::default();
        for (axis, raw) in [
            (Axis::X, f.park_x),
            (Axis::Y, f.park_y),
            (Axis::Z, f.park_z),
        ] {
            park.axes[axis.index()] = config_position(&config.head, axis, raw);
        }
        // U / W only where the head drives them: they have a park position only
        // where they have a source (`Config::xy3_head_lines`).
        if config.head.protocol == Protocol::Xy3 {
            let lines = config.xy3_head_lines();
            for (axis, raw) in [(Axis::U, f.park_u), (Axis::W, f.park_w)] {
                if lines.has(axis) {
                    park.axes[axis.index()] = config_position(&config.head, axis, raw);
                }
            }
        }
        Ok(Bridge {
            config: *config,
            sup: Supervisor::new(f),
            tr: Translator::new(config),
            counters: Counters::default(),
            status: StatusState::new(),
            pending: None,
            held: [None; 5],
            park,
            mo_pa: false,
            laser_forwarded: false,
            laser_off_due: false,
            power: None,
            controller_rate: config.controller.xy3.back_rate,
            rate_changed: None,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The counters.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// The current link state.
    pub fn state(&self) -> LinkState {
        self.sup.state()
    }

    /// The bridge's own alarms: `INPUT_LOST` outside running, `STATUS_LOST` while
    /// the head's status is missing.
    pub fn alarms(&self) -> Alarms {
        let mut a = Alarms::NONE;
        a.set(Alarms::INPUT_LOST, self.sup.state() != LinkState::Running);
        a.set(Alarms::STATUS_LOST, self.sup.status_lost());
        a
    }

    /// The head's status was received (any valid status frame, level sample or
    /// backchannel packet) at `now_ns`: feeds the status watchdog.
    pub fn status_seen(&mut self, now_ns: u64) {
        self.sup.status_seen(now_ns);
    }

    /// Applies time up to `now_ns` to the supervisor and cleans up after a loss.
    /// Inlined: in the quiet case (`Supervisor::poll`) nothing changed and the
    /// clean-up folds away.
    #[inline(always)]
    pub(super) fn poll(&mut self, now_ns: u64) {
        let changes = self.sup.poll(now_ns);
        if changes != Changes::default() {
            self.clean_up(changes);
        }
    }

    /// Counts the changes of a supervisor poll and cleans up after an input loss.
    #[inline(never)]
    fn clean_up(&mut self, Changes { lost, status_lost }: Changes) {
        if lost {
            bump(&mut self.counters.input_losses);
            self.mo_pa = false;
            // A HANS-100 head's laser is driven over the link itself: the gate
            // output cannot stop it, so the first fail-safe frame switches it off.
            self.laser_off_due = self.laser_forwarded;
            // A frame received before the loss is not sent after it.
            if let Some(p) = self.pending.take() {
                if p.command.is_some() {
                    bump(&mut self.counters.commands_not_carried);
                }
            }
        }
        if status_lost {
            bump(&mut self.counters.status_losses);
        }
    }

    /// Feeds one receiver event. In slaved mode a forwarded frame is returned as the
    /// output for its slot; otherwise `None` (free-running output comes from
    /// [`Bridge::tick`]).
    pub fn on_line_event(&mut self, now_ns: u64, event: LineEvent) -> Option<Output> {
        self.poll(now_ns);
        match event {
            LineEvent::Fault { line, kind } => {
                self.counters.fault(line, kind);
                let normal = matches!(self.config.controller.hans.decode, HansDecode::Normal(_));
                if breaks_run(line, normal) {
                    self.sup.fault();
                }
                None
            }
            LineEvent::Frame(f) => self.on_frame(now_ns, &f),
        }
    }

    /// A valid controller frame; returns the output for it (slaved mode only).
    ///
    /// The frame is translated straight into the pending slot (free-running) or the
    /// returned output (slaved): a frame is some 50 bytes and every move of it costs
    /// tens of instructions per frame on the MCU.
    fn on_frame(&mut self, now_ns: u64, f: &ForwardFrame) -> Option<Output> {
        bump(&mut self.counters.frames_ok);
        let was_running = self.sup.state() == LinkState::Running;
        if !self.sup.valid(now_ns) {
            bump(&mut self.counters.not_forwarded);
            if f.command.is_some() {
                bump(&mut self.counters.commands_not_carried);
            }
            if f.laser.is_some() {
                bump(&mut self.counters.laser_not_carried);
            }
            return None;
        }
        if !was_running {
            bump(&mut self.counters.recoveries);
        }
        if let Some(LaserControl::Power { power, mo, pa, .. }) = f.laser {
            self.power = Some(power);
            self.mo_pa = mo && pa;
        }
        match self.config.output.timing {
            Timing::Slaved => {
                let mut frame = ForwardFrame::default();
                let t = self.tr.translate(f, &mut frame);
                self.count_translation(&t);
                let head_back_rate = finish_frame(
                    &mut frame,
                    &mut self.held,
                    &mut self.laser_forwarded,
                    &mut self.counters.commands_forwarded,
                );
                Some(self.output(Some(frame), head_back_rate))
            }
            Timing::FreeRunning => {
                if self.pending.is_some() {
                    self.supersede(f);
                }
                // The slot is free in the steady state (one input frame per output
                // slot); after `supersede` it holds the older frame's one-offs,
                // which the translation replaces where the newer frame has its own.
                let next = self.pending.get_or_insert_with(ForwardFrame::default);
                let t = self.tr.translate(f, next);
                self.count_translation(&t);
                None
            }
        }
    }

    /// Free-running, a frame `f` arrived before the pending one was sent (input
    /// faster than output): the older frame's positions are superseded; its
    /// one-off command / laser control rides on the newer frame if that has none,
    /// else it is lost (counted). Leaves only those one-offs in the pending slot,
    /// for the translation of `f` to keep or replace. Out of line: the steady state
    /// never takes it, and holding the older one-offs across the translation would
    /// cost that state registers.
    #[inline(never)]
    fn supersede(&mut self, f: &ForwardFrame) {
        let Some(old) = self.pending.take() else {
            return;
        };
        bump(&mut self.counters.skipped);
        let (command_own, laser_own) = self.tr.carries_own(f);
        if old.command.is_some() && command_own {
            bump(&mut self.counters.commands_not_carried);
        }
        if old.laser.is_some() && laser_own {
            bump(&mut self.counters.laser_not_carried);
        }
        self.pending = Some(ForwardFrame {
            command: old.command,
            laser: old.laser,
            ..ForwardFrame::default()
        });
    }

    /// Counts what a translation dropped and applies a controller backchannel-rate
    /// command.
    fn count_translation(&mut self, t: &Translated) {
        if t.command_dropped {
            bump(&mut self.counters.commands_not_carried);
        }
        if t.laser_dropped {
            bump(&mut self.counters.laser_not_carried);
        }
        if let Some(r) = t.back_rate {
            if self.config.controller.protocol == Protocol::Xy3 {
                self.controller_rate = r;
                self.rate_changed = Some(r);
                self.status.note_rate_change();
            }
        }
    }

    /// One output slot at `now_ns`. Free-running: call once per output frame; the
    /// newest input is sent, or the last positions repeated. Slaved: call at the
    /// configured frame rate too; while running it returns no frame (frames come
    /// from [`Bridge::on_line_event`]), in the fail-safe states it clocks the hold /
    /// park frames.
    pub fn tick(&mut self, now_ns: u64) -> Output {
        self.poll(now_ns);
        let state = self.sup.state();
        if state == LinkState::Running
            && self.config.output.timing == Timing::FreeRunning
            && self.pending.is_some()
        {
            // The steady state: the newest input, completed where it lies and then
            // moved out whole (no laser-off is due while running).
            let mut head_back_rate = None;
            if let Some(f) = self.pending.as_mut() {
                head_back_rate = finish_frame(
                    f,
                    &mut self.held,
                    &mut self.laser_forwarded,
                    &mut self.counters.commands_forwarded,
                );
            }
            // The frame goes straight from its slot into the output (built first:
            // `output` does not read `pending`), one copy instead of two.
            let mut out = self.output(None, head_back_rate);
            out.frame = self.pending.take();
            return out;
        }
        let frame = match (state, self.config.output.timing) {
            (LinkState::Running, Timing::Slaved) => None,
            (LinkState::Running, Timing::FreeRunning) => {
                bump(&mut self.counters.repeated);
                Some(self.positions_only())
            }
            (LinkState::Holding, _) => Some(self.positions_only()),
            (LinkState::Safe, _) => match self.config.failsafe.after_hold {
                AfterHold::Park => Some(self.park),
                AfterHold::Stop => None,
            },
        };
        let mut head_back_rate = None;
        let frame = frame.map(|mut f| {
            if self.laser_off_due && state != LinkState::Running {
                f.laser = Some(LASER_OFF);
                self.laser_off_due = false;
            }
            head_back_rate = finish_frame(
                &mut f,
                &mut self.held,
                &mut self.laser_forwarded,
                &mut self.counters.commands_forwarded,
            );
            f
        });
        self.output(frame, head_back_rate)
    }

    /// The last sent positions, without command or laser control (one-offs are
    /// never repeated).
    fn positions_only(&self) -> ForwardFrame {
        ForwardFrame {
            axes: self.held,
            command: None,
            laser: None,
        }
    }

    /// The output for `frame` (already completed by [`finish_frame`]), with the
    /// state, alarms and laser outputs of now and a pending controller rate change.
    #[inline(always)]
    fn output(&mut self, frame: Option<ForwardFrame>, head_back_rate: Option<BackRate>) -> Output {
        let running = self.sup.state() == LinkState::Running;
        let laser_cfg = &self.config.laser;
        // Unknown: not seen yet, or lost (`Supervisor::status_unknown`).
        let head_alarm = self.status.head.alarms.any() || self.sup.status_unknown();
        let gate = running
            && !(laser_cfg.off_on_head_alarm && head_alarm)
            && (laser_cfg.gate == GateSource::LinkOk || self.mo_pa);
        Output {
            frame,
            state: self.sup.state(),
            alarms: self.alarms(),
            laser: LaserOutputs {
                gate,
                power: if running {
                    self.power
                } else {
                    self.power.map(|_| 0)
                },
            },
            head_back_rate,
            controller_back_rate: self.rate_changed.take(),
        }
    }
}

/// Whether a fault on `line` breaks a recovery run: only a controller-side frame
/// period the receiver could not publish does.
///
/// - XY2-100 / XY3-100 lines (`Axis`, `Framing`): their receivers drop the whole
///   period on any fault.
/// - HANS-100 `Framing` (`channel: None`): a decoded period that publishes no frame
///   (vote failed, no super channel verified, no majority), the shared timing
///   lost, input discarded.
/// - HANS-100 channel faults (`HansChannel`: check failed, resync, minority,
///   missing) in the vote and super modes are counted only: there the receiver
///   ends every decoded period in a frame or a period fault, so a channel fault
///   says nothing about the period. A noisy or dead backup channel faulting every
///   period would otherwise hold the run at zero and the link in hold / safe while
///   verified frames flow. In normal mode (`channel_is_period`) the one channel's
///   faults are the period's (its check failure is the lost period).
/// - Head-side lines (`Status`, `Backchannel`) say nothing about the controller.
fn breaks_run(line: Line, channel_is_period: bool) -> bool {
    match line {
        Line::Axis(_) | Line::Framing => true,
        Line::HansChannel(_) => channel_is_period,
        Line::Status | Line::Backchannel => false,
    }
}

/// Completes a frame about to be sent: fills missing axes from the held positions,
/// records what is sent (held positions, laser control forwarded, commands counted)
/// and returns the backchannel rate an XY3-100 command in it sets on the head.
/// A free function over the fields it needs, so it can work on the pending frame in
/// place while the rest of the bridge is borrowed too.
#[inline(always)]
fn finish_frame(
    f: &mut ForwardFrame,
    held: &mut [Option<Position>; 5],
    laser_forwarded: &mut bool,
    commands_forwarded: &mut u64,
) -> Option<BackRate> {
    for (slot, held) in f.axes.iter_mut().zip(held.iter_mut()) {
        match slot {
            Some(p) => *held = Some(*p),
            None => *slot = *held,
        }
    }
    if f.laser.is_some() {
        *laser_forwarded = f.laser != Some(LASER_OFF);
    }
    match f.command {
        Some(Command::Xy3(code)) => {
            bump(commands_forwarded);
            match xy3::Command::from_code(code) {
                Ok(xy3::Command::BackRate(r)) => Some(r),
                _ => None,
            }
        }
        Some(_) => {
            bump(commands_forwarded);
            None
        }
        None => None,
    }
}
