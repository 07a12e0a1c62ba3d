//! A HANS-100 controller -> XY2-100 head (`configs/hans-normal-to-xy2.toml`,
//! `configs/hans-super-to-xy2.toml`): the HANS-100 input tasks and the waveform
//! bridge loop with an XY2-100 encoder.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::e2e::checks::{
        assert_identity_axes, assert_mux_on_waveform, head_drivers_on, laser_gate_high, phase_end,
        GateWatch, Xy2Periods, HEAD_XY2_PINS,
    };
    use embassy_futures::select::{select, Either};
    use embassy_stm32::gpio::{AnyPin, Level, Output, Speed};
    use embassy_stm32::peripherals::PG8;
    use embassy_stm32::{pac, peripherals, Peri};
    use embassy_time::{with_timeout, Duration, Instant};
    use shared::bridge::{AfterHold, Timing};
    use shared::hans::frame::{read_slot, write_slot, Frame, FRAME_BITS, RING_BYTES, RING_SLOTS};
    use shared::hans::rx::{HansRx, Mode as HansMode, RxEvent};
    use shared::hans::tx::LEAD_SLOTS;
    use shared::hans::StatusReceiver;
    use shared::model::{Alarms, FaultKind, HeadStatus};
    use shared::xy2::rx::Receiver as Xy2Receiver;
    use shared::xy2::{LinkConfig, Mode};
    use xy_bridge::app::{self, Executors};
    use xy_bridge::board::{self, Board, HansStatusInRes, HANS_FS_HZ};
    use xy_bridge::config::{self, Roles};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::oversample_clock;
    use xy_bridge::drivers::serial_tx::SerialTx;
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    use xy_bridge::drivers::xy2_sampler::Xy2Sampler;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// The ring slot that carries the frame with a flipped bit for [`BAD_FOR`],
    /// [`BAD_AT`] into the run (once the link runs: in normal mode a check failure
    /// breaks the recovery run, so a bad frame every lap would keep the link down).
    const BAD_SLOT: usize = 5;
    const BAD_AT: Duration = Duration::from_millis(100);
    const BAD_FOR: Duration = Duration::from_millis(10);
    /// The frame number whose corrupted copy is sent: no other slot carries it.
    const BAD_FRAME: u32 = RING_SLOTS as u32;
    /// Samples per read of the head's XY2 output (25 frames of 20 bits).
    const CHUNK: usize = 500;
    /// How long the controller sends.
    const RUN: Duration = Duration::from_millis(300);

    /// Head positions (X, Y, Z, 16 bits) of the frame in ring slot `slot`: none is
    /// the park position's 0x8000 on X, and no two slots share an X.
    fn positions(slot: u32) -> [u16; 3] {
        [
            (0x1000 + slot * 0x1357) as u16,
            (0x2345 + slot * 0x0F0F) as u16,
            (0xC000 - slot * 0x0777) as u16,
        ]
    }

    /// The controller's frame in slot `slot`: each position MSB-aligned in its
    /// 20-bit word (low four bits zero, so the 20 -> 16-bit resize is exact), DATA3
    /// with extension code 0 (a Z position: `shared::hans::ext`).
    fn frame_of(slot: u32) -> Frame {
        let [x, y, z] = positions(slot).map(|v| u32::from(v) << 4);
        // Every word is below 2^20.
        Frame::new(x, y, z).unwrap()
    }

    /// Copies slot `slot`'s bits of `image` into `ring` (its first and last bytes
    /// are shared with the neighbouring slots, which keep theirs).
    fn copy_slot(ring: &mut [u8; RING_BYTES], image: &[u8; RING_BYTES], slot: usize) {
        for bit in slot * FRAME_BITS..(slot + 1) * FRAME_BITS {
            let mask = 0x80u8 >> (bit % 8);
            ring[bit / 8] = ring[bit / 8] & !mask | image[bit / 8] & mask;
        }
    }

    /// Runs `f` on the controller's ring with interrupts off, only while slot
    /// `slot` is at least `LEAD_SLOTS` ahead of the one the DMA fetches and not the
    /// one just behind it (so neither the DMA nor the SAI FIFO holds any of its
    /// bits: `drivers::serial_tx`); returns whether it ran. A slot is then never
    /// sent half old, half new.
    fn update_ahead(
        tx: &mut SerialTx<'_>,
        slot: usize,
        f: impl FnOnce(&mut [u8; RING_BYTES]),
    ) -> bool {
        cortex_m::interrupt::free(|_| {
            let ahead = (slot + RING_SLOTS - tx.sending_slot()) % RING_SLOTS;
            let safe = (LEAD_SLOTS..RING_SLOTS - 1).contains(&ahead);
            if safe {
                tx.update(f);
            }
            safe
        })
    }

    /// What the head received, checked period by period against the ring's frames.
    #[derive(Default, Debug, defmt::Format)]
    struct HeadLog {
        /// The periods decoded, and of them the ones before the input, with a
        /// line failing its check or missing, with a framing fault.
        head: Xy2Periods,
        /// Periods that are neither a ring frame (translated) nor the park position.
        unknown: u32,
        /// Frames seen: the same slot as the last one, a step forward of 1..=4
        /// slots, a step of 5..=7 (back, or further than the bridge may skip).
        frames: u32,
        repeats: u32,
        distinct: u32,
        backwards: u32,
        /// The frame with the flipped bit was seen.
        bad_seen: bool,
        /// Park periods; of them before the first frame; frames after a park.
        park: u32,
        park_before_first: u32,
        frames_after_park: u32,
    }

    /// One look at the HANS STATUS stream towards the controller (PA0): SPI6,
    /// clocked by fs on TIM3 CH2 (PC7, which this pairing leaves free), captures
    /// 1024 words (41 frame periods) from a fresh start, decoded by `shared`'s
    /// HANS-100 receiver (channel 1) as the controller would.
    #[derive(Default, Debug, defmt::Format)]
    struct StatusLook {
        /// Frames decoded, frames failing their check.
        frames: u32,
        failed: u32,
        /// The alarms the frames report (`StatusReceiver` over all of them).
        alarms: u32,
    }

    async fn status_look(s: &mut HansStatusInRes, ring: &mut [u16]) -> StatusLook {
        let no_nss: Option<Peri<'_, PG8>> = None;
        let mut rx = SpiSlaveRx::new(
            s.spi.reborrow(),
            s.sck.reborrow(),
            s.mosi.reborrow(),
            no_nss,
            s.dma.reborrow(),
            Irqs,
            ring,
        )
        .unwrap();
        let mut words = [0u16; 1024];
        with_timeout(Duration::from_millis(200), rx.read_exact(&mut words))
            .await
            .unwrap()
            .unwrap();
        let mut hans_rx = HansRx::new(HANS_FS_HZ, HansMode::Normal { channel: 1 }).unwrap();
        let mut receiver = StatusReceiver::new();
        let mut status = HeadStatus::default();
        let mut look = StatusLook::default();
        hans_rx.push(&[&words], &mut |ev| match ev {
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

    /// The whole bridge through its own tasks for a HANS-100 controller and an
    /// XY2-100 head (axis map identity, Z from the input, free-running at 100 kHz):
    /// `app`'s per-side functions spawn the supervisor (watchdog, laser gate), LEDs
    /// and statistics, `hans_in` (line executor) and `hans_decode` (decode
    /// executor) on the TIM3 CH1 oversampling clock, `hans_status_out`, the head's
    /// STATUS level input and `bridge_wave_out` with the XY2-100 encoder, as
    /// `app::spawn_bridge` does for this pairing. SAI1 (the HANS-100 head output,
    /// which this pairing leaves free) plays the controller into all five channels:
    /// its ring idles at zeros (no frame on the line), then carries eight frames
    /// for 300 ms, then zeros again; 100 ms into the run slot 5 carries another
    /// frame with one bit flipped for 10 ms (~125 times). The head's XY2-100 output
    /// is sampled on the controller-side XY2 input (TIM1 ETR on CLK, port G, also
    /// free here) and decoded by `shared::xy2::rx::Receiver`. A test GPIO holds the
    /// head's STATUS level at OK (the gate waits for the head's first status,
    /// `failsafe.status_timeout_us`). SPI6 on TIM3 CH2 reads the HANS STATUS
    /// towards the controller three times (before, 50 ms into, and 100 ms after the
    /// input).
    ///
    /// Checks: no head period before the input; then every one decodes (no failed
    /// line; no framing fault once the first period is in) and is a ring frame,
    /// translated (X, Y, Z each `>> 4`: 20 -> 16 bits), or the park position; the
    /// ring's order is kept (from one frame to the next the slot steps by 0..=4,
    /// never back), at least 60 % of the input's frame periods reach the head as a
    /// new frame; the flipped frame never; no park before the first frame, then
    /// park and nothing else after the input stops (at least 1000 periods). The
    /// laser gate (PF13 pad): off before the input, on within 10 ms of it and on
    /// until it stops, off within 6 ms after and for good. The STATUS towards the
    /// controller: each look decodes >= 28 frames, none failing its check, with the
    /// lost input reported (communication alarm) before and after the input and
    /// not 50 ms into it.
    ///
    /// Jumpers: PE6 (SAI1_SD_A) -> PD7, PC1, PC12, PE14, PF9; PC6 (TIM3 CH1, fs)
    /// -> PA5, PB10, PC10, PE12, PF7 (as `hans_controller_loopback`; normal mode on
    /// channel 1 needs PE6 -> PD7 and PC6 -> PA5 only); head PD0 (CLK) -> PE7, PD1
    /// (SYNC) -> PG0, PD2 (X) -> PG1, PD3 (Y) -> PG2, PD10 (Z) -> PG3; PE2 (test
    /// GPIO, head STATUS level) -> PG9; STATUS PA0 (SAI2_SD_B) -> PG14, PC7 (TIM3
    /// CH2) -> PB3.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_hans_to_xy2_end_to_end(board: Board) {
        // The baked configuration this test is written for: its roles are the
        // image's (`bridge_pairing`), the settings its expectations rest on are
        // checked here.
        let config = config::load().unwrap();
        let roles = Roles::of(&config);
        assert_identity_axes(&config);
        assert_eq!(config.head.xy2.mode, Mode::Standard16);
        assert_eq!(config.output.timing, Timing::FreeRunning);
        assert_eq!(config.output.frame_rate_hz, 100_000);
        assert_eq!(config.failsafe.after_hold, AfterHold::Park);
        assert_eq!(config.laser.gate, shared::bridge::GateSource::LinkOk);
        let f = config.failsafe;
        let park = [f.park_x, f.park_y, f.park_z].map(|v| (v >> 4) as u16);
        assert!(
            (0..RING_SLOTS as u32).all(|s| positions(s) != park),
            "a frame looks parked"
        );
        let recovery = f.recovery_frames;
        // The head's STATUS level: OK in the configured polarity.
        let status_ok_high = shared::xy2::StatusLevel {
            polarity: config.head.xy2.polarity,
        }
        .health(true)
            == shared::xy2::Health::Ok;

        // The controller's ring, and the same ring with `BAD_FRAME`'s pattern in
        // `BAD_SLOT`, one bit flipped in the middle (inside a complement pair), as
        // `hans_controller_loopback` flips it.
        let mut ring_bytes = [0u8; RING_BYTES];
        for slot in 0..RING_SLOTS {
            write_slot(&mut ring_bytes, slot, &frame_of(slot as u32)).unwrap();
        }
        let mut ring_bad = ring_bytes;
        write_slot(&mut ring_bad, BAD_SLOT, &frame_of(BAD_FRAME)).unwrap();
        let flip = BAD_SLOT * FRAME_BITS + 60;
        ring_bad[flip / 8] ^= 0x80 >> (flip % 8);
        assert!(
            read_slot(&ring_bad, BAD_SLOT).is_err(),
            "the flipped frame passes"
        );
        assert!(
            (0..RING_SLOTS as u32).all(|s| positions(s) != positions(BAD_FRAME)),
            "BAD_FRAME"
        );
        let slot_of = |p: [u16; 3]| (0..RING_SLOTS as u32).find(|&s| positions(s) == p);

        let spawner = unsafe {
            // SAFETY: `embedded-test` (feature `embassy-010`) runs async tests as
            // tasks of embassy's thread-mode executor, so the context is embassy's.
            embassy_executor::Spawner::for_current_executor()
        }
        .await;
        let r = board.res;

        // The head's STATUS level, held at OK.
        // SAFETY: PE2 is in no `board::Resources` group and no firmware task uses
        // it; this test is its only user.
        let status_pin: Peri<'static, AnyPin> = unsafe { peripherals::PE2::steal() }.into();
        let _head_status = Output::new(status_pin, Level::from(status_ok_high), Speed::Low);
        // The controller, idle: zeros on the line.
        let ring = dma_ring!(".sram2", u8, RING_BYTES);
        let o = r.hans_out;
        let mut channel = None;
        let mut controller = SerialTx::new(o.sai, o.sd, o.dma, Irqs, &mut channel, ring);

        // The firmware's tasks for this pairing, spawned as `app::spawn_bridge` does.
        let leds = [board.led_green, board.led_yellow, board.led_red];
        app::spawn_supervision(spawner, board.iwdg, board.laser_gate, leds, false);
        let ex = Executors::start();
        let head_enable = app::head_drivers(r.head_enable, r.head_mux, roles.head);
        // fs on CH1 for the controller input, as `spawn_bridge` starts it, and on
        // CH2 (PC7, unused by this pairing) for the test's STATUS read-back.
        let fs = oversample_clock::start(r.fs.tim, Some(r.fs.ctrl), Some(r.fs.status));
        let mut fs_status = fs.status;
        fs_status.run();
        app::controller_hans(ex, &config, r.xy3_in, r.hans_in, fs.ctrl);
        app::controller_hans_status(ex, r.hans_status_out, r.ctrl_status, r.back.de);
        app::head_wave(
            spawner,
            ex,
            &config,
            roles,
            r.wave,
            head_enable,
            r.head_status,
        );

        // The bridge switches the head drivers on once its idle pattern plays; the
        // mux select stays driven low (waveform).
        head_drivers_on().await;
        assert_mux_on_waveform();
        // Head side read back on the controller-side XY2 input: TIM1 samples port G
        // on every falling edge of the head's CLK (PE7).
        let x = r.xy2_in;
        // SYNC, X, Y, Z out of their analog reset state (as `line::xy2_in`).
        let _data = x.data.inputs();
        let in_ring = dma_ring!(".sram2", u16, 8 * CHUNK);
        let mut sampler = Xy2Sampler::new(x.tim, x.clk, x.dma, Irqs, pac::GPIOG, in_ring);
        let link = LinkConfig {
            mode: config.head.xy2.mode,
            parity: config.head.xy2.parity,
        };
        let mut rx = Xy2Receiver::new(HEAD_XY2_PINS, link).unwrap();

        // Phases, set by the controller: 0 before the input, 1 while it sends, 2
        // once the ring is back at zeros (`stop_at`), 3 done.
        let phase = core::cell::Cell::new(0u8);
        let input_at = core::cell::Cell::new(Instant::now());
        let stop_at = core::cell::Cell::new(None);

        let controller_run = async {
            embassy_time::Timer::after_millis(30).await;
            // The slot being sent may mix zeros and its frame: it fails its check.
            controller.update(|buf| buf.copy_from_slice(&ring_bytes));
            input_at.set(Instant::now());
            phase.set(1);
            embassy_time::Timer::after(BAD_AT).await;
            // The bad frame into its slot, and the good one back after BAD_FOR.
            for image in [&ring_bad, &ring_bytes] {
                while !update_ahead(&mut controller, BAD_SLOT, |ring| {
                    copy_slot(ring, image, BAD_SLOT)
                }) {
                    embassy_time::Timer::after_micros(10).await;
                }
                embassy_time::Timer::after(BAD_FOR).await;
            }
            embassy_time::Timer::after(RUN - BAD_AT - BAD_FOR * 2).await;
            phase.set(2);
            controller.update(|buf| buf.fill(0));
            stop_at.set(Some(Instant::now()));
            embassy_time::Timer::after_millis(300).await;
            phase.set(3);
        };

        // The gate every 100 us: violations counted per phase.
        let mut gate = GateWatch::default();
        let gate_sampler = async {
            loop {
                let g = laser_gate_high();
                let p = phase.get();
                if p > 2 {
                    break;
                }
                let since_stop = stop_at.get().map(|t: Instant| t.elapsed());
                gate.sample(p, g, input_at.get().elapsed(), since_stop);
                embassy_time::Timer::after_micros(100).await;
            }
        };

        // The STATUS towards the controller, looked at before the input, 50 ms into
        // it (before the bad frame) and 100 ms after it stopped.
        let mut s = r.hans_status_in;
        let status_ring = dma_ring!(".sram4", u16, 4096);
        let mut looks: [StatusLook; 3] = Default::default();
        let status_run = async {
            embassy_time::Timer::after_millis(15).await;
            looks[0] = status_look(&mut s, status_ring).await;
            while phase.get() < 1 || input_at.get().elapsed() < Duration::from_millis(50) {
                embassy_time::Timer::after_millis(1).await;
            }
            looks[1] = status_look(&mut s, status_ring).await;
            while stop_at
                .get()
                .is_none_or(|t: Instant| t.elapsed() < Duration::from_millis(100))
            {
                embassy_time::Timer::after_millis(1).await;
            }
            looks[2] = status_look(&mut s, status_ring).await;
        };

        let mut log = HeadLog::default();
        let mut overrun = false;
        // Reads the samples a chunk at a time and checks each period decoded. The
        // head never stops once it started (hold, then park), so the loop sees the
        // end of the run within a chunk; if it never starts, the deadline ends it.
        let reader = async {
            let mut samples = [0u16; CHUNK];
            let mut last: Option<u32> = None;
            while phase.get() < 3 {
                if sampler.read_exact(&mut samples).await.is_err() {
                    overrun = true;
                    return;
                }
                let before = phase.get() == 0;
                rx.feed(&samples, &mut |e| {
                    let Some(v) = log.head.record(e, before) else {
                        return;
                    };
                    if v == park {
                        log.park += 1;
                        log.park_before_first += u32::from(last.is_none());
                        return;
                    }
                    if v == positions(BAD_FRAME) {
                        log.bad_seen = true;
                        return;
                    }
                    let Some(slot) = slot_of(v) else {
                        log.unknown += 1;
                        return;
                    };
                    log.frames += 1;
                    log.frames_after_park += u32::from(log.park > 0);

                    match last.map(|l| (slot + RING_SLOTS as u32 - l) % RING_SLOTS as u32) {
                        Some(0) => log.repeats += 1,
                        Some(1..=4) | None => log.distinct += 1,
                        Some(_) => log.backwards += 1,
                    }
                    last = Some(slot);
                });
            }
        };
        let deadline = phase_end(&phase, 3, Duration::from_millis(50));
        let reader = async { matches!(select(reader, deadline).await, Either::First(())) };
        let (_, _, _, read_to_the_end) =
            embassy_futures::join::join4(controller_run, gate_sampler, status_run, reader).await;
        drop(controller);
        defmt::info!("head: {}", log);
        defmt::info!("gate: {}", gate);
        defmt::info!("STATUS: {}", looks);

        assert!(
            !overrun,
            "the sampler's ring ran over (test bench too slow)"
        );
        assert!(
            read_to_the_end,
            "the head's output stopped (or never started)"
        );
        // The head: what it got, in order, translated, never the flipped frame.
        log.head.check();
        assert_eq!(log.unknown, 0, "head periods that are no frame sent");
        assert!(
            !log.bad_seen,
            "the frame with a flipped bit reached the head"
        );
        assert_eq!(log.backwards, 0, "frames out of order");
        assert_eq!(log.park_before_first, 0, "park before the first frame");
        assert_eq!(log.frames_after_park, 0, "frames after the park");
        // 100 kHz input for RUN, less the recovery run (`failsafe.recovery_frames`).
        let input_frames = (RUN.as_micros() / 10) as u32;
        assert!(
            log.distinct >= input_frames.saturating_sub(recovery) * 6 / 10,
            "{} distinct frames",
            log.distinct
        );
        assert!(log.park >= 1000, "{} park periods", log.park);
        // The laser gate.
        gate.check();
        assert!(!laser_gate_high(), "gate on at the end");
        // The STATUS towards the controller: frames of the bridge's, none cut, the
        // lost input reported (as a communication alarm: `hans::neutral`) before
        // and after the input, not while it runs.
        for (look, lost) in looks.iter().zip([true, false, true]) {
            assert!(look.frames >= 28, "STATUS: {} frames", look.frames);
            assert_eq!(look.failed, 0, "STATUS frames failing their check");
            assert_eq!(
                Alarms(look.alarms).contains(Alarms::COMMUNICATION),
                lost,
                "STATUS alarms {:#x}",
                look.alarms
            );
        }
    }
}
