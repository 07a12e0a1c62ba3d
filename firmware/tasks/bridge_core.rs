//! What both bridge loops share ([`super::bridge`] for the GPIO waveform heads,
//! [`super::bridge_hans`] for HANS-100 heads): the controller-side receiver run on
//! the input halves, the `Bridge` engine, the head status the status tasks publish,
//! the XY3-100 backchannel towards the controller, the laser gate and the
//! supervision outputs. The loops only decide when an output slot is due and how
//! its frame reaches the head.

use core::sync::atomic::Ordering;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::watch::AnonReceiver;
use shared::bridge::{Bridge, Config, LinkState, Output, StatusForm, ZSource};
use shared::model::{Alarms, Axis, ForwardFrame, HeadStatus, LineEvent};
use shared::xy3::back::SEND_BUF_LEN;
use shared::xy3::BackRate;
use shared::{xy2, xy3};

use crate::channels::{
    set_laser_gate, BridgeSnapshot, Stats, Xy3Raw, BACK_RATE, BACK_TX, BRIDGE_BEAT,
    BRIDGE_SNAPSHOT, CTRL_STATUS_OK, CTRL_STATUS_WORD, HEAD_BACK_RATE, HEAD_FAULT, HEAD_STATUS,
    LINK_RUNNING, RAW_INPUT, SNAPSHOT_WANTED, STATS, XY2_HALF, XY3_HALF, XY3_INPUT, XY3_LINES,
    XY3_RESYNC,
};
use crate::config::{Controller, Head, BAKED_ROLES};

/// Gate-on history mask: the output computed now and the two before it must all
/// have had the gate on. Both loops write two steps ahead of what the head is
/// receiving (the waveform ring holds the playing and the queued batch; the HANS-100
/// transmitter writes two slots ahead), so the laser never fires before the head has
/// the first forwarded position.
const GATE_ON_HISTORY: u8 = 0b111;

/// XY2-100 input pins on port G (board wiring: PG0 SYNC, PG1 X, PG2 Y, PG3 Z). Z is
/// received only with `z.source = "input"`: a frame period counts only if every
/// received channel decodes, so an unconnected Z input (reading the RS-422 fail-safe
/// level) would otherwise reject every frame.
fn xy2_in_pins(config: &Config) -> xy2::rx::PinMap {
    xy2::rx::PinMap {
        sync: 0,
        x: 1,
        y: 2,
        z: (config.z.source == ZSource::Input).then_some(3),
    }
}

/// The controller-side receiver the bridge runs on the input halves.
#[expect(
    clippy::large_enum_variant,
    reason = "one instance, inside the task's future; no heap to box into"
)]
enum Decoder {
    /// XY2-100 port samples ([`RAW_INPUT`]).
    Xy2(xy2::rx::Receiver),
    /// XY3-100 SPI bytes and frame-end marks ([`XY3_INPUT`]).
    Xy3(Xy3Decoder),
    /// HANS-100: events already decoded by `hans_in::hans_decode` (decode executor).
    Hans,
}

/// How the head's status feeds the engine's status watchdog
/// (`Bridge::status_seen`).
///
/// An XY2 head with a STATUS level reports only changes (`status::status_level_in`
/// publishes the debounced level when it changes), but the line itself is always
/// there (an open RS-485 receiver reads its fail-safe level, which the debouncer
/// reports as a level): once the first level is in, the head's status is that
/// level until the next change, so it counts as seen every batch.
///
/// "The first level is in" is not the engine's `Supervisor::status_unknown`
/// (the gate's wait for a head status): that is the watchdog's view and comes
/// back on a `STATUS_LOST` (two batches' heartbeats `failsafe.status_timeout_us`
/// apart, 1 ms at least: a stalled loop), and it is never set with the watchdog
/// off. Gating the heartbeat on it would latch `STATUS_LOST`, and the gate off,
/// until the healthy head's level happened to change. What the level tells stays
/// true once in; the engine's own flag keeps the gate off until the first one
/// (and after a loss until the next batch's heartbeat).
#[derive(Clone, Copy, PartialEq, Eq)]
enum StatusFeed {
    /// Each status a status task publishes counts as seen once (XY3-100
    /// backchannel packets and HANS-100 STATUS frames keep coming; the XY2 status
    /// word feeds the watchdog itself, `head_word`).
    Published,
    /// An XY2 STATUS level whose start-up level has not been debounced yet: the
    /// head's state is not known.
    LevelAwaited,
    /// An XY2 STATUS level that is in: seen every batch.
    Level,
}

/// The XY3-100 receiver and where its byte count stands against the input task's.
struct Xy3Decoder {
    rx: xy3::rx::Receiver,
    lines: xy3::rx::Lines,
    /// The input session the receiver follows (`None` before the first half).
    session: Option<u32>,
    /// `first_byte` the next half must have to continue the byte stream.
    next_byte: u32,
    /// Lines out of step inside a session: withholds suspect periods, asks the
    /// input task for a restart ([`XY3_RESYNC`]).
    watch: xy3::step::StepWatch,
}

impl Xy3Decoder {
    fn new(config: &Config) -> Self {
        // The lines the input task receives (`controller.xy3.lines` that the bridge
        // uses): an unconnected line would read dead and fail every period.
        let lines = config.xy3_input_lines();
        Xy3Decoder {
            rx: xy3::rx::Receiver::new(lines),
            lines,
            session: None,
            next_byte: 0,
            watch: xy3::step::StepWatch::new(xy3::step::OUT_OF_STEP_NS),
        }
    }

    /// Feeds one half and hands the events of every completed period to `emit`,
    /// with the period's end position in this half's X bytes (`0..=XY3_HALF`: a
    /// period closed by a frame end that came with this half but counts bytes of an
    /// earlier one is at 0). The watch holds each good period until the next one
    /// confirms it (`shared::xy3::step`): its events go out at the *confirming*
    /// period's position, one period late; the last period of a half waits for
    /// the next half and goes out at its first period's position. Every frame is
    /// thus placed 3 bytes later in the byte stream: the pacing keeps their order
    /// and spacing, one slot later.
    fn feed(&mut self, raw: &Xy3Raw, emit: &mut impl FnMut(u32, LineEvent)) {
        if self.session != Some(raw.session) || raw.first_byte != self.next_byte {
            // A new input session (all lines restarted) or a lost half: the byte
            // stream is not continuous, so start a receiver at this half's count
            // (pending frame ends of the old stream are meaningless now).
            if self.session.is_some() {
                emit(0, xy3::step::dropped());
            }
            self.rx = xy3::rx::Receiver::with_origin(self.lines, raw.first_byte);
            self.session = Some(raw.session);
        }
        self.next_byte = raw.first_byte.wrapping_add(XY3_HALF as u32);
        // The received lines in axis order, as `push_bytes` takes them.
        let mut lines: [&[u8]; XY3_LINES] = [&[]; XY3_LINES];
        let received = Axis::ALL
            .iter()
            .zip(&raw.bytes)
            .filter(|(a, _)| self.lines.has(**a));
        for (slot, (_, bytes)) in lines.iter_mut().zip(received) {
            *slot = bytes;
        }
        let lines = lines.get(..self.lines.count()).unwrap_or_default();
        if let Err(e) = self.rx.push_bytes(lines) {
            // Not reachable (one equal-length slice per configured line), but never
            // silent: the bytes are not taken.
            defmt::error!("xy3 receiver refused a half: {}", e);
            return;
        }
        self.rx.push_ends(&raw.ends);
        let now_ns = Self::now_ns();
        while let Some(period) = self.rx.poll() {
            // Signed: an end before this half's first byte wraps to a large u32.
            let at = (period.end.wrapping_sub(raw.first_byte) as i32).clamp(0, XY3_HALF as i32);
            let mut emit_at = |e| emit(at as u32, e);
            if self.watch.period(now_ns, &period, &mut emit_at) {
                defmt::warn!(
                    "xy3 in: lines out of step; restarting session {}",
                    raw.session
                );
                XY3_RESYNC.signal(raw.session);
            }
        }
    }

    /// After the halves of a batch (or none): the watch's held period goes to
    /// `emit` once it has waited `CONFIRM_NS` with no period after it (the
    /// controller paused or stopped). A continuing stream confirms it sooner: the
    /// next half (at most 213 us of 24-bit frames at 100 kHz) brings the next
    /// period, so only a stream slower than 0.5 ms per half sees time releases.
    fn release(&mut self, emit: impl FnMut(LineEvent)) {
        self.watch.release(Self::now_ns(), emit);
    }

    /// The watch's clock: halves are drained once per batch (200-250 us), fine
    /// against its 2 ms limit and its 0.5 ms confirmation wait.
    fn now_ns() -> u64 {
        embassy_time::Instant::now()
            .as_micros()
            .saturating_mul(1000)
    }
}

/// The shared state of a bridge loop.
pub(super) struct Core {
    /// The engine.
    pub(super) bridge: Bridge,
    decoder: Decoder,
    head_status: AnonReceiver<'static, CriticalSectionRawMutex, HeadStatus, 2>,
    /// How the head's status feeds the watchdog.
    status_feed: StatusFeed,
    ctrl_level: xy2::StatusLevel,
    /// XY3-100 controller: the bridge's backchannel packets go out through BACK_TX.
    back_ctrl: bool,
    back_buf: [u8; SEND_BUF_LEN],
    rate_due: Option<BackRate>,
    gate_history: u8,
    /// The bridge has been `Running` once (safe start-up: no frame before).
    started: bool,
}

impl Core {
    /// The bridge and receiver for the configuration, or why there are none.
    pub(super) fn new(
        config: &Config,
        head: Head,
        controller: Controller,
    ) -> Result<Core, &'static str> {
        // Slaved timing: `Config::validate` (inside) refuses it for a HANS-100
        // head, whose line has no room for a frame more than the input's.
        let bridge = Bridge::new(config).map_err(|_| "configuration refused")?;
        // Only the baked controller's receiver is built: `controller` comes from the
        // same file, and with it known here the other receivers are never linked.
        if controller != BAKED_ROLES.controller {
            return Err("controller protocol is not the baked one");
        }
        let decoder = match controller {
            Controller::Xy2 => {
                let link = xy2::LinkConfig {
                    mode: config.controller.xy2.mode,
                    parity: config.controller.xy2.parity,
                };
                xy2::rx::Receiver::new(xy2_in_pins(config), link)
                    .map(Decoder::Xy2)
                    .map_err(|_| "XY2-100 receiver pin map refused")?
            }
            Controller::Xy3 => Decoder::Xy3(Xy3Decoder::new(config)),
            Controller::Hans => Decoder::Hans,
        };
        Ok(Core {
            bridge,
            decoder,
            head_status: HEAD_STATUS.anon_receiver(),
            status_feed: if head == Head::Xy2 && config.head.xy2.status == StatusForm::Level {
                StatusFeed::LevelAwaited
            } else {
                StatusFeed::Published
            },
            ctrl_level: xy2::StatusLevel {
                polarity: config.controller.xy2.polarity,
            },
            back_ctrl: controller == Controller::Xy3,
            back_buf: [0; SEND_BUF_LEN],
            rate_due: None,
            gate_history: 0,
            started: false,
        })
    }

    /// Decodes the input halves queued at the call (halves arriving meanwhile wait
    /// for the next call, so the input of a batch is known before its events are
    /// placed). Each event goes to `sink` in time order as `(position, units,
    /// event)`: where it was decided in the drained input (units consumed: XY2-100
    /// samples, XY3-100 X bytes; halves back to back) and the units drained in all,
    /// for `shared::bridge::pacing::batch_slot`.
    pub(super) fn take_input(&mut self, sink: &mut impl FnMut(u32, u32, LineEvent)) {
        // The guards are constants (`Core::new` builds only the baked receiver): they
        // let the compiler drop the other receivers' arms, and their code.
        let baked = BAKED_ROLES.controller;
        match &mut self.decoder {
            Decoder::Xy2(rx) if baked == Controller::Xy2 => {
                let halves = RAW_INPUT.len();
                let units = (halves * XY2_HALF) as u32;
                for h in 0..halves {
                    let Ok(raw) = RAW_INPUT.try_receive() else {
                        break;
                    };
                    let base = (h * XY2_HALF) as u32;
                    rx.feed_at(&raw, &mut |at, ev| {
                        ev.line_events(&mut |le| sink(base + at as u32, units, le))
                    });
                }
            }
            Decoder::Xy3(rx) if baked == Controller::Xy3 => {
                let halves = XY3_INPUT.len();
                let units = (halves * XY3_HALF) as u32;
                for h in 0..halves {
                    let Ok(raw) = XY3_INPUT.try_receive() else {
                        break;
                    };
                    let base = (h * XY3_HALF) as u32;
                    rx.feed(&raw, &mut |at, le| sink(base + at, units, le));
                }
                // A period released unconfirmed goes after the drained input (the
                // end of the batch's bytes).
                rx.release(|le| sink(units, units, le));
            }
            Decoder::Hans if baked == Controller::Hans => super::hans_in::take_events(sink),
            // Not built in this image (`Core::new`).
            Decoder::Xy2(_) | Decoder::Xy3(_) | Decoder::Hans => {}
        }
    }

    /// Takes the head status the status tasks published (XY2 level, XY3
    /// backchannel, HANS STATUS) at bridge time `now_ns`; an XY2 STATUS level that
    /// is in counts as seen every call ([`StatusFeed`]).
    pub(super) fn take_head_status(&mut self, now_ns: u64) {
        if let Some(s) = self.head_status.try_changed() {
            *self.bridge.head_status_mut() = s;
            self.bridge.status_seen(now_ns);
            if self.status_feed == StatusFeed::LevelAwaited {
                self.status_feed = StatusFeed::Level;
            }
        } else if self.status_feed == StatusFeed::Level {
            self.bridge.status_seen(now_ns);
        }
    }

    /// One output slot at bridge time `t_ns`: `events` (the input of this slot) go
    /// to the bridge, then `tick`. Returns the frame to send (`None` before the
    /// bridge was first `Running`, and when the bridge sends nothing) and whether
    /// the bridge allows the laser gate.
    ///
    /// Free-running, the engine keeps the newest frame for `tick`. Slaved, a
    /// forwarded frame comes straight from `on_line_event` (the loops hand a slot
    /// at most one frame: `pacing::SlotQueue`), and `tick` adds only the fail-safe
    /// frames (hold, park) while the link is not running.
    pub(super) fn slot(
        &mut self,
        events: impl IntoIterator<Item = LineEvent>,
        t_ns: u64,
    ) -> (Option<ForwardFrame>, bool) {
        let mut slaved = None;
        for le in events {
            if let Some(o) = self.bridge.on_line_event(t_ns, le) {
                self.note_rates(&o);
                slaved = o.frame.or(slaved);
            }
        }
        let o: Output = self.bridge.tick(t_ns);
        let running = o.state == LinkState::Running;
        self.started |= running;
        LINK_RUNNING.store(running, Ordering::Relaxed);
        self.note_rates(&o);
        let frame = if self.started {
            slaved.or(o.frame)
        } else {
            None
        };
        (frame, o.laser.gate)
    }

    /// A backchannel rate change in a bridge output. Each side has its UART: the
    /// controller's waits for the bytes queued at the old rate (`backchannel`), the
    /// head's follows the forwarded command at once.
    fn note_rates(&mut self, o: &Output) {
        if let Some(rate) = o.controller_back_rate {
            self.rate_due = Some(rate);
        }
        if let Some(rate) = o.head_back_rate {
            HEAD_BACK_RATE.signal(rate);
        }
    }

    /// After a batch of slots (`gate`: every slot allowed the gate) at bridge time
    /// `now_ns`: the laser gate (off at once; on only after [`GATE_ON_HISTORY`]
    /// batches), the statistics snapshot, the XY2 STATUS level and word towards the
    /// controller, the supervisor's heartbeat and fault flag, the XY3-100
    /// backchannel and the HANS STATUS frames towards a HANS-100 controller.
    /// After an output underrun (the head got idle words, the ring guard closed
    /// the gate): the gate rule starts again, so the gate opens only after three
    /// whole batches computed with it on have been queued.
    pub(super) fn restart_gate(&mut self) {
        self.gate_history = 0;
        set_laser_gate(false);
    }

    pub(super) fn end_batch(&mut self, gate: bool, now_ns: u64) {
        self.gate_history = (self.gate_history << 1 | u8::from(gate)) & GATE_ON_HISTORY;
        let gate_on = self.gate_history == GATE_ON_HISTORY;
        set_laser_gate(gate_on);
        if SNAPSHOT_WANTED.swap(false, Ordering::Relaxed) {
            BRIDGE_SNAPSHOT.signal(BridgeSnapshot {
                counters: *self.bridge.counters(),
                state: self.bridge.state(),
                alarms: self.bridge.alarms(),
                reported: self.bridge.reported_alarms(),
                gate: gate_on,
            });
        }
        let ok = self.ctrl_level.health(self.bridge.xy2_status_line_high()) == xy2::Health::Ok;
        CTRL_STATUS_OK.store(ok, Ordering::Relaxed);
        let fault = self.bridge.reported_alarms().0 & !Alarms::INPUT_LOST.0 != 0;
        HEAD_FAULT.store(fault, Ordering::Relaxed);
        let word = self.bridge.xy2_status_word().to_word();
        CTRL_STATUS_WORD.store(u32::from(word), Ordering::Relaxed);
        BRIDGE_BEAT.fetch_add(1, Ordering::Relaxed);
        self.backchannel(now_ns);
        if matches!(self.decoder, Decoder::Hans) {
            super::hans_status_out::feed(&mut self.bridge);
        }
    }

    /// XY3-100 backchannel towards the controller: a rate change waits until the
    /// bytes made for the old rate have left `BACK_TX`; otherwise, when a whole
    /// packet fits, `Bridge::xy3_back_poll` writes the next bytes.
    fn backchannel(&mut self, now_ns: u64) {
        if let Some(rate) = self.rate_due {
            // The backchannel task finishes the write it has taken first.
            if !self.back_ctrl || BACK_TX.is_empty() {
                BACK_RATE.signal(rate);
                self.rate_due = None;
            }
        }
        if self.back_ctrl && self.rate_due.is_none() && BACK_TX.free_capacity() >= SEND_BUF_LEN {
            match self.bridge.xy3_back_poll(now_ns, &mut self.back_buf) {
                // Fits: the bridge is the only writer and checked the space.
                Ok(n) => {
                    let _ = BACK_TX.try_write(self.back_buf.get(..n).unwrap_or_default());
                }
                Err(_) => Stats::bump(&STATS.back_errors),
            }
        }
    }
}
