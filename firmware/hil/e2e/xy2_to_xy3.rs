//! The default pairing (`bridge.toml`): XY2-100 controller -> XY3-100 head.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::e2e::checks::{
        assert_identity_axes, assert_mux_on_waveform, head_drivers_on, laser_gate_high, phase_end,
        FrameSeq,
    };
    use crate::e2e::source::{e2e_positions, frame_of_x, BsrrSource};
    use crate::e2e::xy2_source::{Levels, SRC_FRAMES, SRC_PINS, SRC_TICK_HZ, SRC_TPF};
    use embassy_stm32::usart::UartTx;
    use embassy_time::Duration;
    use shared::xy2::tx::Transmitter as Xy2Tx;
    use shared::xy2::{
        decode as xy2_decode, encode as xy2_encode, Frame as Frame2, LinkConfig, StatusLevel,
    };
    use shared::xy3;
    use shared::xy3::back::{Packet, Sender, SEND_BUF_LEN};
    use shared::xy3::{Frame as Frame3, FrameSize};
    use xy_bridge::board::{self, Board};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::backchannel;
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    use xy_bridge::drivers::sync_marks::SyncMarks;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// What the head received, checked period by period against the frames sent.
    #[derive(Default, Debug, defmt::Format)]
    struct HeadLog {
        /// Periods decoded.
        periods: u32,
        /// Periods where a line failed its check or was missing.
        failed: u32,
        /// Periods that are neither a frame sent (translated) nor the park position.
        unknown: u32,
        /// The frame numbers received, in order, and the park periods.
        seq: FrameSeq,
    }

    /// The whole bridge through its own tasks, for the baked default pairing
    /// (`bridge.toml`: XY2-100 controller -> XY3-100 head, 16 -> 20 bits, axis map
    /// identity, Z from the input, free-running at 100 kHz): the firmware's `app`
    /// functions spawn the supervisor (watchdog, laser gate), LEDs and statistics,
    /// `line::xy2_in` and `bridge_wave_out` in the line executor, the STATUS level
    /// and head backchannel tasks, as `app::spawn_bridge` does for this pairing.
    /// [`BsrrSource`] plays 30 000 frames from `shared::xy2::tx` into the
    /// controller-side XY2 input (frame 12 345 with its X parity bit flipped); the
    /// head's XY3-100 output is received by the controller-side XY3 SPI slaves (X, Y,
    /// Z) and SYNC marks, which this pairing leaves free, and decoded by
    /// `shared::xy3::rx::Receiver`; UART7 plays the head's backchannel (a status
    /// packet every 20 ms), which the gate waits for (`failsafe.status_timeout_us`).
    ///
    /// Checks: no head frame before the input's; then every head period decodes and
    /// is a frame sent, translated (X, Y, Z each `v << 4`: positions are MSB-aligned,
    /// `xy3-100-notes.md` "Summary"), never going back, in steps of at most 4
    /// frames, at least 60 % of the frames distinct (free-running at the input's
    /// rate, a batch of 20 slots that drains a half of 25 frames skips 5: ~80 %
    /// expected, README "Added latency"), the first one at the end of the recovery
    /// run (`failsafe.recovery_frames`), the last ones reaching the head, then the
    /// park position and nothing else; the flipped frame never; the laser gate (PF13
    /// pad) off before the input, on within 10 ms of it and on until it stops, off
    /// within 6 ms after and for good; the STATUS towards the controller (PA0)
    /// "fault" before, "OK" within 200 ms of the input and until it stops, "fault"
    /// again within 250 ms after.
    ///
    /// Jumpers: source PE2 -> PE7, PE3 -> PG0, PE4 -> PG1, PE9 -> PG2, PE10 -> PG3;
    /// head PD0 (SYNC) -> PA15, PE11, PF6 and PA4, PD1 (CLK) -> PC10, PE12 and PF7,
    /// PD2 (X) -> PC12, PD3 (Y) -> PE14, PD10 (Z) -> PF9; head backchannel PE8 ->
    /// PD6.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy2_to_xy3_end_to_end(board: Board) {
        use embassy_futures::select::{select, Either};
        use embassy_time::Instant;
        use shared::bridge::{AfterHold, Timing};
        use shared::model::Axis;
        use xy_bridge::app::{self, Executors};
        use xy_bridge::config::{self, Roles};
        const N: u32 = 30_000;
        const BAD: u32 = 12_345;
        const CHUNK: usize = xy3::rx::WINDOW / 2;

        // The baked configuration this test is written for: its roles are the
        // image's (`bridge_pairing`), the settings its expectations rest on are
        // checked here (`bridge.toml`).
        let config = config::load().unwrap();
        let roles = Roles::of(&config);
        assert_identity_axes(&config);
        assert_eq!(config.head.xy3.frame_size, FrameSize::Bits24);
        assert_eq!(config.output.timing, Timing::FreeRunning);
        assert_eq!(config.output.frame_rate_hz, 100_000);
        assert_eq!(config.failsafe.after_hold, AfterHold::Park);
        assert_ne!(config.failsafe.status_timeout_us, 0);
        let f = config.failsafe;
        let park = [f.park_x, f.park_y, f.park_z];
        let recovery = f.recovery_frames;
        let head_of = |k: u32| e2e_positions(k).map(|v| u32::from(v) << 4);
        assert!((0..N).all(|k| head_of(k) != park), "a frame looks parked");
        assert!(
            (0..N).all(|k| frame_of_x(e2e_positions(k)[0]) == k),
            "frame_of_x"
        );
        let link = LinkConfig {
            mode: config.controller.xy2.mode,
            parity: config.controller.xy2.parity,
        };
        // The flipped bit is the parity bit: the word still carries frame BAD's X
        // (which would show at the head if it got through), and fails its check.
        let bad_x = Frame2::Position16(e2e_positions(BAD)[0]);
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

        // The head backchannel's USART2 goes to the firmware but its TX DMA stream
        // (DMA1 S6, the HIL's) to the source: DMA1 carries nothing else fast here.
        let hb = r.head_back;
        // The controller side's source, idle.
        let tx = Xy2Tx::new(SRC_PINS, SRC_TPF, link).unwrap();
        let mut source = BsrrSource::start(
            hb.tx_dma,
            dma_ring!(".sram1", u32, 2 * SRC_FRAMES * SRC_TPF),
            tx.idle_word(),
            SRC_TICK_HZ,
        );
        // The head's backchannel.
        let mut head_back = UartTx::new(
            r.back.uart,
            r.back.tx,
            r.back.tx_dma,
            Irqs,
            backchannel::config(config.controller.xy3.back_rate.baud()),
        )
        .unwrap();

        // The firmware's tasks for this pairing, spawned as `app::spawn_bridge` does.
        let leds = [board.led_green, board.led_yellow, board.led_red];
        app::spawn_supervision(spawner, board.iwdg, board.laser_gate, leds, false);
        let ex = Executors::start();
        let head_enable = app::head_drivers(r.head_enable, r.head_mux, roles.head);
        let i = r.xy3_in;
        app::controller_xy2(
            spawner,
            ex,
            &config,
            r.xy2_in,
            r.ctrl_status,
            r.back.de,
            i.sck_buffer_oe,
        );
        app::head_xy3_backchannel(spawner, &config, hb.uart, hb.rx, hb.rx_dma);
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
        // Head side read back, started now that the head's lines idle (SYNC high,
        // CLK low; before, the unconfigured pins floated): SPI3 (X), SPI4 (Y), SPI5
        // (Z) slaves selected by the head's SYNC, and the SYNC marks, whose every
        // rising edge from here is a frame end.
        let (lx, ly, lz) = (i.x, i.y, i.z);
        let mut rx_lines = [
            SpiSlaveRx::new(
                lx.spi,
                lx.sck,
                lx.mosi,
                Some(lx.nss),
                lx.dma,
                Irqs,
                dma_ring!(".sram1", u8, 1024),
            )
            .unwrap(),
            SpiSlaveRx::new(
                ly.spi,
                ly.sck,
                ly.mosi,
                Some(ly.nss),
                ly.dma,
                Irqs,
                dma_ring!(".sram1", u8, 1024),
            )
            .unwrap(),
            SpiSlaveRx::new(
                lz.spi,
                lz.sck,
                lz.mosi,
                Some(lz.nss),
                lz.dma,
                Irqs,
                dma_ring!(".sram1", u8, 1024),
            )
            .unwrap(),
        ];
        let mut marks = SyncMarks::new(i.sync, i.exti, Irqs, 1024);

        // Phases, set by the source: 0 before the input, 1 while frames are written,
        // 2 once the last frame is written (`stop_at`: once it played, the ring
        // holding nothing but idle), 3 done.
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
                    let x = if k == BAD { x ^ 1 } else { x };
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

        let head_sim = async {
            let mut sender = Sender::default();
            let mut out = [0u8; SEND_BUF_LEN];
            while phase.get() < 3 {
                let n = sender
                    .send(0, &Packet::FrameErrorCount([0; 5]), &mut out)
                    .unwrap();
                head_back.write(&out[..n]).await.unwrap();
                embassy_time::Timer::after_millis(20).await;
            }
        };

        // Gate and STATUS, every 100 us: violations counted per phase.
        let mut lv = Levels::default();
        let sampler = lv.watch(&phase, &input_at, &stop_at, status_level);

        let mut log = HeadLog::default();
        // Reads every line's next chunk (no timeout: a read cancelled half-way would
        // lose bytes of one line only) and checks each period decoded. The head
        // never stops once it started (hold, then park), so the loop sees the end
        // of the run within a chunk; if it never starts, the deadline below ends it.
        let reader = async {
            let mut rx = xy3::rx::Receiver::new(xy3::rx::Lines::XYZ);
            let mut bytes = [[0u8; CHUNK]; 3];
            let mut ends = [0u32; xy3::rx::MAX_PENDING_ENDS];
            while phase.get() < 3 {
                for (line, buf) in rx_lines.iter_mut().zip(bytes.iter_mut()) {
                    line.read_exact(buf).await.unwrap();
                }
                let n = marks.drain(&mut ends);
                let lines: [&[u8]; 3] = [&bytes[0], &bytes[1], &bytes[2]];
                rx.push_bytes(&lines).unwrap();
                rx.push_ends(&ends[..n]);
                while let Some(p) = rx.poll() {
                    log.periods += 1;
                    let mut v = [0u32; 3];
                    let mut ok = true;
                    for (axis, v) in [Axis::X, Axis::Y, Axis::Z].iter().zip(v.iter_mut()) {
                        match p.lines[axis.index()] {
                            Some(Ok(Frame3::Position24(pos))) => *v = pos,
                            _ => ok = false,
                        }
                    }
                    if !ok {
                        log.failed += 1;
                        continue;
                    }
                    if v == park {
                        log.seq.park();
                        continue;
                    }
                    let k = frame_of_x((v[0] >> 4) as u16);
                    if k >= N || head_of(k) != v {
                        log.unknown += 1;
                        continue;
                    }
                    log.seq.frame(k, k == BAD);
                }
            }
        };
        let deadline = phase_end(&phase, 3, Duration::from_millis(50));
        let reader = async { matches!(select(reader, deadline).await, Either::First(())) };
        let (_, _, _, read_to_the_end) =
            embassy_futures::join::join4(source_run, head_sim, sampler, reader).await;
        drop(source);
        defmt::info!("head: {}", log);

        assert!(
            !underrun.get(),
            "the source's DMA ran out of words (test bench too slow)"
        );
        assert!(
            read_to_the_end,
            "the head's output stopped (or never started)"
        );
        assert_eq!(marks.dropped(), 0, "SYNC marks dropped");
        // The head: what it got, in order, translated, never the flipped frame.
        assert_eq!(log.failed, 0, "head periods failing their check");
        assert_eq!(log.unknown, 0, "head periods that are no frame sent");
        log.seq.check(N, recovery);
        // The laser gate and the STATUS towards the controller.
        lv.check();
        assert!(!laser_gate_high(), "gate on at the end");
    }
}
