//! What the end-to-end tests share, as plain functions and structs over what a test
//! recorded or reads once: the baked settings every pairing's expectations rest
//! on, the order of the frame numbers a head received, the laser gate's timing
//! against the input, and the head drivers' switch-on (README "Hardware-in-the-loop
//! self-tests"). Each item is compiled only for the pairings whose test uses it,
//! so no image carries one it does not call.

use embassy_stm32::pac;
use embassy_time::Duration;
#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "hans_to_xy2",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
use embassy_time::Instant;
use shared::bridge::{Config, ZSource};

/// Checks the baked settings every end-to-end test's expectations rest on: the
/// axis map is the identity (no swap, no inversion, no offsets) and Z comes from
/// the input, so a frame reaches the head as it was sent (up to the protocols'
/// bit widths).
pub fn assert_identity_axes(config: &Config) {
    let a = config.axes;
    assert!(
        !a.swap_xy && !a.invert_x && !a.invert_y && !a.invert_z,
        "axis map"
    );
    assert_eq!((a.offset_x, a.offset_y, a.offset_z), (0, 0, 0), "offsets");
    assert_eq!(config.z.source, ZSource::Input);
}

/// The frame numbers a free-running head received, in the order it received them,
/// and its park periods: what the waveform tests (one frame number per head
/// period) judge with [`FrameSeq::check`].
#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
#[derive(Default, Debug, defmt::Format)]
pub struct FrameSeq {
    /// First frame number seen, and the highest one so far.
    pub first: Option<u32>,
    pub last: Option<u32>,
    /// Frames seen for the first time, repeats of the last one, steps back; the
    /// largest step between two distinct frames.
    pub distinct: u32,
    pub repeats: u32,
    pub backwards: u32,
    pub max_step: u32,
    /// Steps of more than 4 frames (an outage the head held across), and the last
    /// one as (the frame before, the frame after).
    pub big_steps: u32,
    pub gap: Option<(u32, u32)>,
    /// The frame with the flipped parity bit was seen.
    pub bad_seen: bool,
    /// Park periods; of them before the first frame; frames after a park.
    pub park: u32,
    pub park_before_first: u32,
    pub frames_after_park: u32,
}

#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
impl FrameSeq {
    /// Records one period at the park position.
    pub fn park(&mut self) {
        self.park += 1;
        self.park_before_first += u32::from(self.first.is_none());
    }

    /// Records one period carrying frame `k` (a frame sent); `bad` when it is the
    /// one sent with a flipped parity bit.
    pub fn frame(&mut self, k: u32, bad: bool) {
        self.frames_after_park += u32::from(self.park > 0);
        self.bad_seen |= bad;
        self.first.get_or_insert(k);
        match self.last {
            Some(last) if k == last => self.repeats += 1,
            Some(last) if k < last => self.backwards += 1,
            Some(last) => {
                self.distinct += 1;
                self.max_step = self.max_step.max(k - last);
                if k - last > 4 {
                    self.big_steps += 1;
                    self.gap = Some((last, k));
                }
            }
            None => self.distinct += 1,
        }
        self.last = Some(self.last.map_or(k, |l| l.max(k)));
    }

    /// The verdict for a source of `n` frames whose first `recovery` frames the
    /// bridge's recovery run (`failsafe.recovery_frames`) holds back: the flipped
    /// frame never; frames never go back; park only after the last frame; the
    /// first frame at the end of the recovery run, the last within 4 of the last
    /// one sent; steps of at most 4 and at least 60 % of the frames after the
    /// recovery run distinct (free-running at the input's rate, a batch of 20
    /// slots that drains a half of 25 frames skips 5: ~80 % expected, README
    /// "Added latency"); at least 1000 park periods at the end.
    pub fn check(&self, n: u32, recovery: u32) {
        self.check_outages(n, recovery, 0);
    }

    /// [`Self::check`] for a run in which the head held across `outages` known
    /// input outages: exactly that many steps of more than 4 frames (the caller
    /// checks where [`Self::gap`] lies), all the others of at most 4.
    pub fn check_outages(&self, n: u32, recovery: u32, outages: u32) {
        assert!(
            !self.bad_seen,
            "the frame with a flipped parity bit reached the head"
        );
        assert_eq!(self.backwards, 0, "frames out of order");
        assert_eq!(self.park_before_first, 0, "park before the first frame");
        assert_eq!(self.frames_after_park, 0, "frames after the park");
        let first = self.first.expect("no frame reached the head");
        assert!(
            (recovery - 1..recovery + 10).contains(&first),
            "first frame {}",
            first
        );
        assert!(
            self.last.is_some_and(|l| l + 4 >= n - 1),
            "last frame {:?}",
            self.last
        );
        assert_eq!(
            self.big_steps, outages,
            "steps of more than 4 frames (the largest {}, the last {:?})",
            self.max_step, self.gap
        );
        assert!(
            self.distinct >= (n - recovery) * 6 / 10,
            "{} distinct frames",
            self.distinct
        );
        assert!(self.park >= 1000, "{} park periods", self.park);
    }
}

/// The laser gate, sampled every 100 us by the tests whose gate follows the input
/// link alone (`laser.gate = "link_ok"`, no head alarm): violations counted per
/// phase of the test's source (0 before the input, 1 while it runs, 2 once it
/// stopped).
#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "xy3_to_xy2"))]
#[derive(Default, Debug, defmt::Format)]
pub struct GateWatch {
    /// Samples with the gate on before the input.
    pub before: u32,
    /// When the gate first came on after the input started, and samples with it
    /// off after that while the input runs.
    pub on_after_us: Option<u64>,
    pub drops: u32,
    /// Samples once the input stopped, and of them with the gate still on more
    /// than 6 ms after.
    pub late: u32,
    pub samples_after: u32,
}

#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "xy3_to_xy2"))]
impl GateWatch {
    /// Records one sample `on` of the gate in `phase`, `since_input` after the
    /// input started and `since_stop` after it stopped (`None` while the stop is
    /// not yet timed). Phases past 2 are not recorded.
    pub fn sample(
        &mut self,
        phase: u8,
        on: bool,
        since_input: Duration,
        since_stop: Option<Duration>,
    ) {
        match phase {
            0 => self.before += u32::from(on),
            1 => match (self.on_after_us, on) {
                (None, true) => self.on_after_us = Some(since_input.as_micros()),
                (Some(_), false) => self.drops += 1,
                _ => {}
            },
            2 => {
                if let Some(t) = since_stop {
                    self.samples_after += 1;
                    if t > Duration::from_millis(6) && on {
                        self.late += 1;
                    }
                }
            }
            _ => {}
        }
    }

    /// The verdict: off before the input, on within 10 ms of it and on until it
    /// stops, off within 6 ms after and for good (over more than 1000 samples,
    /// 100 ms).
    pub fn check(&self) {
        assert_eq!(self.before, 0, "gate on before the input");
        let on = self.on_after_us.expect("gate never on");
        assert!(on < 10_000, "gate on {} us after the input", on);
        assert_eq!(self.drops, 0, "gate off while the input runs");
        assert!(
            self.samples_after > 1000,
            "{} samples after the input",
            self.samples_after
        );
        assert_eq!(self.late, 0, "gate still on 6 ms after the input stopped");
    }
}

/// Whether the laser gate's pad (PF13) reads high: the level the laser sees,
/// not the output register the supervisor writes.
pub fn laser_gate_high() -> bool {
    pac::GPIOF
        .idr()
        .read()
        .idr(xy_bridge::board::LASER_GATE_PIN)
        == pac::gpio::vals::Idr::HIGH
}

/// Waits for the bridge to switch the head's line drivers on (PF11 high), which it
/// does once its idle pattern plays on the head's lines: the point from which a
/// read-back of the head's output sees the bridge's and no floating pins. Fails
/// after 100 ms.
#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "hans_to_xy2",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
pub async fn head_drivers_on() {
    let pf = pac::GPIOF;
    let t0 = Instant::now();
    while pf.odr().read().odr(11) != pac::gpio::vals::Odr::HIGH {
        assert!(
            t0.elapsed() < Duration::from_millis(100),
            "head drivers never enabled"
        );
        embassy_time::Timer::after_micros(100).await;
    }
}

/// Checks that the head mux select (PF15) is driven, and low: the head's lines
/// carry the waveform output.
#[cfg(any(bridge_pairing = "xy2_to_xy3", bridge_pairing = "hans_to_xy2"))]
pub fn assert_mux_on_waveform() {
    let pf = pac::GPIOF;
    assert_eq!(
        pf.moder().read().moder(15),
        pac::gpio::vals::Moder::OUTPUT,
        "PF15 released"
    );
    assert_eq!(
        pf.odr().read().odr(15),
        pac::gpio::vals::Odr::LOW,
        "PF15 not on the waveform"
    );
}

/// Where the head's XY2-100 lines sit in the port samples the waveform-to-XY2
/// tests feed `shared::xy2::rx::Receiver`: SYNC, X, Y, Z in bits 0 to 3, as PG0 to
/// PG3 of the controller-side XY2 input carry them (and as `xy2_to_xy2` puts its
/// SPI read-backs together).
#[cfg(any(
    bridge_pairing = "hans_to_xy2",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
pub const HEAD_XY2_PINS: shared::xy2::rx::PinMap = shared::xy2::rx::PinMap {
    sync: 0,
    x: 1,
    y: 2,
    z: Some(3),
};

/// Returns `grace` after the test's source reached its `last` phase: the end of
/// the window in which a test reads the head's output back, so that the read-back
/// covers the park periods after the input stopped.
pub async fn phase_end(phase: &core::cell::Cell<u8>, last: u8, grace: Duration) {
    while phase.get() < last {
        embassy_time::Timer::after_millis(1).await;
    }
    embassy_time::Timer::after(grace).await;
}

/// The periods an XY2-100 head received, as the waveform-to-XY2 tests decode them
/// with `shared::xy2::rx::Receiver`: how many, how many before the input, how
/// many with a line failing its check or missing, and the framing faults after the
/// first period (the read-back may start inside a frame, or on edges that are no
/// whole frame).
#[cfg(any(
    bridge_pairing = "hans_to_xy2",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
#[derive(Default, Debug, defmt::Format)]
pub struct Xy2Periods {
    pub periods: u32,
    pub before_input: u32,
    pub failed: u32,
    pub framing: u32,
}

#[cfg(any(
    bridge_pairing = "hans_to_xy2",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
impl Xy2Periods {
    /// Records one receiver event (`before`: the input has not started) and
    /// returns the period's X, Y, Z positions when it is a frame period whose
    /// three lines pass their checks as 16-bit positions.
    pub fn record(&mut self, e: shared::xy2::rx::Event, before: bool) -> Option<[u16; 3]> {
        use shared::xy2::rx::Event;
        use shared::xy2::Frame;
        let p = match e {
            Event::Frame(p) => p,
            Event::Framing(_) => {
                self.framing += u32::from(self.periods > 0);
                return None;
            }
            Event::Resync => return None,
        };
        self.periods += 1;
        self.before_input += u32::from(before);
        match (p.x, p.y, p.z) {
            (
                Ok(Frame::Position16(x)),
                Ok(Frame::Position16(y)),
                Some(Ok(Frame::Position16(z))),
            ) => Some([x, y, z]),
            _ => {
                self.failed += 1;
                None
            }
        }
    }

    /// The verdict: no period before the input, none failing its check, no
    /// framing fault once the first period is in.
    pub fn check(&self) {
        assert_eq!(self.before_input, 0, "head periods before the input");
        assert_eq!(self.failed, 0, "head periods failing their check");
        assert_eq!(self.framing, 0, "head periods with a wrong SYNC pattern");
    }
}

/// The laser gate, sampled every 100 us by the tests whose head raises an alarm
/// during the input (`laser.off_on_head_alarm`): violations counted per phase of
/// the test (0 before the input, 1 while it runs with the head OK, 2 during the
/// head's alarm, 3 once the head is OK again, 4 once the input stopped or was lost).
#[cfg(any(bridge_pairing = "xy2_to_xy2", bridge_pairing = "hans_to_hans"))]
#[derive(Default, Debug, defmt::Format)]
pub struct AlarmGateWatch {
    /// Samples with the gate on before the input.
    pub before: u32,
    /// When the gate first came on after the input started, and samples with it
    /// off after that until the alarm.
    pub on_after_us: Option<u64>,
    pub drops: u32,
    /// Samples more than 5 ms into the alarm, and of them with the gate on.
    pub alarm_samples: u32,
    pub alarm_late: u32,
    /// When the gate came on again after the alarm, and samples with it off after
    /// that until the input stops.
    pub on_again_after_us: Option<u64>,
    pub drops_again: u32,
    /// Samples more than 6 ms after the input stopped, and of them with the gate on.
    pub samples_after: u32,
    pub late: u32,
}

#[cfg(any(bridge_pairing = "xy2_to_xy2", bridge_pairing = "hans_to_hans"))]
impl AlarmGateWatch {
    /// Records one sample `on` of the gate in `phase`, `since` the start of that
    /// phase (the input's start, the alarm's, its end, the input's end). Phases
    /// past 4 are not recorded.
    pub fn sample(&mut self, phase: u8, on: bool, since: Duration) {
        let t = since.as_micros();
        match phase {
            0 => self.before += u32::from(on),
            1 => match (self.on_after_us, on) {
                (None, true) => self.on_after_us = Some(t),
                (Some(_), false) => self.drops += 1,
                _ => {}
            },
            2 if since > Duration::from_millis(5) => {
                self.alarm_samples += 1;
                self.alarm_late += u32::from(on);
            }
            3 => match (self.on_again_after_us, on) {
                (None, true) => self.on_again_after_us = Some(t),
                (Some(_), false) => self.drops_again += 1,
                _ => {}
            },
            4 if since > Duration::from_millis(6) => {
                self.samples_after += 1;
                self.late += u32::from(on);
            }
            _ => {}
        }
    }

    /// The verdict: off before the input; on within 10 ms of it and without a gap
    /// until the head's alarm; off from 5 ms into the alarm to its end (over more
    /// than `alarm_samples` samples); on within 10 ms after it and without a gap
    /// until the input stops; off from 6 ms after that for good (over more than
    /// `samples_after` samples). The sample counts say the sampler saw the
    /// phases: a test that keeps thread mode busy between samples gets fewer.
    pub fn check(&self, alarm_samples: u32, samples_after: u32) {
        assert_eq!(self.before, 0, "gate on before the input");
        let on = self.on_after_us.expect("gate never on");
        assert!(on < 10_000, "gate on {} us after the input", on);
        assert_eq!(self.drops, 0, "gate off while the input runs");
        assert!(
            self.alarm_samples > alarm_samples,
            "{} alarm samples",
            self.alarm_samples
        );
        assert_eq!(self.alarm_late, 0, "gate on 5 ms into the head's alarm");
        let on = self.on_again_after_us.expect("gate not on after the alarm");
        assert!(on < 10_000, "gate on {} us after the alarm", on);
        assert_eq!(self.drops_again, 0, "gate off after the alarm");
        assert!(
            self.samples_after > samples_after,
            "{} samples after the input",
            self.samples_after
        );
        assert_eq!(self.late, 0, "gate on 6 ms after the input stopped");
    }
}

/// Decodes one capture of a HANS-100 line (channel 1) with a fresh
/// `shared::hans::rx::HansRx`, as a controller or head would, handing `sink`
/// every event. Out of line, with one closure type for every capture of the
/// image: one copy of the receiver for the end-to-end tests' read-backs.
#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "hans_to_hans"))]
#[inline(never)]
pub fn decode_hans(words: &[u16], sink: &mut dyn FnMut(shared::hans::rx::RxEvent)) {
    use shared::hans::rx::{HansRx, Mode};
    let mut rx = HansRx::new(xy_bridge::board::HANS_FS_HZ, Mode::Normal { channel: 1 }).unwrap();
    rx.push(&[words], &mut |ev| sink(ev));
}

/// Captures `words.len()` words of a HANS-100 line: a fresh start of the SPI
/// slave `spi` (no NSS, free-running) on the fs clock into `ring`, read once; false
/// when it overran or took longer than `timeout`. A look decodes for about as long
/// as it captured, so a continuous capture would overrun: each look starts anew.
#[cfg(any(
    bridge_pairing = "hans_to_xy2",
    bridge_pairing = "xy2_to_hans",
    bridge_pairing = "hans_to_hans"
))]
#[expect(
    clippy::too_many_arguments,
    reason = "the parts of one SPI line, each typed by its pin trait"
)]
pub async fn capture<T, D>(
    spi: embassy_stm32::Peri<'_, T>,
    sck: embassy_stm32::Peri<'_, impl embassy_stm32::spi::SckPin<T>>,
    mosi: embassy_stm32::Peri<'_, impl embassy_stm32::spi::MosiPin<T>>,
    nss: Option<embassy_stm32::Peri<'_, impl embassy_stm32::spi::CsPin<T>>>,
    dma: embassy_stm32::Peri<'_, D>,
    ring: &mut [u16],
    words: &mut [u16],
    timeout: Duration,
) -> bool
where
    T: xy_bridge::drivers::spi_slave_rx::Instance,
    D: embassy_stm32::spi::RxDma<T>,
    xy_bridge::tasks::Irqs: embassy_stm32::interrupt::typelevel::Binding<
        D::Interrupt,
        embassy_stm32::dma::InterruptHandler<D>,
    >,
{
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    let Ok(mut rx) = SpiSlaveRx::new(spi, sck, mosi, nss, dma, xy_bridge::tasks::Irqs, ring) else {
        return false;
    };
    matches!(
        embassy_time::with_timeout(timeout, rx.read_exact(words)).await,
        Ok(Ok(()))
    )
}

/// One look at a HANS STATUS stream towards the controller: the frames of a
/// capture decoded by [`decode_hans`] as the controller would, with the alarms
/// they report (`StatusReceiver` over all of them).
#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "hans_to_hans"))]
#[derive(Default, Debug, defmt::Format)]
pub struct StatusLook {
    /// Frames decoded, frames failing their check.
    pub frames: u32,
    pub failed: u32,
    /// The alarms the frames report (`shared::model::Alarms` bits).
    pub alarms: u32,
}

#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "hans_to_hans"))]
impl StatusLook {
    /// Decodes `words`.
    pub fn of(words: &[u16]) -> StatusLook {
        use shared::hans::rx::RxEvent;
        use shared::model::{FaultKind, HeadStatus};
        let mut receiver = shared::hans::StatusReceiver::new();
        let mut status = HeadStatus::default();
        let mut look = StatusLook::default();
        decode_hans(words, &mut |ev| match ev {
            RxEvent::Frame(f) => {
                look.frames += 1;
                receiver.apply(&f, &mut status);
            }
            RxEvent::Fault {
                kind: FaultKind::CheckFailed,
                ..
            } => look.failed += 1,
            RxEvent::Fault { .. } => {}
        });
        look.alarms = status.alarms.0;
        look
    }

    /// The verdict: at least 28 frames (of ~41 in 1024 words), none failing its
    /// check, and the alarms in `want` reported exactly when `reported`.
    pub fn check(&self, want: shared::model::Alarms, reported: bool) {
        assert!(self.frames >= 28, "STATUS: {} frames", self.frames);
        assert_eq!(self.failed, 0, "STATUS frames failing their check");
        assert_eq!(
            shared::model::Alarms(self.alarms).contains(want),
            reported,
            "STATUS alarms {:#x}",
            self.alarms
        );
    }
}

/// A HANS-100 controller's ring of eight frames as a head received it: the ring
/// slot of every frame in the order they came, with the park frames, judged step
/// by step within a look (a capture, or a run of periods) and across looks only
/// by what never may come.
#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "hans_to_hans"))]
#[derive(Default, Debug, defmt::Format)]
pub struct RingSteps {
    /// Frames seen: the same slot as the one before in the look, a step forward of
    /// 1..=4 slots (or the first of a look), a step of 5..=7 (back, or further
    /// than the bridge may skip).
    pub frames: u32,
    pub repeats: u32,
    pub distinct: u32,
    pub backwards: u32,
    /// The frame with the flipped bit was seen.
    pub bad_seen: bool,
    /// Park frames; of them before the first frame; frames after a park.
    pub park: u32,
    pub park_before_first: u32,
    pub frames_after_park: u32,
    /// The slot of the frame before in this look.
    last: Option<u32>,
    /// A frame was seen in any look.
    any: bool,
}

#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "hans_to_hans"))]
impl RingSteps {
    /// A new look starts: the next frame is not compared with the one before.
    #[cfg(bridge_pairing = "hans_to_hans")]
    pub fn new_look(&mut self) {
        self.last = None;
    }

    /// Records one park frame.
    pub fn park(&mut self) {
        self.park += 1;
        self.park_before_first += u32::from(!self.any);
    }

    /// Records the frame with the flipped bit.
    pub fn bad(&mut self) {
        self.bad_seen = true;
    }

    /// Records one frame of ring slot `slot`.
    pub fn frame(&mut self, slot: u32) {
        let n = shared::hans::frame::RING_SLOTS as u32;
        self.frames += 1;
        self.frames_after_park += u32::from(self.park > 0);
        match self.last.map(|l| (slot + n - l) % n) {
            Some(0) => self.repeats += 1,
            Some(1..=4) | None => self.distinct += 1,
            Some(_) => self.backwards += 1,
        }
        self.last = Some(slot);
        self.any = true;
    }

    /// The verdict: the flipped frame never; never a step back or beyond 4 slots;
    /// no park before the first frame, nothing but park after it; at least
    /// `min_distinct` new frames and `min_park` park frames.
    pub fn check(&self, min_distinct: u32, min_park: u32) {
        assert!(
            !self.bad_seen,
            "the frame with a flipped bit reached the head"
        );
        assert_eq!(self.backwards, 0, "frames out of order");
        assert_eq!(self.park_before_first, 0, "park before the first frame");
        assert_eq!(self.frames_after_park, 0, "frames after the park");
        assert!(
            self.distinct >= min_distinct,
            "{} distinct frames",
            self.distinct
        );
        assert!(self.park >= min_park, "{} park frames", self.park);
    }
}
