//! A HANS-100 controller -> XY2-100 head (`configs/hans-normal-to-xy2.toml`,
//! `configs/hans-super-to-xy2.toml`): the HANS-100 input tasks and the waveform
//! bridge loop with an XY2-100 encoder.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::e2e::checks::{
        assert_identity_axes, assert_mux_on_waveform, capture, head_drivers_on, laser_gate_high,
        phase_end, GateWatch, RingSteps, StatusLook, Xy2Periods, HEAD_XY2_PINS,
    };
    use crate::e2e::hans_source::{
        bad_burst, controller_rings, positions, BAD_AT, BAD_FOR, BAD_FRAME,
    };
    use embassy_futures::select::{select, Either};
    use embassy_stm32::gpio::{AnyPin, Level, Output, Speed};
    use embassy_stm32::peripherals::PG8;
    use embassy_stm32::{pac, peripherals, Peri};
    use embassy_time::{Duration, Instant};
    use shared::bridge::{AfterHold, Timing};
    use shared::hans::frame::{RING_BYTES, RING_SLOTS};
    use shared::model::Alarms;
    use shared::xy2::rx::Receiver as Xy2Receiver;
    use shared::xy2::{LinkConfig, Mode};
    use xy_bridge::app::{self, Executors};
    use xy_bridge::board::{self, Board, HansStatusInRes};
    use xy_bridge::config::{self, Roles};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::oversample_clock;
    use xy_bridge::drivers::serial_tx::SerialTx;
    use xy_bridge::drivers::xy2_sampler::Xy2Sampler;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// Samples per read of the head's XY2 output (25 frames of 20 bits).
    const CHUNK: usize = 500;
    /// How long the controller sends.
    const RUN: Duration = Duration::from_millis(300);

    /// What the head received, checked period by period against the ring's frames.
    #[derive(Default, Debug, defmt::Format)]
    struct HeadLog {
        /// The periods decoded, and of them the ones before the input, with a
        /// line failing its check or missing, with a framing fault.
        head: Xy2Periods,
        /// Periods that are neither a ring frame (translated) nor the park position.
        unknown: u32,
        /// The ring slots of the frames, in order, and the park periods (one look:
        /// the read-back is continuous).
        steps: RingSteps,
    }

    /// One look at the HANS STATUS stream towards the controller (PA0): SPI6,
    /// clocked by fs on TIM3 CH2 (PC7, which this pairing leaves free), captures
    /// 1024 words (41 frame periods) from a fresh start, decoded as the controller
    /// would ([`StatusLook::of`]).
    async fn status_look(s: &mut HansStatusInRes, ring: &mut [u16]) -> StatusLook {
        let no_nss: Option<Peri<'_, PG8>> = None;
        let mut words = [0u16; 1024];
        let captured = capture(
            s.spi.reborrow(),
            s.sck.reborrow(),
            s.mosi.reborrow(),
            no_nss,
            s.dma.reborrow(),
            ring,
            &mut words,
            Duration::from_millis(200),
        )
        .await;
        assert!(captured, "STATUS capture failed");
        StatusLook::of(&words)
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

        // The controller's ring, and the same ring with the flipped frame.
        let (ring_bytes, ring_bad) = controller_rings();
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
            bad_burst(&mut controller, &ring_bytes, &ring_bad).await;
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
                        log.steps.park();
                    } else if v == positions(BAD_FRAME) {
                        log.steps.bad();
                    } else if let Some(slot) = slot_of(v) {
                        log.steps.frame(slot);
                    } else {
                        log.unknown += 1;
                    }
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
        // 100 kHz input for RUN, less the recovery run (`failsafe.recovery_frames`).
        let input_frames = (RUN.as_micros() / 10) as u32;
        log.steps
            .check(input_frames.saturating_sub(recovery) * 6 / 10, 1000);
        // The laser gate.
        gate.check();
        assert!(!laser_gate_high(), "gate on at the end");
        // The STATUS towards the controller: frames of the bridge's, none cut, the
        // lost input reported (as a communication alarm: `hans::neutral`) before
        // and after the input, not while it runs.
        for (look, lost) in looks.iter().zip([true, false, true]) {
            look.check(Alarms::COMMUNICATION, lost);
        }
    }
}
