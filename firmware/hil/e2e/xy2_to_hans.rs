//! An XY2-100 controller -> HANS-100 head (`configs/xy2-to-hans.toml`): the XY2-100
//! input task, the HANS-100 bridge loop and the head's HANS STATUS input; and a
//! stall of the bridge loop longer than the head's ring (the slot ring guard).

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use core::cell::Cell;

    use crate::e2e::checks::{assert_identity_axes, capture, laser_gate_high, phase_end};
    use crate::e2e::source::{e2e_positions, frame_of_x, BsrrSource};
    use crate::e2e::xy2_source::{Levels, SRC_FRAMES, SRC_PINS, SRC_TICK_HZ, SRC_TPF};
    use embassy_stm32::interrupt::typelevel::{Handler, Interrupt, CEC};
    use embassy_stm32::interrupt::Priority;
    use embassy_stm32::peripherals::PA4;
    use embassy_stm32::{bind_interrupts, Peri};
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_sync::blocking_mutex::Mutex;
    use embassy_time::{Duration, Instant};
    use shared::bridge::AfterHold;
    use shared::hans::frame::{write_slot, Frame, RING_BYTES, RING_SLOTS};
    use shared::hans::rx::{HansRx, Mode as HansMode, RxEvent};
    use shared::hans::{status_frame, DeviceExt, GalvoStatus, ZAlarms};
    use shared::model::{FaultKind, HeadStatus};
    use shared::xy2::tx::Transmitter as Xy2Tx;
    use shared::xy2::{
        decode as xy2_decode, encode as xy2_encode, Frame as Frame2, LinkConfig, StatusLevel,
    };
    use xy_bridge::app::{self, Executors};
    use xy_bridge::board::{self, Board, HANS_FS_HZ};
    use xy_bridge::config::{self, Roles};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::oversample_clock;
    use xy_bridge::drivers::serial_tx::{self, SerialTx};
    use xy_bridge::tasks::{self, Irqs};

    bind_interrupts!(
        /// The stall test's stall (CEC: unused on this board).
        struct StallIrq {
            CEC => StallHandler;
        }
    );

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// Frames the source sends.
    const N: u32 = 30_000;
    /// Every `BAD_EVERY`-th frame (from `BAD_EVERY / 2`) goes out with its X parity
    /// bit flipped: more than the recovery run apart (a check failure breaks it, so
    /// the link still recovers), and at least one inside every look at the head.
    const BAD_EVERY: u32 = 150;
    /// Words per look at the head's output: 1.6 ms, ~160 frames at 40 MHz fs.
    const LOOK_WORDS: usize = 4096;

    /// Whether frame `k` is sent with a flipped parity bit.
    fn is_bad(k: u32) -> bool {
        k % BAD_EVERY == BAD_EVERY / 2
    }

    /// The HANS-100 frame frame `k` becomes (axis map identity): X and Y MSB-aligned
    /// from 16 to 20 bits, Z as DATA3 with extension code 0 (`shared::hans::ext`).
    fn head_frame(k: u32) -> Frame {
        let [x, y, z] = e2e_positions(k).map(|v| u32::from(v) << 4);
        // Every word is below 2^20.
        Frame::new(x, y, z).unwrap()
    }

    /// What the head sent, checked frame by frame in every look.
    #[derive(Default, Debug, defmt::Format)]
    struct HeadLog {
        /// Looks taken, before the input; captures that failed (overrun, timeout).
        looks: u32,
        looks_before: u32,
        capture_errors: u32,
        /// Frames decoded before the input; check failures.
        before: u32,
        failed: u32,
        /// Frames that are neither a frame sent (translated) nor the park frame.
        unknown: u32,
        /// Frames of the input: repeats of the one before in the same look, steps
        /// forward, steps back (in a look or across looks); the largest step in a
        /// look.
        frames: u32,
        repeats: u32,
        distinct: u32,
        backwards: u32,
        max_step: u32,
        /// A frame sent with a flipped bit was seen; consecutive frames of a look
        /// with such a frame between them.
        bad_seen: bool,
        bad_between: u32,
        /// Park frames; of them before the first frame; frames after a park.
        park: u32,
        park_before_first: u32,
        frames_after_park: u32,
        /// The stall test's look across the stall: taken; its frames; its largest
        /// step (not in `max_step`); its runs of zero words longer than any frame
        /// can hold, those cut by the look's ends, and the longest (words).
        stall_look: bool,
        stall_frames: u32,
        stall_max_step: u32,
        zero_runs: u32,
        zero_runs_cut: u32,
        zero_run_words: u32,
    }

    /// The stall (us): a busy loop in the CEC interrupt at P5, above the line
    /// executor (P6, `app::LINE_PRIORITY`, which runs `xy2_in` and
    /// `bridge_hans_out`) and thread mode, below the DMA handlers and the slot ring
    /// guard (P0). Longer than the head's ring (8 slots, 80 us) plus what the loop
    /// writes ahead (30 us) plus two stream-trigger guard periods (80 us): the
    /// head output runs dry whatever the phase, and the guard sees it at four of
    /// the stream's runs and twenty of the slot timer's at least. Short
    /// enough that nothing else runs dry: the XY2-100 input ring (two 250 us
    /// halves) holds less than a half unread when it starts, so 200 us more never
    /// lap it (no input overrun); the source's ring holds a whole 500 us half
    /// then (thread mode ran for [`STALL_DELAY_US`] before); the bridge's input
    /// timeout (1 ms) is not reached (the hold would change the frames).
    const STALL_US: u64 = 200;
    /// When the stall starts, from the start of the look that captures it (room
    /// before it for the read-back's start, after it for the recovery: the look
    /// is 1638 us).
    const STALL_DELAY_US: u64 = 300;
    /// The stall's look: the first one starting 40 ms after the input (the gate is
    /// on within 10 ms).
    const STALL_AFTER_INPUT: Duration = Duration::from_millis(40);
    /// Guard runs from the stream's trigger (its half-transfer and
    /// transfer-complete interrupts) come every 62 or 63 bytes of 12.5 MHz bits:
    /// 39.68 or 40.32 us (in ns).
    const RUN_MIN_NS: u64 = 62 * 8 * 80;
    const RUN_MAX_NS: u64 = 63 * 8 * 80;
    /// Guard runs from the slot timer (TIM7, `serial_tx::SLOT_TICK_NS`) come
    /// every 8 us; a run may start up to [`TICK_LATE_US`] late (a critical
    /// section or another P0 handler first), so a window of `w` us holds at
    /// least `w / 8 - 1` and at most `w / 8 + 1` of them.
    const TICK_NS: u64 = serial_tx::SLOT_TICK_NS;
    const TICK_LATE_US: u64 = 2;
    /// The loop writes each frame two slots ahead of the one the DMA fetches
    /// (`hans::tx::LEAD_SLOTS`), so at the stall's start the DMA enters a slot
    /// not written for this lap within three slots (30 us) of the loop's last
    /// write, which came before the stall.
    const LEAD_US: u64 = 30;
    /// After the stall, until the loop writes again: pending P0 handlers,
    /// `xy2_in` (woken as well: the half completed during the stall) and the
    /// loop's ~22 overdue slots through the bridge. Estimated, not measured
    /// (tens of microseconds at 400-480 MHz; a bench run should log the
    /// probe's figures and tighten this).
    const CATCH_UP_US: u64 = 100;
    /// Gate off during the stall: the DMA enters the unwritten slot at most
    /// [`LEAD_US`] in; the slot timer's next run comes within a tick (8 us) plus
    /// [`TICK_LATE_US`] of that, i.e. within one slot (10 us: the guard's bound,
    /// `serial_tx` "The slot timer"); plus the probe's resolution (1 us). It was
    /// `LEAD_US` + a stream run period (41 us) + 2 = 73 us with the stream's
    /// runs alone.
    const GATE_OFF_MAX_US: u64 = LEAD_US + TICK_NS / 1000 + TICK_LATE_US + 1;
    /// Misses the guard counts during the stall: every run, of either trigger,
    /// from the DMA's entry into the first unwritten slot (at most [`LEAD_US`]
    /// in; at least 10 us in less up to 10 us of the loop's wake-up jitter, so
    /// from the start at worst) to the stall's end. Least: the slot timer's
    /// runs in the last `STALL_US - LEAD_US` (170 us: 21 - 1) and the stream's
    /// (4); most: both over the whole stall, one more each (25 + 1, 5 + 1).
    const MISSES_MIN: u32 = ((STALL_US - LEAD_US) * 1000 / TICK_NS) as u32 - 1
        + ((STALL_US - LEAD_US) * 1000 / RUN_MAX_NS) as u32;
    const MISSES_MAX: u32 =
        (STALL_US * 1000 / TICK_NS) as u32 + 1 + (STALL_US * 1000 / RUN_MIN_NS) as u32 + 1;
    /// Misses after the stall, before the loop's first write publishes a slot
    /// ahead of the DMA: the runs of both triggers within [`CATCH_UP_US`].
    const MISSES_AFTER_MAX: u32 = (CATCH_UP_US * 1000).div_ceil(TICK_NS) as u32
        + (CATCH_UP_US * 1000).div_ceil(RUN_MIN_NS) as u32;
    /// The gate on again after the stall's end: the loop's first write (within
    /// [`CATCH_UP_US`]), whose look restarts the gate rule, then three wakes
    /// (10 us apart, `GATE_ON_HISTORY`) with the gate on, and 10 us of jitter.
    const GATE_BACK_MAX_US: u64 = CATCH_UP_US + 3 * 10 + 10;
    /// Words of the read-back (16 samples at 40 MHz: 0.4 us each) that no frame
    /// can hold as zeros: a frame is 125 bits (10 us) starting with its start
    /// marker `1 1 1 0 1`, so it holds at most 120 zero bits (9.6 us, 24 words),
    /// and frames follow back to back; 32 words (12.8 us) leave a word either side.
    const LONG_ZEROS: usize = 32;
    /// The zeros at the head across the stall (us): from the DMA's entry into the
    /// first unwritten slot (10..30 us after the loop's last write, which was at
    /// most 10 us + jitter before the stall) to the loop's first slot after it
    /// (written within [`CATCH_UP_US`] of the stall's end, two slots ahead: on the
    /// wire 10..20 us later), the SAI FIFO's lag (under 6 us) the same at both
    /// ends; 10 us more either side for a frame's trailing zero bits, the word
    /// grid and jitter.
    const ZEROS_MIN_US: u64 = STALL_US - LEAD_US - 10;
    const ZEROS_MAX_US: u64 = STALL_US + CATCH_UP_US + 20 + 10 + 10;
    /// The largest step between two frames in the stall's look: the slots the
    /// stall and the catch-up span (one frame each, `SlotEvents`), a half of
    /// input frames (25) more that may wait beyond the backlog the loop drains
    /// faster, and the usual 4.
    const STALL_STEP_MAX: u32 = ((STALL_US + CATCH_UP_US + 20) / 10) as u32 + 25 + 4;

    /// What the stall saw (only P0 runs meanwhile), from its start: the gate then,
    /// when it first read low (us; `u32::MAX`: never), whether it read high again
    /// after that; the guards' miss count at its start and end.
    #[derive(Clone, Copy, Debug, defmt::Format)]
    struct Probe {
        ran: bool,
        gate_at_start: bool,
        gate_off_us: u32,
        gate_on_again: bool,
        misses_at_start: u32,
        misses_at_end: u32,
    }

    static PROBE: Mutex<CriticalSectionRawMutex, Cell<Probe>> = Mutex::new(Cell::new(Probe {
        ran: false,
        gate_at_start: false,
        gate_off_us: u32::MAX,
        gate_on_again: false,
        misses_at_start: 0,
        misses_at_end: 0,
    }));

    /// The CEC interrupt: one busy loop of [`STALL_US`] watching the laser gate,
    /// with the guard's miss count read at both ends.
    struct StallHandler;

    impl Handler<CEC> for StallHandler {
        unsafe fn on_interrupt() {
            let t0 = Instant::now();
            let gate_at_start = laser_gate_high();
            let misses_at_start = tasks::guard_misses();
            let len = Duration::from_micros(STALL_US);
            let (mut off, mut on_again) = (u32::MAX, false);
            loop {
                let t = t0.elapsed();
                if t >= len {
                    break;
                }
                let g = laser_gate_high();
                if off == u32::MAX {
                    if !g {
                        off = t.as_micros() as u32;
                    }
                } else {
                    on_again |= g;
                }
            }
            let p = Probe {
                ran: true,
                gate_at_start,
                gate_off_us: off,
                gate_on_again: on_again,
                misses_at_start,
                misses_at_end: tasks::guard_misses(),
            };
            PROBE.lock(|c| c.set(p));
        }
    }

    /// Readies the stall: CEC at P5, nothing pending; `_irq` proves the handler.
    fn arm_stall(_irq: impl embassy_stm32::interrupt::typelevel::Binding<CEC, StallHandler>) {
        PROBE.lock(|c| {
            c.set(Probe {
                ran: false,
                ..c.get()
            })
        });
        CEC::set_priority(Priority::P5);
        CEC::unpend();
        // SAFETY: the handler bound for CEC is `StallHandler` (`_irq`), which only
        // waits, reads pins and the guards' count, and writes `PROBE`.
        unsafe { CEC::enable() };
    }

    /// What the reader measured around the stall, in thread mode: the guards'
    /// miss count just before it was pended, the gate's return after it (us;
    /// `None`: not within 300 us) and the miss count then.
    #[derive(Clone, Copy, Debug, Default, defmt::Format)]
    struct AfterStall {
        pended: bool,
        misses_before: u32,
        gate_back_us: Option<u64>,
        misses_then: u32,
    }

    /// Runs of zero words in `words`: those of more than [`LONG_ZEROS`] that the
    /// look's ends do not cut, those that they cut, and the longest (words).
    fn zero_runs(words: &[u16]) -> (u32, u32, u32) {
        let (mut whole, mut cut, mut longest) = (0u32, 0u32, 0usize);
        let mut start = 0;
        while start < words.len() {
            if words[start] != 0 {
                start += 1;
                continue;
            }
            let len = words[start..].iter().take_while(|&&w| w == 0).count();
            if len > LONG_ZEROS {
                if start == 0 || start + len == words.len() {
                    cut += 1;
                } else {
                    whole += 1;
                    longest = longest.max(len);
                }
            }
            start += len;
        }
        (whole, cut, longest as u32)
    }

    /// The whole bridge through its own tasks for an XY2-100 controller and a
    /// HANS-100 head (axis map identity, Z from the input): `app`'s per-side
    /// functions spawn the supervisor (watchdog, laser gate), LEDs and statistics,
    /// `line::xy2_in` and the STATUS level out, and for the head `bridge_hans_out`,
    /// `line::hans_status_in` and `status::hans_status`, as `app::spawn_bridge`
    /// does for this pairing. [`BsrrSource`] plays 30 000 frames into the
    /// controller-side XY2 input, every 150th with its X parity bit flipped. SAI2
    /// block B (HANS STATUS out, free here) plays the head's STATUS on PG10: eight
    /// healthy status frames (code 65, no alarm; code 15, no Z alarm), which the
    /// gate waits for (`failsafe.status_timeout_us`). The head's HANS-100 output
    /// (SAI1, PE6) is read back by SPI1 (free here) clocked by fs on TIM3 CH1 (PC6,
    /// which only a HANS-100 controller uses), in looks of 4096 words from a fresh
    /// start, one after the other, decoded by `shared`'s receiver (channel 1).
    ///
    /// Checks: no frame before the input (the ring holds zeros); then every frame
    /// decodes (no check failure: a slot is never written while it is sent) and is
    /// a frame sent, translated (X, Y, Z each `<< 4`), or the park frame; frames
    /// never go back (in a look or across looks) and step by at most 4 in a look,
    /// at least 60 % of them new; a frame sent with a flipped bit never, and at
    /// least one of them fell between two frames of a look (dropped where it would
    /// have been); park only after the last frame, nothing after it (>= 100 park
    /// frames seen). The laser gate (PF13 pad) and the STATUS level towards the
    /// controller (PA0) as in `bridge_tasks_xy2_to_xy3_end_to_end`.
    ///
    /// Jumpers: source PE2 -> PE7, PE3 -> PG0, PE4 -> PG1, PE9 -> PG2, PE10 -> PG3;
    /// head PE6 (SAI1_SD_A) -> PD7 (SPI1 MOSI), PC6 (TIM3 CH1) -> PA5 (SPI1 SCK);
    /// head STATUS PG10 (SAI2_SD_B, test) -> PG14, PC7 (TIM3 CH2) -> PB3.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy2_to_hans_end_to_end(board: Board) {
        run(board, false).await;
    }

    /// A stall of the bridge loop longer than the HANS-100 head's ring (the slot
    /// ring guard, `serial_tx` "No stale frames"), through the same tasks, source,
    /// wiring and read-back as `bridge_tasks_xy2_to_hans_end_to_end`: in the first
    /// look 40 ms into the input, [`STALL_DELAY_US`] after its capture started, the
    /// reader pends a [`STALL_US`] (200 us) busy loop at P5 (`StallHandler`),
    /// which holds the line executor (the input task and the bridge loop) and
    /// thread mode; only P0 (the DMA, the guard) runs. The input ring and the
    /// source outlast it (no overrun, no hold): the head output alone runs dry.
    ///
    /// Checks: every check of the end-to-end test (frames in order across every
    /// look, each a frame sent or park, none failing its check, the flipped frame
    /// never, the gate on until the input stops and the STATUS level), with the
    /// stall's look apart for the step size; and: the stall ran with the gate on
    /// at its start and no guard miss before it (none from the input's start: the
    /// loop kept up); the gate off within [`GATE_OFF_MAX_US`] of its start and not
    /// on again during it; [`MISSES_MIN`]..=[`MISSES_MAX`] guard misses counted
    /// during it (`tasks::guard_misses`, the statistics' count) and at most
    /// [`MISSES_AFTER_MAX`] after it; in the stall's look no slot of an earlier
    /// lap: exactly one run of zeros longer than any frame holds (none cut by the
    /// look's ends), [`ZEROS_MIN_US`]..=[`ZEROS_MAX_US`] long, and on either side
    /// only frames sent, in order (a replayed lap would step back), the largest
    /// step at most [`STALL_STEP_MAX`]; the bridge resumes: the gate on again
    /// within [`GATE_BACK_MAX_US`] of the stall's end (the reader watches it,
    /// before the level watch samples again), frames flow to the end.
    ///
    /// Jumpers: those of `bridge_tasks_xy2_to_hans_end_to_end`.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy2_to_hans_stall_beyond_output(board: Board) {
        let (log, after, misses_at_input) = run(board, true).await;
        let probe = PROBE.lock(|c| c.get());
        defmt::info!("stall: {}; after: {}", probe, after);
        // The design's bounds, as the constants' comments derive them.
        const {
            assert!(STALL_US * 1000 > 8 * 10_000 + LEAD_US * 1000 + 2 * RUN_MAX_NS);
            assert!(MISSES_MIN >= 24 && MISSES_MIN <= MISSES_MAX);
            assert!(GATE_OFF_MAX_US <= LEAD_US + 10 + 1);
            assert!(ZEROS_MIN_US * 1000 > LONG_ZEROS as u64 * 400);
        }
        assert!(after.pended, "no look 40 ms into the input to stall in");
        assert!(probe.ran, "the stall never ran");
        assert!(log.stall_look, "the stall's look failed");
        // Before: the gate on, no miss since the input started.
        assert!(probe.gate_at_start, "gate off when the stall began");
        assert_eq!(
            after.misses_before, misses_at_input,
            "guard misses before the stall"
        );
        assert_eq!(
            probe.misses_at_start, after.misses_before,
            "a guard miss between the pend and the stall"
        );
        // During: the gate off within the guard's bound and for good.
        assert!(
            probe.gate_off_us != u32::MAX,
            "the gate never went off during the stall"
        );
        assert!(
            u64::from(probe.gate_off_us) <= GATE_OFF_MAX_US,
            "gate off {} us into the stall (bound {})",
            probe.gate_off_us,
            GATE_OFF_MAX_US
        );
        assert!(!probe.gate_on_again, "gate on again during the stall");
        // Counted: a miss per guard run that found the DMA on an unwritten slot.
        let during = probe.misses_at_end.wrapping_sub(probe.misses_at_start);
        assert!(
            (MISSES_MIN..=MISSES_MAX).contains(&during),
            "{} guard misses during the stall (expected {}..={})",
            during,
            MISSES_MIN,
            MISSES_MAX
        );
        let later = after.misses_then.wrapping_sub(probe.misses_at_end);
        assert!(
            later <= MISSES_AFTER_MAX,
            "{} guard misses after the stall",
            later
        );
        // At the head: zeros, never an old lap's frame, across the stall.
        assert_eq!(log.zero_runs_cut, 0, "the zeros cut by the look's ends");
        assert_eq!(log.zero_runs, 1, "runs of zeros in the stall's look");
        let zeros_us = u64::from(log.zero_run_words) * 2 / 5;
        assert!(
            (ZEROS_MIN_US..=ZEROS_MAX_US).contains(&zeros_us),
            "{} us of zeros (expected {}..={})",
            zeros_us,
            ZEROS_MIN_US,
            ZEROS_MAX_US
        );
        assert!(
            log.stall_frames >= 100,
            "{} frames in the stall's look",
            log.stall_frames
        );
        assert!(
            log.stall_max_step <= STALL_STEP_MAX,
            "a step of {} frames across the stall",
            log.stall_max_step
        );
        // Resumed.
        let back = after
            .gate_back_us
            .expect("gate not on again 300 us after the stall");
        assert!(
            back <= GATE_BACK_MAX_US,
            "gate on {} us after the stall (bound {})",
            back,
            GATE_BACK_MAX_US
        );
    }

    /// The body of the two tests: the end-to-end run, with the stall (`stall`) in
    /// one look; its checks, then what the stall test checks further: the head's
    /// log, the reader's measurements around the stall and the guards' miss count
    /// when the input started.
    async fn run(board: Board, stall: bool) -> (HeadLog, AfterStall, u32) {
        use embassy_futures::select::{select, Either};

        // The baked configuration this test is written for: its roles are the
        // image's (`bridge_pairing`), the settings its expectations rest on are
        // checked here.
        let config = config::load().unwrap();
        let roles = Roles::of(&config);
        assert_identity_axes(&config);
        assert_eq!(config.failsafe.after_hold, AfterHold::Park);
        assert_ne!(config.failsafe.status_timeout_us, 0);
        let f = config.failsafe;
        // Park Z goes out as DATA3 code 0 with 16 bits: exact for these.
        assert_eq!(f.park_z & 0xF, 0, "park_z");
        let park = Frame::new(f.park_x, f.park_y, f.park_z).unwrap();
        assert!(
            (0..N).all(|k| head_frame(k) != park),
            "a frame looks parked"
        );
        assert!(
            (0..N).all(|k| frame_of_x(e2e_positions(k)[0]) == k),
            "frame_of_x"
        );
        let link = LinkConfig {
            mode: config.controller.xy2.mode,
            parity: config.controller.xy2.parity,
        };
        // The flipped bit is the parity bit: the word still carries the frame's X
        // (which would show at the head if it got through), and fails its check.
        let bad_x = Frame2::Position16(e2e_positions(BAD_EVERY / 2)[0]);
        let bad_word = xy2_encode(bad_x, &link).unwrap() ^ 1;
        assert!(xy2_decode(bad_word, &link).is_err(), "flipped word passes");
        assert_eq!(xy2_decode(bad_word ^ 1, &link), Ok(bad_x));
        let status_level = StatusLevel {
            polarity: config.controller.xy2.polarity,
        };

        let spawner = unsafe {
            // SAFETY: `embedded-test` (feature `embassy-010`) runs async tests as
            // tasks of embassy's thread-mode executor, so the context is embassy's.
            embassy_executor::Spawner::for_current_executor()
        }
        .await;
        let r = board.res;

        // The controller side's source, idle, on the head backchannel's TX stream
        // (DMA1 S6; no head backchannel in this pairing).
        let tx = Xy2Tx::new(SRC_PINS, SRC_TPF, link).unwrap();
        let mut source = BsrrSource::start(
            r.head_back.tx_dma,
            dma_ring!(".sram1", u32, 2 * SRC_FRAMES * SRC_TPF),
            tx.idle_word(),
            SRC_TICK_HZ,
        );
        // The head's STATUS: SAI2 B on PG10 (SPI1's NSS pin, unused here).
        let healthy = status_frame(
            &GalvoStatus::velocity_from(&HeadStatus::default()),
            &DeviceExt::ZVelocity {
                velocity: 0,
                alarms: ZAlarms::default(),
            },
        )
        .unwrap();
        let status_ring = dma_ring!(".sram2", u8, RING_BYTES);
        for slot in 0..RING_SLOTS {
            write_slot(status_ring, slot, &healthy).unwrap();
        }
        let x = r.xy3_in;
        let s = r.hans_status_out;
        let mut status_channel = None;
        let _head_status = SerialTx::new(
            s.sai,
            x.u.nss,
            s.dma,
            Irqs,
            &mut status_channel,
            status_ring,
        );

        // The firmware's tasks for this pairing, spawned as `app::spawn_bridge` does.
        let leds = [board.led_green, board.led_yellow, board.led_red];
        app::spawn_supervision(spawner, board.iwdg, board.laser_gate, leds, false);
        let ex = Executors::start();
        let head_enable = app::head_drivers(r.head_enable, r.head_mux, roles.head);
        // fs on CH2 for the head's STATUS, as `spawn_bridge` starts it, and on CH1
        // (PC6, unused by this pairing) for the test's read-back.
        let fs = oversample_clock::start(r.fs.tim, Some(r.fs.ctrl), Some(r.fs.status));
        let mut fs_look = fs.ctrl;
        fs_look.run();
        app::controller_xy2(
            spawner,
            ex,
            &config,
            r.xy2_in,
            r.ctrl_status,
            r.back.de,
            x.sck_buffer_oe,
        );
        app::head_hans(
            ex,
            &config,
            roles,
            r.hans_out,
            head_enable,
            r.hans_status_in,
            fs.status,
        );

        // The head's output read back: SPI1 on the fs clock, MOSI PD7 (HANS CH1).
        let (mut spi, mut sck, mut dma) = (x.u.spi, x.u.sck, x.u.dma);
        let mut mosi = r.hans_in.ch1;
        let look_ring = dma_ring!(".sram1", u16, 2 * LOOK_WORDS);

        // Phases, set by the source: 0 before the input, 1 while frames are written,
        // 2 once the last frame is written (`stop_at`: once it played), 3 done.
        let phase = Cell::new(0u8);
        let input_at = Cell::new(Instant::now());
        let stop_at = Cell::new(None);
        let underrun = Cell::new(false);
        let misses_at_input = Cell::new(0u32);
        let mut after = AfterStall::default();
        if stall {
            arm_stall(StallIrq);
        }

        let source_run = async {
            embassy_time::Timer::after_millis(30).await;
            let mut half = [0u32; SRC_FRAMES * SRC_TPF];
            for h in 0..N / SRC_FRAMES as u32 {
                for (f, slot) in half.chunks_exact_mut(SRC_TPF).enumerate() {
                    let k = h * SRC_FRAMES as u32 + f as u32;
                    let [x, y, z] =
                        e2e_positions(k).map(|v| xy2_encode(Frame2::Position16(v), &link).unwrap());
                    let x = if is_bad(k) { x ^ 1 } else { x };
                    tx.write_words(slot, [x, y, z]).unwrap();
                }
                if !source.write(&half).await {
                    underrun.set(true);
                }
                if h == 0 {
                    input_at.set(Instant::now());
                    misses_at_input.set(tasks::guard_misses());
                    phase.set(1);
                }
            }
            phase.set(2);
            if !source.finish(&mut half, tx.idle_word()).await {
                underrun.set(true);
            }
            stop_at.set(Some(Instant::now()));
            embassy_time::Timer::after_millis(300).await;
            phase.set(3);
        };

        let mut lv = Levels::default();
        let levels = lv.watch(&phase, &input_at, &stop_at, status_level);

        let mut log = HeadLog::default();
        // Looks at the head one after the other, each from a fresh start of SPI1
        // (a look decodes for about as long as it captured: a continuous capture
        // would overrun).
        let reader = async {
            let mut words = [0u16; LOOK_WORDS];
            let mut last: Option<u32> = None;
            while phase.get() < 3 {
                let before = phase.get() == 0;
                let stall_here = stall
                    && !after.pended
                    && phase.get() == 1
                    && input_at.get().elapsed() >= STALL_AFTER_INPUT;
                let no_nss: Option<Peri<'_, PA4>> = None;
                let look = capture(
                    spi.reborrow(),
                    sck.reborrow(),
                    mosi.reborrow(),
                    no_nss,
                    dma.reborrow(),
                    &mut *look_ring,
                    &mut words,
                    Duration::from_millis(50),
                );
                // The stall, pended from thread mode while the capture's DMA runs:
                // it has run when `pend` returns (P5 over thread mode); the gate's
                // return is then watched here, before any other thread-mode task
                // (the level watch) runs again.
                let stall_run = async {
                    if !stall_here {
                        return;
                    }
                    embassy_time::Timer::after_micros(STALL_DELAY_US).await;
                    after.pended = true;
                    after.misses_before = tasks::guard_misses();
                    CEC::pend();
                    let end = Instant::now();
                    while !laser_gate_high() && end.elapsed() < Duration::from_micros(300) {}
                    if laser_gate_high() {
                        after.gate_back_us = Some(end.elapsed().as_micros());
                    }
                    after.misses_then = tasks::guard_misses();
                };
                let (captured, ()) = embassy_futures::join::join(look, stall_run).await;
                if !captured {
                    log.capture_errors += 1;
                    continue;
                }
                log.looks += 1;
                log.looks_before += u32::from(before);
                if stall_here {
                    log.stall_look = true;
                    (log.zero_runs, log.zero_runs_cut, log.zero_run_words) = zero_runs(&words);
                }
                let mut hans = HansRx::new(HANS_FS_HZ, HansMode::Normal { channel: 1 }).unwrap();
                let mut prev: Option<u32> = None;
                hans.push(&[&words], &mut |ev| {
                    let f = match ev {
                        RxEvent::Frame(f) => f,
                        RxEvent::Fault {
                            kind: FaultKind::CheckFailed,
                            ..
                        } => {
                            log.failed += 1;
                            return;
                        }
                        RxEvent::Fault { .. } => return,
                    };
                    if before {
                        log.before += 1;
                        return;
                    }
                    if f == park {
                        log.park += 1;
                        log.park_before_first += u32::from(last.is_none());
                        return;
                    }
                    let k = frame_of_x((f.data1() >> 4) as u16);
                    if k >= N || head_frame(k) != f {
                        log.unknown += 1;
                        return;
                    }
                    log.frames += 1;
                    log.stall_frames += u32::from(stall_here);
                    log.frames_after_park += u32::from(log.park > 0);
                    log.bad_seen |= is_bad(k);
                    if last.is_some_and(|l| k < l) {
                        log.backwards += 1;
                    }
                    if let Some(p) = prev.filter(|&p| k >= p) {
                        if k == p {
                            log.repeats += 1;
                        } else if stall_here {
                            log.distinct += 1;
                            log.stall_max_step = log.stall_max_step.max(k - p);
                        } else {
                            log.distinct += 1;
                            log.max_step = log.max_step.max(k - p);
                        }
                        log.bad_between += u32::from((p + 1..k).any(is_bad));
                    }
                    prev = Some(k);
                    last = Some(last.map_or(k, |l| l.max(k)));
                });
            }
        };
        let deadline = phase_end(&phase, 3, Duration::from_millis(100));
        let reader = async { matches!(select(reader, deadline).await, Either::First(())) };
        let (_, _, read_to_the_end) =
            embassy_futures::join::join3(source_run, levels, reader).await;
        drop(source);
        defmt::info!("head: {}", log);

        assert!(
            !underrun.get(),
            "the source's DMA ran out of words (test bench too slow)"
        );
        assert!(read_to_the_end, "a look at the head never ended");
        assert_eq!(log.capture_errors, 0, "looks that failed");
        // The head: nothing before the input, then what it got, in order,
        // translated, never a frame with a flipped bit.
        assert!(log.looks_before >= 1, "no look before the input");
        assert_eq!(log.before, 0, "head frames before the input");
        assert_eq!(log.failed, 0, "head frames failing their check");
        assert_eq!(log.unknown, 0, "head frames that are no frame sent");
        assert!(
            !log.bad_seen,
            "a frame with a flipped parity bit reached the head"
        );
        assert!(log.bad_between >= 1, "no look spanned a flipped frame");
        assert_eq!(log.backwards, 0, "frames out of order");
        assert!(log.max_step <= 4, "a step of {} frames", log.max_step);
        assert!(
            log.distinct >= (log.distinct + log.repeats) * 6 / 10 && log.distinct >= 1000,
            "{} new frames, {} repeats",
            log.distinct,
            log.repeats
        );
        assert_eq!(log.park_before_first, 0, "park before the first frame");
        assert_eq!(log.frames_after_park, 0, "frames after the park");
        assert!(log.park >= 100, "{} park frames", log.park);
        // The laser gate and the STATUS towards the controller.
        lv.check();
        assert!(!laser_gate_high(), "gate on at the end");
        if stall {
            CEC::disable();
        }
        (log, after, misses_at_input.get())
    }
}
