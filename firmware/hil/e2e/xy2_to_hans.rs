//! An XY2-100 controller -> HANS-100 head (`configs/xy2-to-hans.toml`): the XY2-100
//! input task, the HANS-100 bridge loop and the head's HANS STATUS input.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::e2e::checks::{assert_identity_axes, capture, laser_gate_high, phase_end};
    use crate::e2e::source::{e2e_positions, frame_of_x, BsrrSource};
    use crate::e2e::xy2_source::{Levels, SRC_FRAMES, SRC_PINS, SRC_TICK_HZ, SRC_TPF};
    use embassy_stm32::peripherals::PA4;
    use embassy_stm32::Peri;
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
    use xy_bridge::drivers::serial_tx::SerialTx;
    use xy_bridge::tasks::Irqs;

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
        let phase = core::cell::Cell::new(0u8);
        let input_at = core::cell::Cell::new(Instant::now());
        let stop_at = core::cell::Cell::new(None);
        let underrun = core::cell::Cell::new(false);

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
                let no_nss: Option<Peri<'_, PA4>> = None;
                let captured = capture(
                    spi.reborrow(),
                    sck.reborrow(),
                    mosi.reborrow(),
                    no_nss,
                    dma.reborrow(),
                    &mut *look_ring,
                    &mut words,
                    Duration::from_millis(50),
                )
                .await;
                if !captured {
                    log.capture_errors += 1;
                    continue;
                }
                log.looks += 1;
                log.looks_before += u32::from(before);
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
                    log.frames_after_park += u32::from(log.park > 0);
                    log.bad_seen |= is_bad(k);
                    if last.is_some_and(|l| k < l) {
                        log.backwards += 1;
                    }
                    if let Some(p) = prev.filter(|&p| k >= p) {
                        if k == p {
                            log.repeats += 1;
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
    }
}
