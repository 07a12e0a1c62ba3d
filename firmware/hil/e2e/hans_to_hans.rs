//! A HANS-100 controller -> HANS-100 head (`configs/hans-normal-to-hans.toml`): the
//! HANS-100 input tasks, the HANS-100 bridge loop, the head's HANS STATUS input
//! decoded every second half, and the HANS STATUS towards the controller.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::e2e::checks::{
        assert_identity_axes, capture, decode_hans, laser_gate_high, phase_end, AlarmGateWatch,
        RingSteps, StatusLook,
    };
    use crate::e2e::hans_source::{
        bad_burst, controller_rings, frame_of, switch_ring, BAD_AT, BAD_FRAME,
    };
    use core::cell::Cell;
    use embassy_futures::select::{select, Either};
    use embassy_stm32::peripherals::{PA15, PE11};
    use embassy_stm32::{peripherals, Peri};
    use embassy_time::{Duration, Instant};
    use shared::bridge::{AfterHold, GateSource, HansDecode};
    use shared::hans::frame::{write_slot, Frame, RING_BYTES, RING_SLOTS};
    use shared::hans::rx::RxEvent;
    use shared::hans::{status_frame, DeviceExt, GalvoStatus, ZAlarms};
    use shared::model::{Alarms, FaultKind, HeadStatus};
    use xy_bridge::app::{self, Executors};
    use xy_bridge::board::{self, Board};
    use xy_bridge::config::{self, Controller, Roles};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::serial_tx::SerialTx;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// Words per look at the head's output: 819 us, ~80 frame periods at 40 MHz fs
    /// (a look decodes for about as long as it captured, in thread mode: short
    /// looks leave the gate sampler its turn).
    const LOOK_WORDS: usize = 2048;
    /// Words per look at the STATUS towards the controller (41 frame periods).
    const STATUS_WORDS: usize = 1024;
    /// The head's over-temperature alarm, from `ALARM_FROM` into the input to
    /// `ALARM_TO`; the input stops at `RUN`.
    const ALARM_FROM: Duration = Duration::from_millis(150);
    const ALARM_TO: Duration = Duration::from_millis(300);
    const RUN: Duration = Duration::from_millis(450);

    /// The head's STATUS frame for `status` (code 65 with the galvo alarms, DATA3
    /// code 15 with no Z alarm), as a HANS-100 head sends it.
    fn head_status_frame(status: &HeadStatus) -> Frame {
        status_frame(
            &GalvoStatus::velocity_from(status),
            &DeviceExt::ZVelocity {
                velocity: 0,
                alarms: ZAlarms::default(),
            },
        )
        .unwrap()
    }

    /// A ring of eight copies of `frame`.
    fn ring_of(frame: &Frame) -> [u8; RING_BYTES] {
        let mut ring = [0u8; RING_BYTES];
        for slot in 0..RING_SLOTS {
            write_slot(&mut ring, slot, frame).unwrap();
        }
        ring
    }

    /// What the head received, checked frame by frame in every look.
    #[derive(Default, Debug, defmt::Format)]
    struct HeadLog {
        /// Looks taken, before the input; captures that failed (overrun, timeout).
        looks: u32,
        looks_before: u32,
        capture_errors: u32,
        /// Frames decoded before the input; check failures.
        before: u32,
        failed: u32,
        /// Frames that are neither a ring frame nor the park frame.
        unknown: u32,
        /// The ring slots of the frames, in order within each look, and the park
        /// frames.
        steps: RingSteps,
    }

    /// The whole bridge through its own tasks for a HANS-100 controller (normal
    /// mode, channel 1) and a HANS-100 head (axis map identity, Z from the input):
    /// `app::spawn_supervision` spawns the supervisor (watchdog, laser gate), LEDs
    /// and statistics, and the firmware's own `app::spawn_bridge` `hans_in` (line executor) and `hans_decode` (decode
    /// executor) on the TIM3 CH1 fs, `hans_status_out` (SAI2 B on PA0), and for the
    /// head `bridge_hans_out` (SAI1 A on PE6), `line::hans_status_in` (SPI6 on the
    /// TIM3 CH2 fs) passing on every second half, as a HANS-100 controller beside
    /// it makes it (`shared::hans::follow::status_every`), and `status::hans_status`,
    /// whose one receiver follows the STATUS line across the halves it does not
    /// see. The test's two sources
    /// run on the SAI blocks the firmware leaves free, beside the firmware's
    /// blocks of the same SAIs (`drivers::serial_tx` resets an SAI only when its
    /// other block is idle): SAI1 B (PE3) plays the controller as in
    /// `bridge_tasks_hans_to_xy2_end_to_end` (zeros, then the eight ring frames for
    /// 450 ms with the flipped frame's 10 ms burst 100 ms in, then zeros); SAI2 A
    /// (PD11) plays the head's STATUS: healthy frames (code 65, no alarm; code 15,
    /// no Z alarm), from 150 ms to 300 ms into the input an over-temperature
    /// alarm, then healthy again (each switch made between two frames, never
    /// back: [`switch_ring`]). SPI3 and SPI4, which normal mode on channel 1
    /// leaves idle, read back on the head's STATUS fs (TIM3 CH2, PC7, which runs
    /// without a pause once `hans_status_in` started it): SPI3 the head's HANS-100
    /// output in looks of 2048 words, each from a fresh start, SPI4 the HANS
    /// STATUS towards the controller five times, both decoded by `shared`'s
    /// receiver as a head and a controller would.
    ///
    /// Checks: the head as in `bridge_tasks_xy2_to_hans_end_to_end`: no frame before
    /// the input; then every frame passes its check, and is a ring frame (20-bit
    /// positions and DATA3 code 0 pass unchanged) or the park frame; within a look
    /// the ring slot steps by 0..=4, never back, at least 60 % of the frames new
    /// and 1000 in all; the flipped frame never; park only after the last frame
    /// (>= 100 park frames). The STATUS towards the controller: each look >= 28
    /// frames, none failing its check; the lost input (communication alarm)
    /// reported before the input and 100 ms after it, not 50 ms into it, 50 ms into
    /// the head's alarm nor 50 ms after it; the head's over-temperature reported
    /// 50 ms into the alarm and at no other look (the every-second-half decoder
    /// took it in and let it go). The laser gate (PF13 pad, `laser.gate =
    /// "link_ok"` with `off_on_head_alarm`): off before the input, on within 10 ms
    /// and without a gap until the alarm, off from 5 ms into it to its end, on
    /// within 10 ms after it and without a gap, off from 6 ms after the input
    /// stopped for good.
    ///
    /// Jumpers: controller PE3 (SAI1_SD_B, test) -> PD7 (SPI1 MOSI, CH1), PC6 (TIM3
    /// CH1) -> PA5 (SPI1 SCK); head STATUS PD11 (SAI2_SD_A, test) -> PG14 (SPI6
    /// MOSI); PC7 (TIM3 CH2) -> PB3 (SPI6 SCK), PC10 (SPI3 SCK) and PE12 (SPI4
    /// SCK); head output PE6 (SAI1_SD_A) -> PC12 (SPI3 MOSI); STATUS towards the
    /// controller PA0 (SAI2_SD_B) -> PE14 (SPI4 MOSI).
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_hans_to_hans_end_to_end(board: Board) {
        // The baked configuration this test is written for: its roles are the
        // image's (`bridge_pairing`), the settings its expectations rest on are
        // checked here.
        let config = config::load().unwrap();
        let roles = Roles::of(&config);
        assert_identity_axes(&config);
        // Normal mode on channel 1 leaves SPI2..5 idle: two of them read back.
        assert_eq!(
            config.controller.hans.decode,
            HansDecode::Normal(1),
            "controller.hans.decode: this test needs configs/hans-normal-to-hans.toml"
        );
        assert_eq!(config.failsafe.after_hold, AfterHold::Park);
        assert_ne!(config.failsafe.status_timeout_us, 0);
        assert_eq!(config.laser.gate, GateSource::LinkOk);
        assert!(config.laser.off_on_head_alarm, "laser.off_on_head_alarm");
        // The premise of the STATUS checks: beside a HANS-100 controller the head's
        // STATUS decoder gets every second half only.
        assert_eq!(
            shared::hans::follow::status_every(roles.controller == Controller::Hans),
            2
        );
        let f = config.failsafe;
        // Park Z goes out as DATA3 code 0 with 16 bits: exact for these.
        assert_eq!(f.park_z & 0xF, 0, "park_z");
        let park = Frame::new(f.park_x, f.park_y, f.park_z).unwrap();
        assert!(
            (0..=BAD_FRAME).all(|s| frame_of(s) != park),
            "a frame looks parked"
        );
        let slot_of = |f: &Frame| (0..RING_SLOTS as u32).find(|&s| frame_of(s) == *f);

        // The controller's ring, and the same ring with the flipped frame.
        let (ring_bytes, ring_bad) = controller_rings();
        // The head's STATUS rings: healthy, and with the over-temperature alarm.
        let healthy = ring_of(&head_status_frame(&HeadStatus::default()));
        let hot = ring_of(&head_status_frame(&HeadStatus {
            alarms: Alarms::TEMPERATURE,
            ..HeadStatus::default()
        }));
        assert_ne!(healthy, hot);

        let spawner = unsafe {
            // SAFETY: `embedded-test` (feature `embassy-010`) runs async tests as
            // tasks of embassy's thread-mode executor, so the context is embassy's.
            embassy_executor::Spawner::for_current_executor()
        }
        .await;
        let r = board.res;

        // The test's sources, started before the firmware's blocks of the same
        // SAIs (either order works: `SerialTx::new` keeps a running block).
        // SAFETY: SAI1 and SAI2 are the firmware's (`r.hans_out`,
        // `r.hans_status_out`), but it runs only their blocks A and B,
        // respectively; PE3 and PD11 are in no `board::Resources` group and no
        // firmware task uses them. This test is the only user of SAI1 B, SAI2 A
        // and the two pins.
        // DMA2 S1 / S2 are `r.wave`'s, which only a waveform head uses: with a
        // HANS-100 head `spawn_bridge` leaves them alone.
        let (sai1, sai2, pe3, pd11, wave_dma, wave_status_dma) = unsafe {
            (
                peripherals::SAI1::steal(),
                peripherals::SAI2::steal(),
                peripherals::PE3::steal(),
                peripherals::PD11::steal(),
                peripherals::DMA2_CH1::steal(),
                peripherals::DMA2_CH2::steal(),
            )
        };
        // The controller, idle: zeros on the line (on the waveform output's DMA
        // stream: no waveform head in this pairing).
        let ctrl_ring = dma_ring!(".sram2", u8, RING_BYTES);
        let mut ctrl_channel = None;
        let mut controller = SerialTx::new(sai1, pe3, wave_dma, Irqs, &mut ctrl_channel, ctrl_ring);
        // The head's STATUS, healthy from the start (the gate waits for it).
        let status_ring = dma_ring!(".sram2", u8, RING_BYTES);
        status_ring.copy_from_slice(&healthy);
        let mut status_channel = None;
        let mut head_status = SerialTx::new(
            sai2,
            pd11,
            wave_status_dma,
            Irqs,
            &mut status_channel,
            status_ring,
        );

        // The read-backs: SPI3 (head output) and SPI4 (STATUS towards the
        // controller) with their pins and DMA1 streams.
        // SAFETY: they belong to `r.xy3_in`, which `hans_in` takes, but in normal
        // mode on channel 1 (checked above) `HansInput::start` starts SPI1 only
        // and never touches SPI3 / SPI4, their pins or streams (the channel mask,
        // `drivers::hans_lines`). This test is their only user.
        let (mut spi3, mut sck3, mut mosi3, mut dma3) = unsafe {
            (
                peripherals::SPI3::steal(),
                peripherals::PC10::steal(),
                peripherals::PC12::steal(),
                peripherals::DMA1_CH0::steal(),
            )
        };
        let (mut spi4, mut sck4, mut mosi4, mut dma4) = unsafe {
            (
                peripherals::SPI4::steal(),
                peripherals::PE12::steal(),
                peripherals::PE14::steal(),
                peripherals::DMA1_CH1::steal(),
            )
        };

        // The firmware's tasks for this pairing, spawned by the firmware's own
        // `app::spawn_bridge` (the test's peripherals are stolen above).
        let leds = [board.led_green, board.led_yellow, board.led_red];
        app::spawn_supervision(spawner, board.iwdg, board.laser_gate, leds, false);
        app::spawn_bridge(spawner, Executors::start(), config, r);

        // Phases: 0 before the input, 1 while it runs (head OK), 2 the head's
        // alarm, 3 head OK again, 4 once the ring is back at zeros (`stop_at`),
        // 5 done.
        let phase = Cell::new(0u8);
        let input_at = Cell::new(Instant::now());
        let alarm_at = Cell::new(Instant::now());
        let clear_at = Cell::new(Instant::now());
        let stop_at: Cell<Option<Instant>> = Cell::new(None);

        let controller_run = async {
            embassy_time::Timer::after_millis(30).await;
            // The slot being sent may mix zeros and its frame: it fails its check.
            controller.update(|buf| buf.copy_from_slice(&ring_bytes));
            input_at.set(Instant::now());
            phase.set(1);
            embassy_time::Timer::at(input_at.get() + BAD_AT).await;
            bad_burst(&mut controller, &ring_bytes, &ring_bad).await;
            embassy_time::Timer::at(input_at.get() + RUN).await;
            phase.set(4);
            controller.update(|buf| buf.fill(0));
            stop_at.set(Some(Instant::now()));
            embassy_time::Timer::after_millis(300).await;
            phase.set(5);
        };

        // The head's over-temperature alarm.
        let head_run = async {
            while phase.get() < 1 {
                embassy_time::Timer::after_millis(1).await;
            }
            embassy_time::Timer::at(input_at.get() + ALARM_FROM).await;
            switch_ring(&mut head_status, &hot);
            alarm_at.set(Instant::now());
            phase.set(2);
            embassy_time::Timer::at(input_at.get() + ALARM_TO).await;
            switch_ring(&mut head_status, &healthy);
            clear_at.set(Instant::now());
            phase.set(3);
        };

        // The gate every 100 us, per phase.
        let mut gate = AlarmGateWatch::default();
        let gate_sampler = async {
            loop {
                let g = laser_gate_high();
                let p = phase.get();
                let since = match p {
                    0 => Duration::from_ticks(0),
                    1 => input_at.get().elapsed(),
                    2 => alarm_at.get().elapsed(),
                    3 => clear_at.get().elapsed(),
                    4 => stop_at
                        .get()
                        .map_or(Duration::from_ticks(0), |t| t.elapsed()),
                    _ => break,
                };
                gate.sample(p, g, since);
                embassy_time::Timer::after_micros(100).await;
            }
        };

        // The STATUS towards the controller: before the input, 50 ms into it, into
        // the head's alarm and after it, and 100 ms after the input stopped.
        let ctrl_status_ring = dma_ring!(".sram1", u16, 2 * STATUS_WORDS);
        let mut looks: [StatusLook; 5] = Default::default();
        let status_run = async {
            let mut words = [0u16; STATUS_WORDS];
            embassy_time::Timer::after_millis(15).await;
            let starts = [
                Duration::from_millis(50),
                ALARM_FROM + Duration::from_millis(50),
                ALARM_TO + Duration::from_millis(50),
            ];
            for (n, look) in looks.iter_mut().enumerate() {
                match n {
                    0 => {}
                    1..=3 => {
                        while phase.get() < 1 {
                            embassy_time::Timer::after_millis(1).await;
                        }
                        embassy_time::Timer::at(input_at.get() + starts[n - 1]).await;
                    }
                    _ => {
                        while stop_at
                            .get()
                            .is_none_or(|t: Instant| t.elapsed() < Duration::from_millis(100))
                        {
                            embassy_time::Timer::after_millis(1).await;
                        }
                    }
                }
                let no_nss: Option<Peri<'_, PE11>> = None;
                let captured = capture(
                    spi4.reborrow(),
                    sck4.reborrow(),
                    mosi4.reborrow(),
                    no_nss,
                    dma4.reborrow(),
                    &mut *ctrl_status_ring,
                    &mut words,
                    Duration::from_millis(50),
                )
                .await;
                assert!(captured, "STATUS capture {} failed", n);
                *look = StatusLook::of(&words);
            }
        };

        let mut log = HeadLog::default();
        // Looks at the head one after the other, each from a fresh start of SPI3.
        let look_ring = dma_ring!(".sram1", u16, 2 * LOOK_WORDS);
        let reader = async {
            let mut words = [0u16; LOOK_WORDS];
            while phase.get() < 5 {
                let before = phase.get() == 0;
                let no_nss: Option<Peri<'_, PA15>> = None;
                let captured = capture(
                    spi3.reborrow(),
                    sck3.reborrow(),
                    mosi3.reborrow(),
                    no_nss,
                    dma3.reborrow(),
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
                log.steps.new_look();
                decode_hans(&words, &mut |ev| {
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
                    } else if f == park {
                        log.steps.park();
                    } else if f == frame_of(BAD_FRAME) {
                        log.steps.bad();
                    } else if let Some(slot) = slot_of(&f) {
                        log.steps.frame(slot);
                    } else {
                        log.unknown += 1;
                    }
                });
                // The gate sampler's and the STATUS looks' turn: the decode held
                // thread mode for about as long as the capture took, or longer.
                embassy_time::Timer::after_millis(1).await;
            }
        };
        let deadline = phase_end(&phase, 5, Duration::from_millis(100));
        let reader = async { matches!(select(reader, deadline).await, Either::First(())) };
        let (_, _, _, _, read_to_the_end) = embassy_futures::join::join5(
            controller_run,
            head_run,
            gate_sampler,
            status_run,
            reader,
        )
        .await;
        drop(controller);
        drop(head_status);
        defmt::info!("head: {}", log);
        defmt::info!("gate: {}", gate);
        defmt::info!("STATUS: {}", looks);

        assert!(read_to_the_end, "a look at the head never ended");
        assert_eq!(log.capture_errors, 0, "looks that failed");
        // The head: nothing before the input, then what it got, in order, never
        // the flipped frame.
        assert!(log.looks_before >= 1, "no look before the input");
        assert_eq!(log.before, 0, "head frames before the input");
        assert_eq!(log.failed, 0, "head frames failing their check");
        assert_eq!(log.unknown, 0, "head frames that are no frame sent");
        let s = &log.steps;
        assert!(
            s.distinct >= (s.distinct + s.repeats) * 6 / 10,
            "{} new frames, {} repeats",
            s.distinct,
            s.repeats
        );
        s.check(1000, 100);
        // The STATUS towards the controller: the lost input before and after the
        // input only, the head's over-temperature during its alarm only.
        let lost = [true, false, false, false, true];
        let hot = [false, false, true, false, false];
        for ((look, lost), hot) in looks.iter().zip(lost).zip(hot) {
            look.check(Alarms::COMMUNICATION, lost);
            look.check(Alarms::TEMPERATURE, hot);
        }
        // The laser gate: the sampler runs while a look captures or pauses
        // (about half of thread mode's time), so >= ~700 of the alarm's ~1450
        // samples and ~1500 of the tail's are expected; the bounds say it saw them.
        gate.check(300, 600);
        assert!(!laser_gate_high(), "gate on at the end");
    }
}
