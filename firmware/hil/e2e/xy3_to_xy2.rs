//! An XY3-100 controller -> XY2-100 head (`configs/xy3-to-xy2.toml`): the XY3-100
//! input sessions, the waveform bridge loop with an XY2-100 encoder and the
//! backchannel towards the controller.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::e2e::checks::{
        assert_identity_axes, head_drivers_on, laser_gate_high, phase_end, FrameSeq, GateWatch,
        Xy2Periods, HEAD_XY2_PINS,
    };
    use crate::e2e::source::{e2e_positions, frame_of_x, BsrrSource};
    use embassy_futures::select::{select, Either};
    use embassy_stm32::gpio::{AnyPin, Level, Output, Speed};
    use embassy_stm32::{pac, peripherals, Peri};
    use embassy_time::{Duration, Instant};
    use shared::bridge::{AfterHold, Timing};
    use shared::xy2::rx::Receiver as Xy2Receiver;
    use shared::xy2::{LinkConfig, Mode};
    use shared::xy3;
    use shared::xy3::back::{Event, Packet, Parser};
    use shared::xy3::{Frame as Frame3, FrameSize};
    use xy_bridge::app::{self, Executors};
    use xy_bridge::board::{self, Board};
    use xy_bridge::config::{self, Roles};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::backchannel;
    use xy_bridge::drivers::xy2_sampler::Xy2Sampler;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// Frames the source sends, and the one sent with its X parity bit flipped.
    const N: u32 = 30_000;
    const BAD: u32 = 12_345;
    /// Frames per half of the source's ring (0.5 ms), and ticks per frame: 48 for
    /// the 24 bits and `xy3::tx::MIN_IDLE_TICKS`, 5 MHz at 100 kHz.
    const SRC_FRAMES: usize = 50;
    const SRC_TPF: usize = 50;
    /// Samples per read of the head's XY2 output (25 frames of 20 bits).
    const CHUNK: usize = 500;
    /// The source's port-E pins: SYNC PE2, CLK PE3, X PE4, Y PE9, Z PE10.
    const SRC_PINS: xy3::tx::OutPinMap = xy3::tx::OutPinMap {
        clk: 3,
        sync: 2,
        data: [Some(4), Some(9), Some(10), None, None],
    };

    /// What the head received, checked period by period against the frames sent.
    #[derive(Default, Debug, defmt::Format)]
    struct HeadLog {
        /// The periods decoded, and of them the ones before the input, with a
        /// line failing its check or missing, with a framing fault.
        head: Xy2Periods,
        /// Periods that are neither a frame sent (translated) nor the park position.
        unknown: u32,
        /// The frame numbers received, in order, and the park periods.
        seq: FrameSeq,
    }

    /// ERROR_STATE packets on the backchannel towards the controller, by phase:
    /// reporting an error (any component code not 0) or none.
    #[derive(Default, Debug, defmt::Format)]
    struct BackLog {
        packets: u32,
        errors_before: u32,
        clean_before: u32,
        errors_during: u32,
        clean_during: u32,
        errors_after: u32,
        clean_after: u32,
    }

    /// The whole bridge through its own tasks for an XY3-100 controller (lines X,
    /// Y, Z) and an XY2-100 head (axis map identity, Z from the input,
    /// free-running at 100 kHz): `app`'s per-side functions spawn the supervisor
    /// (watchdog, laser gate), LEDs and statistics, `line::xy3_in` (its sessions)
    /// and `status::back_to_controller` (UART7 with DE), the head's STATUS level
    /// input and `bridge_wave_out` with the XY2-100 encoder, as `app::spawn_bridge`
    /// does for this pairing. [`BsrrSource`] plays a test-only XY3-100 controller:
    /// 30 000 periods of 24-bit X, Y, Z frames from `shared::xy3::tx` at 100 kHz
    /// (50 ticks at 5 MHz) on port E, frame 12 345 with its X parity bit flipped.
    /// The NUCLEO has no SCK-bus buffer: the source's clock is still while
    /// `xy3_in` starts its first session (the ring idles: SYNC high, CLK low), as
    /// the buffer would hold it. The head's XY2-100 output is sampled on the
    /// controller-side XY2 input (TIM1 ETR on CLK, port G, free here) and decoded
    /// by `shared::xy2::rx::Receiver`; USART2 RX (the head backchannel's, free
    /// here) reads the backchannel towards the controller, parsed by
    /// `shared::xy3::back::Parser`. A test GPIO holds the head's STATUS level at
    /// OK (the gate waits for the head's first status).
    ///
    /// Checks: no head period before the input; then every one decodes (no failed
    /// line; no framing fault once the first period is in) and is a frame sent,
    /// translated (20 -> 16 bits: X, Y, Z each `>> 4`), or the park position;
    /// frames never go back, step by at most 4, at least 60 % of them distinct,
    /// the first one at the end of the recovery run, the last ones reaching the
    /// head, then the park position and nothing else; the flipped frame never.
    /// The laser gate (PF13 pad): off before the input, on within 10 ms of it and
    /// on until it stops, off within 6 ms after and for good. The backchannel:
    /// ERROR_STATE packets report an error (the lost input) before the input and
    /// from 100 ms after it stopped, none from 100 ms into it until it stops.
    ///
    /// Jumpers: source PE2 (SYNC) -> PA15, PE11, PF6 and PA4, PE3 (CLK) -> PC10,
    /// PE12 and PF7, PE4 (X) -> PC12, PE9 (Y) -> PE14, PE10 (Z) -> PF9; head PD0
    /// (CLK) -> PE7, PD1 (SYNC) -> PG0, PD2 (X) -> PG1, PD3 (Y) -> PG2, PD10 (Z)
    /// -> PG3; PE5 (test GPIO, head STATUS level) -> PG9; backchannel PE8 -> PD6.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy3_to_xy2_end_to_end(board: Board) {
        // The baked configuration this test is written for: its roles are the
        // image's (`bridge_pairing`), the settings its expectations rest on are
        // checked here.
        let config = config::load().unwrap();
        let roles = Roles::of(&config);
        assert_identity_axes(&config);
        assert_eq!(
            config.xy3_input_lines(),
            xy3::rx::Lines::XYZ,
            "controller.xy3.lines"
        );
        assert_eq!(config.head.xy2.mode, Mode::Standard16);
        assert_eq!(config.output.timing, Timing::FreeRunning);
        assert_eq!(config.output.frame_rate_hz, 100_000);
        assert_eq!(config.failsafe.after_hold, AfterHold::Park);
        assert_ne!(config.failsafe.status_timeout_us, 0);
        let f = config.failsafe;
        let park = [f.park_x, f.park_y, f.park_z].map(|v| (v >> 4) as u16);
        assert!(
            (0..N).all(|k| e2e_positions(k) != park),
            "a frame looks parked"
        );
        assert!(
            (0..N).all(|k| frame_of_x(e2e_positions(k)[0]) == k),
            "frame_of_x"
        );
        let recovery = f.recovery_frames;
        // Frame k's wire words (X, Y, Z): its positions MSB-aligned in 20 bits.
        let words = |k: u32| {
            e2e_positions(k).map(|v| {
                // Every position fits 20 bits: the encoder accepts it.
                let (w, _) = xy3::encode(&Frame3::Position24(u32::from(v) << 4)).unwrap();
                w
            })
        };
        // The flipped bit is X's last, a parity bit: the word still carries frame
        // BAD's X (which would show at the head if it got through).
        let bad_x = words(BAD)[0] ^ 1;
        assert!(
            xy3::decode(bad_x, FrameSize::Bits24).is_err(),
            "flipped word passes"
        );
        let head_ok_high = shared::xy2::StatusLevel {
            polarity: config.head.xy2.polarity,
        }
        .health(true)
            == shared::xy2::Health::Ok;

        let spawner = unsafe {
            // SAFETY: `embedded-test` (feature `embassy-010`) runs async tests as
            // tasks of embassy's thread-mode executor, so the context is embassy's.
            embassy_executor::Spawner::for_current_executor()
        }
        .await;
        let r = board.res;

        // The head's STATUS level, held at OK.
        // SAFETY: PE5 is in no `board::Resources` group and no firmware task uses
        // it; this test is its only user.
        let status_pin: Peri<'static, AnyPin> = unsafe { peripherals::PE5::steal() }.into();
        let _head_status = Output::new(status_pin, Level::from(head_ok_high), Speed::Low);
        // The controller side's source, idle (SYNC high, CLK and data low), on the
        // head backchannel's TX stream (DMA1 S6; that UART only receives here).
        let tx = xy3::tx::Transmitter::new(&xy3::tx::TxConfig {
            pins: SRC_PINS,
            size: FrameSize::Bits24,
            idle_ticks: xy3::tx::MIN_IDLE_TICKS,
        })
        .unwrap();
        assert_eq!(tx.ticks_per_frame(), SRC_TPF, "ticks per frame");
        let tick_hz = tx.tick_hz(config.output.frame_rate_hz) as u32;
        let mut idle = [0u32; SRC_TPF];
        tx.idle(&mut idle).unwrap();
        let hb = r.head_back;
        let mut source = BsrrSource::start(
            hb.tx_dma,
            dma_ring!(".sram1", u32, 2 * SRC_FRAMES * SRC_TPF),
            idle[0],
            tick_hz,
        );
        // The backchannel towards the controller, read on USART2 RX.
        let back_rx = embassy_stm32::usart::UartRx::new(
            hb.uart,
            hb.rx,
            hb.rx_dma,
            Irqs,
            backchannel::config(config.controller.xy3.back_rate.baud()),
        )
        .unwrap();
        let mut back_rx = backchannel::head_rx(back_rx, dma_ring!(".sram3", u8, 256));

        // The firmware's tasks for this pairing, spawned as `app::spawn_bridge` does.
        let leds = [board.led_green, board.led_yellow, board.led_red];
        app::spawn_supervision(spawner, board.iwdg, board.laser_gate, leds, false);
        let ex = Executors::start();
        let head_enable = app::head_drivers(r.head_enable, r.head_mux, roles.head);
        app::controller_xy3(spawner, ex, &config, r.xy3_in, r.back);
        app::head_wave(
            spawner,
            ex,
            &config,
            roles,
            r.wave,
            head_enable,
            r.head_status,
        );

        // The bridge switches the head drivers on once its idle pattern plays.
        let pf = pac::GPIOF;
        head_drivers_on().await;
        // `xy3_in`'s first session has started: the SCK-bus buffer is on.
        assert_eq!(
            pf.odr().read().odr(14),
            pac::gpio::vals::Odr::LOW,
            "SCK-bus buffer (PF14) still off"
        );
        // Head side read back on the controller-side XY2 input.
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
                    let [x, y, z] = words(k);
                    let x = if k == BAD { x ^ 1 } else { x };
                    tx.encode_words([x, y, z, 0, 0], slot).unwrap();
                }
                if !source.write(&half).await {
                    underrun.set(true);
                }
                if h == 0 {
                    input_at.set(Instant::now());
                    phase.set(1);
                }
            }
            // Two idle halves: once both are queued the last frame has played.
            phase.set(2);
            half.fill(idle[0]);
            for _ in 0..2 {
                if !source.write(&half).await {
                    underrun.set(true);
                }
            }
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

        // The backchannel towards the controller: every ERROR_STATE packet, by
        // phase (clear of the transitions by 100 ms).
        let mut back = BackLog::default();
        let back_reader = async {
            let mut parser = Parser::default();
            let mut buf = [0u8; 64];
            while phase.get() < 3 {
                let Ok(Ok(n)) =
                    embassy_time::with_timeout(Duration::from_millis(5), back_rx.read(&mut buf))
                        .await
                else {
                    continue;
                };
                for &byte in &buf[..n] {
                    let Some(Event::Packet(raw)) = parser.push(byte) else {
                        continue;
                    };
                    back.packets += 1;
                    let Ok(Packet::ErrorState(codes)) = Packet::decode(raw.ty, raw.payload) else {
                        continue;
                    };
                    let error = codes.iter().any(|&c| c != 0);
                    let settled = |t: Option<Instant>| {
                        t.is_some_and(|t| t.elapsed() >= Duration::from_millis(100))
                    };
                    let (errors, clean) = match phase.get() {
                        0 => (&mut back.errors_before, &mut back.clean_before),
                        1 if settled(Some(input_at.get())) => {
                            (&mut back.errors_during, &mut back.clean_during)
                        }
                        2 if settled(stop_at.get()) => {
                            (&mut back.errors_after, &mut back.clean_after)
                        }
                        _ => continue,
                    };
                    *if error { errors } else { clean } += 1;
                }
            }
        };

        let mut log = HeadLog::default();
        let mut overrun = false;
        // Reads the samples a chunk at a time and checks each period decoded.
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
                        log.seq.park();
                        return;
                    }
                    let k = frame_of_x(v[0]);
                    if k >= N || e2e_positions(k) != v {
                        log.unknown += 1;
                        return;
                    }
                    log.seq.frame(k, k == BAD);
                });
            }
        };
        let deadline = phase_end(&phase, 3, Duration::from_millis(50));
        let reader = async { matches!(select(reader, deadline).await, Either::First(())) };
        let (_, _, _, read_to_the_end) =
            embassy_futures::join::join4(source_run, gate_sampler, back_reader, reader).await;
        drop(source);
        defmt::info!("head: {}", log);
        defmt::info!("gate: {}", gate);
        defmt::info!("backchannel: {}", back);

        assert!(
            !underrun.get(),
            "the source's DMA ran out of words (test bench too slow)"
        );
        assert!(
            !overrun,
            "the sampler's ring ran over (test bench too slow)"
        );
        assert!(
            read_to_the_end,
            "the head's output stopped (or never started)"
        );
        // The head: nothing before the input, then what it got, in order,
        // translated, never the flipped frame.
        log.head.check();
        assert_eq!(log.unknown, 0, "head periods that are no frame sent");
        log.seq.check(N, recovery);
        // The laser gate.
        gate.check();
        assert!(!laser_gate_high(), "gate on at the end");
        // The backchannel towards the controller: the lost input reported before
        // and after, not while the input runs.
        assert!(
            back.errors_before >= 1,
            "no error reported before the input"
        );
        assert_eq!(back.clean_before, 0, "no error reported before the input");
        assert!(back.clean_during >= 1, "no ERROR_STATE while the input ran");
        assert_eq!(back.errors_during, 0, "errors reported while the input ran");
        assert!(back.errors_after >= 1, "no error reported after the input");
        assert_eq!(back.clean_after, 0, "no error reported after the input");
    }
}
