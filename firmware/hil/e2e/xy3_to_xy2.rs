//! An XY3-100 controller -> XY2-100 head (`configs/xy3-to-xy2.toml`): the XY3-100
//! input sessions, the waveform bridge loop with an XY2-100 encoder and the
//! backchannel towards the controller; and session restarts while the
//! controller's clock runs: lines out of step (`shared::xy3::step`), and a real
//! SPI DMA ring overrun.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use core::cell::Cell;
    use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

    use crate::e2e::checks::{
        assert_identity_axes, head_drivers_on, laser_gate_high, phase_end, FrameSeq, GateWatch,
        Xy2Periods, HEAD_XY2_PINS,
    };
    use crate::e2e::sck_gate::{SckGate, SckGateHandler};
    use crate::e2e::source::{e2e_positions, frame_of_x, BsrrSource};
    use embassy_futures::select::{select, Either};
    use embassy_stm32::gpio::{AnyPin, Input, Level, Output, Speed};
    use embassy_stm32::interrupt::typelevel::{Handler, Interrupt, CEC};
    use embassy_stm32::interrupt::Priority;
    use embassy_stm32::{bind_interrupts, pac, peripherals, Peri};
    use embassy_time::{Duration, Instant};
    use shared::bridge::{AfterHold, Config, Timing};
    use shared::head_port::XY2_TICK_HZ;
    use shared::xy2::rx::Receiver as Xy2Receiver;
    use shared::xy2::{LinkConfig, Mode};
    use shared::xy3;
    use shared::xy3::back::{Event, Packet, Parser};
    use shared::xy3::{Frame as Frame3, FrameSize};
    use xy_bridge::app::{self, Executors};
    use xy_bridge::board::{self, BackRes, Board, HeadBackRes, WaveRes, Xy2InRes, Xy3InRes};
    use xy_bridge::config::{self, Roles};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::backchannel;
    use xy_bridge::drivers::xy2_sampler::Xy2Sampler;
    use xy_bridge::tasks::{self, Irqs};

    bind_interrupts!(
        /// PF14's edges for the emulated SCK-bus buffer (`e2e::sck_gate`), and the
        /// overrun tests' stall (CEC: unused on this board).
        struct GateIrq {
            EXTI15_10 => SckGateHandler;
            CEC => StallHandler;
        }
    );

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

    /// The baked configuration both tests are written for (its roles are the
    /// image's, `bridge_pairing`), with the settings their expectations rest on
    /// checked, and what they take from it.
    struct Baked {
        config: Config,
        roles: Roles,
        /// The park position as the head shows it (16 bits).
        park: [u16; 3],
        /// `failsafe.recovery_frames`.
        recovery: u32,
        /// The head STATUS level that reads OK.
        head_ok_high: bool,
    }

    /// Loads and checks the baked configuration for a source of `n` frames.
    fn baked(n: u32) -> Baked {
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
            (0..n).all(|k| e2e_positions(k) != park),
            "a frame looks parked"
        );
        assert!(
            (0..n).all(|k| frame_of_x(e2e_positions(k)[0]) == k),
            "frame_of_x"
        );
        let head_ok_high = shared::xy2::StatusLevel {
            polarity: config.head.xy2.polarity,
        }
        .health(true)
            == shared::xy2::Health::Ok;
        Baked {
            config,
            roles,
            park,
            recovery: f.recovery_frames,
            head_ok_high,
        }
    }

    /// Frame k's wire words (X, Y, Z): its positions MSB-aligned in 20 bits.
    fn wire_words(k: u32) -> [u32; 3] {
        e2e_positions(k).map(|v| {
            // Every position fits 20 bits: the encoder accepts it.
            let (w, _) = xy3::encode(&Frame3::Position24(u32::from(v) << 4)).unwrap();
            w
        })
    }

    /// The board's resources the firmware's tasks for this pairing take.
    struct Firmware {
        iwdg: Peri<'static, peripherals::IWDG1>,
        laser_gate: Output<'static>,
        leds: [Output<'static>; 3],
        xy3_in: Xy3InRes,
        back: BackRes,
        wave: WaveRes,
        head_enable: Peri<'static, peripherals::PF11>,
        head_mux: Peri<'static, peripherals::PF15>,
        head_status: Peri<'static, peripherals::PG9>,
    }

    impl Firmware {
        /// Splits `board` into the firmware's resources, the head backchannel's
        /// (the source's DMA stream, USART2 RX) and the controller-side XY2-100
        /// input's (the head read-back): free here, the tests use them.
        fn take(board: Board) -> (Firmware, HeadBackRes, Xy2InRes) {
            let r = board.res;
            let fw = Firmware {
                iwdg: board.iwdg,
                laser_gate: board.laser_gate,
                leds: [board.led_green, board.led_yellow, board.led_red],
                xy3_in: r.xy3_in,
                back: r.back,
                wave: r.wave,
                head_enable: r.head_enable,
                head_mux: r.head_mux,
                head_status: r.head_status,
            };
            (fw, r.head_back, r.xy2_in)
        }

        /// Spawns the tasks as `app::spawn_bridge` does for this pairing:
        /// `app`'s per-side functions spawn the supervisor (watchdog, laser gate),
        /// LEDs and statistics, `line::xy3_in` (its sessions) and
        /// `status::back_to_controller` (UART7 with DE), the head's STATUS level
        /// input and `bridge_wave_out` with the XY2-100 encoder.
        fn spawn(self, spawner: embassy_executor::Spawner, b: &Baked) {
            app::spawn_supervision(spawner, self.iwdg, self.laser_gate, self.leds, false);
            let ex = Executors::start();
            let head_enable = app::head_drivers(self.head_enable, self.head_mux, b.roles.head);
            app::controller_xy3(spawner, ex, &b.config, self.xy3_in, self.back);
            app::head_wave(
                spawner,
                ex,
                &b.config,
                b.roles,
                self.wave,
                head_enable,
                self.head_status,
            );
        }
    }

    /// The head's STATUS level on PE5, held at OK (the gate waits for the head's
    /// first status).
    fn head_status_ok(b: &Baked) -> Output<'static> {
        // SAFETY: PE5 is in no `board::Resources` group and no firmware task uses
        // it; this test is its only user.
        let status_pin: Peri<'static, AnyPin> = unsafe { peripherals::PE5::steal() }.into();
        Output::new(status_pin, Level::from(b.head_ok_high), Speed::Low)
    }

    /// The controller side's source, idle (SYNC high, CLK and data low), on the
    /// head backchannel's TX stream (DMA1 S6; that UART only receives here): its
    /// transmitter, idle word and the running source.
    fn start_source(
        dma: Peri<'static, peripherals::DMA1_CH6>,
        b: &Baked,
    ) -> (xy3::tx::Transmitter, u32, BsrrSource) {
        let tx = xy3::tx::Transmitter::new(&xy3::tx::TxConfig {
            pins: SRC_PINS,
            size: FrameSize::Bits24,
            idle_ticks: xy3::tx::MIN_IDLE_TICKS,
        })
        .unwrap();
        assert_eq!(tx.ticks_per_frame(), SRC_TPF, "ticks per frame");
        let tick_hz = tx.tick_hz(b.config.output.frame_rate_hz) as u32;
        let mut idle = [0u32; SRC_TPF];
        tx.idle(&mut idle).unwrap();
        let source = BsrrSource::start(
            dma,
            dma_ring!(".sram1", u32, 2 * SRC_FRAMES * SRC_TPF),
            idle[0],
            tick_hz,
        );
        (tx, idle[0], source)
    }

    /// The head's XY2-100 output read back on the controller-side XY2 input
    /// (TIM1 ETR on CLK, port G, free here) and decoded.
    struct HeadReadBack {
        sampler: Xy2Sampler<'static>,
        rx: Xy2Receiver,
        /// SYNC, X, Y, Z out of their analog reset state (as `line::xy2_in`).
        _data: [Input<'static>; 4],
    }

    /// Waits until the bridge switches the head drivers on (once its idle pattern
    /// plays), checks that `xy3_in`'s first session turned the SCK-bus buffer on,
    /// and starts reading the head's output back.
    async fn head_read_back(x: Xy2InRes, b: &Baked) -> HeadReadBack {
        head_drivers_on().await;
        // `xy3_in`'s first session has started: the SCK-bus buffer is on.
        assert_eq!(
            pac::GPIOF.odr().read().odr(14),
            pac::gpio::vals::Odr::LOW,
            "SCK-bus buffer (PF14) still off"
        );
        let _data = x.data.inputs();
        let in_ring = dma_ring!(".sram2", u16, 8 * CHUNK);
        let sampler = Xy2Sampler::new(x.tim, x.clk, x.dma, Irqs, pac::GPIOG, in_ring);
        let link = LinkConfig {
            mode: b.config.head.xy2.mode,
            parity: b.config.head.xy2.parity,
        };
        let rx = Xy2Receiver::new(HEAD_XY2_PINS, link).unwrap();
        HeadReadBack { sampler, rx, _data }
    }

    /// How a read-back of the head's output ended.
    #[derive(PartialEq, Eq, Debug, defmt::Format)]
    enum Reading {
        /// To the end of the source's last phase and 50 ms beyond.
        ToTheEnd,
        /// The sampler's ring ran over (test bench too slow).
        Overrun,
        /// The head's output stopped (or never started): no chunk came in time.
        Stopped,
    }

    impl Reading {
        fn check(&self) {
            assert_ne!(
                *self,
                Reading::Overrun,
                "the sampler's ring ran over (test bench too slow)"
            );
            assert_eq!(
                *self,
                Reading::ToTheEnd,
                "the head's output stopped (or never started)"
            );
        }
    }

    /// Reads the head's output a chunk at a time until the source's `phase`
    /// reaches `last` (and 50 ms beyond) and checks each period decoded into
    /// `log`: the park position, a frame sent (of the `n` sent; `bad` the one with
    /// a flipped bit), or else `other` gets its positions and the frame number its
    /// X names, and the period counts as unknown unless `other` says it counted it.
    async fn read_head(
        rb: &mut HeadReadBack,
        phase: &Cell<u8>,
        last: u8,
        (n, park, bad): (u32, [u16; 3], Option<u32>),
        log: &mut HeadLog,
        mut other: impl FnMut([u16; 3], u32) -> bool,
    ) -> Reading {
        let reader = async {
            let mut samples = [0u16; CHUNK];
            while phase.get() < last {
                if rb.sampler.read_exact(&mut samples).await.is_err() {
                    return Reading::Overrun;
                }
                let before = phase.get() == 0;
                rb.rx.feed(&samples, &mut |e| {
                    let Some(v) = log.head.record(e, before) else {
                        return;
                    };
                    if v == park {
                        log.seq.park();
                        return;
                    }
                    let k = frame_of_x(v[0]);
                    if k < n && e2e_positions(k) == v {
                        log.seq.frame(k, Some(k) == bad);
                    } else if !other(v, k) {
                        log.unknown += 1;
                    }
                });
            }
            Reading::ToTheEnd
        };
        let deadline = phase_end(phase, last, Duration::from_millis(50));
        match select(reader, deadline).await {
            Either::First(r) => r,
            Either::Second(()) => Reading::Stopped,
        }
    }

    async fn current_spawner() -> embassy_executor::Spawner {
        // SAFETY: `embedded-test` (feature `embassy-010`) runs async tests as tasks
        // of embassy's thread-mode executor, so the context is embassy's.
        unsafe { embassy_executor::Spawner::for_current_executor() }.await
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
        let b = baked(N);
        let recovery = b.recovery;
        // The flipped bit is X's last, a parity bit: the word still carries frame
        // BAD's X (which would show at the head if it got through).
        let bad_x = wire_words(BAD)[0] ^ 1;
        assert!(
            xy3::decode(bad_x, FrameSize::Bits24).is_err(),
            "flipped word passes"
        );

        let spawner = current_spawner().await;
        let (fw, hb, x) = Firmware::take(board);
        let _head_status = head_status_ok(&b);
        let (tx, idle, mut source) = start_source(hb.tx_dma, &b);
        // The backchannel towards the controller, read on USART2 RX.
        let back_rx = embassy_stm32::usart::UartRx::new(
            hb.uart,
            hb.rx,
            hb.rx_dma,
            Irqs,
            backchannel::config(b.config.controller.xy3.back_rate.baud()),
        )
        .unwrap();
        let mut back_rx = backchannel::head_rx(back_rx, dma_ring!(".sram3", u8, 256));

        // The firmware's tasks for this pairing, spawned as `app::spawn_bridge` does.
        fw.spawn(spawner, &b);
        // Head side read back on the controller-side XY2 input.
        let mut head = head_read_back(x, &b).await;

        // Phases, set by the source: 0 before the input, 1 while frames are written,
        // 2 once the last frame is written (`stop_at`: once it played), 3 done.
        let phase = Cell::new(0u8);
        let input_at = Cell::new(Instant::now());
        let stop_at = Cell::new(None);
        let underrun = Cell::new(false);

        let source_run = async {
            embassy_time::Timer::after_millis(30).await;
            let mut half = [0u32; SRC_FRAMES * SRC_TPF];
            for h in 0..N / SRC_FRAMES as u32 {
                for (f, slot) in half.chunks_exact_mut(SRC_TPF).enumerate() {
                    let k = h * SRC_FRAMES as u32 + f as u32;
                    let [x, y, z] = wire_words(k);
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
            phase.set(2);
            if !source.finish(&mut half, idle).await {
                underrun.set(true);
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
        // Reads the samples a chunk at a time and checks each period decoded.
        let reader = read_head(
            &mut head,
            &phase,
            3,
            (N, b.park, Some(BAD)),
            &mut log,
            |_, _| false,
        );
        let (_, _, _, reading) =
            embassy_futures::join::join4(source_run, gate_sampler, back_reader, reader).await;
        drop(source);
        defmt::info!("head: {}", log);
        defmt::info!("gate: {}", gate);
        defmt::info!("backchannel: {}", back);

        assert!(
            !underrun.get(),
            "the source's DMA ran out of words (test bench too slow)"
        );
        reading.check();
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

    /// The restart test's source: frames sent, and from where it looks for the
    /// shift's first frame ([`shift_start`]).
    const RESTART_N: u32 = 20_000;
    const SHIFT_FROM: u32 = 10_000;
    /// Bits Y's line lags by while shifted: a whole byte, which is what an SPI
    /// slave that took 8 extra clock edges receives whether it keeps a partial
    /// byte across SYNC or drops it (`xy3::rx` "Partial bytes and bit slips"), so
    /// the emulated slip does not rest on that unknown.
    const SHIFT_BITS: u32 = 8;
    /// Frames the shift lasts at most if no restart heals it (30 ms).
    const SHIFT_MAX: u32 = 3_000;
    /// What the timing bounds are built from (us): a half of the source's ring
    /// (a half written plays after at most the one before it); the bridge's batch
    /// (it drains its input and sets the gate once per output batch, 200-250 us);
    /// the gate sampling period; a margin for what is not modelled (wake-ups, the
    /// writer's copy).
    const RING_HALF_US: u64 = 500;
    const BATCH_US: u64 = 250;
    const SAMPLE_US: u64 = 100;
    const MARGIN_US: u64 = 500;

    /// Y's wire word in frame `k` as the shifted line plays it: the last
    /// [`SHIFT_BITS`] bits of frame k-1's Y word, then the first 24 - SHIFT_BITS
    /// of frame k's, as an SPI slave that slipped by that many edges reads it.
    fn shifted_y(k: u32) -> u32 {
        let [_, prev, _] = wire_words(k.wrapping_sub(1));
        let [_, cur, _] = wire_words(k);
        (prev << (24 - SHIFT_BITS) | cur >> SHIFT_BITS) & 0xFF_FFFF
    }

    /// The Y the head would show for the shifted period `k` had it got through:
    /// `Some` when the shifted word passes as a position frame (X and Z are in step
    /// and pass, so the bridge's receiver would call the period good: a chance
    /// pass); a command on Y alone is refused as kinds no controller sends.
    fn shifted_head_y(k: u32) -> Option<u16> {
        match xy3::decode(shifted_y(k), FrameSize::Bits24) {
            Ok(Frame3::Position24(p)) => Some((p >> 4) as u16),
            _ => None,
        }
    }

    /// The first frame from [`SHIFT_FROM`] whose shifted period passes by chance:
    /// the shift's first period then passes its checks before the step watch has
    /// seen a bad one, the case the README's residual is about (`shared::xy3::step`:
    /// such a period is forwarded if the next one passes too). Only the watch's
    /// confirmation keeps it from the head: it holds the period until the next
    /// one, which fails here (the test checks that the data never give two
    /// chance passes in a row, so by the documented rules nothing shifted gets
    /// through, and a frame made from the shifted bits at the head is a finding).
    fn shift_start() -> u32 {
        (SHIFT_FROM..SHIFT_FROM + 100)
            .find(|&k| shifted_head_y(k).is_some())
            .expect("no chance pass to start the shift with")
    }

    /// The laser gate from the shift on until the input stops, every 100 us.
    #[derive(Default, Debug, defmt::Format)]
    struct Outage {
        /// Samples with the gate off, and runs of them.
        off: u32,
        off_runs: u32,
        /// The first off sample, after the shifted half was queued (us).
        off_after_shift_us: Option<u64>,
        /// The first on sample after it, after the healed half was queued (us),
        /// or an on sample after it before the heal was queued.
        back_on_us: Option<u64>,
        back_on_early: bool,
        /// Off samples once it was back on.
        drops_after: u32,
        was_off: bool,
    }

    impl Outage {
        /// Records one sample `on`, `since_shift` after the shifted half was queued
        /// and `since_heal` after the healed one was (`None`: not yet).
        fn sample(&mut self, on: bool, since_shift: Duration, since_heal: Option<Duration>) {
            if !on {
                self.off += 1;
                self.off_runs += u32::from(!self.was_off);
                self.off_after_shift_us
                    .get_or_insert(since_shift.as_micros());
                self.drops_after += u32::from(self.back_on_us.is_some() || self.back_on_early);
            } else if self.was_off && self.back_on_us.is_none() && !self.back_on_early {
                match since_heal {
                    Some(t) => self.back_on_us = Some(t.as_micros()),
                    None => self.back_on_early = true,
                }
            }
            self.was_off = !on;
        }

        /// The verdict: off once, within `off_us` of the shifted half being queued
        /// and for at least `min_off` samples; back on after the healed half was
        /// queued, within `back_us` of it, and on until the input stops.
        fn check(&self, off_us: u64, back_us: u64, min_off: u32) {
            assert_eq!(
                self.off_runs, 1,
                "the gate did not go off once while out of step"
            );
            let off = self.off_after_shift_us.unwrap_or(u64::MAX);
            assert!(
                off <= off_us,
                "gate off {} us after the shift (limit {})",
                off,
                off_us
            );
            assert!(
                self.off >= min_off,
                "gate off for {} samples only (at least {})",
                self.off,
                min_off
            );
            assert!(!self.back_on_early, "gate back on before the line healed");
            let back = self
                .back_on_us
                .expect("gate never back on after the restart");
            assert!(
                back <= back_us,
                "gate back on {} us after the heal (limit {})",
                back,
                back_us
            );
            assert_eq!(self.drops_after, 0, "gate off again after it came back");
        }
    }

    /// An XY3-100 input session restart while the controller's clock runs,
    /// through the firmware's tasks (spawned as in
    /// `bridge_tasks_xy3_to_xy2_end_to_end`, whose source, wiring and head
    /// read-back it shares). The source plays 20 000 frames as that test does (no
    /// flipped frame) and, from a frame near 10 000 ([`shift_start`]: its shifted
    /// period passes by chance), plays line Y 8 bits late ([`shifted_y`]): to the
    /// bridge that is exactly a Y
    /// slave that took a byte of extra clock edges, the lines out of step with
    /// every byte count plausible (`shared::xy3::step`). The bridge's step watch
    /// asks for a restart (`XY3_RESYNC`), and `line::xy3_in` restarts the three
    /// SPI slaves with the SCK-bus buffer (PF14) off while the clock runs. A real
    /// slip is healed by that restart; the source's slip by the source itself:
    /// from the first half it writes after a new session has let the clock in,
    /// Y plays in step again (that half is queued up to two ring halves after
    /// the restart and plays up to one more later: the new session sees the
    /// shift for another 1..1.5 ms, well inside its doubled 4 ms limit).
    /// The NUCLEO has no SCK-bus buffer, so `e2e::sck_gate` emulates it (PF14's
    /// own edges switch the source's CLK pin between output and pulled-down
    /// input) and checks on every edge that it held the clock off before any new
    /// SPI was on, and let it in only after all were.
    ///
    /// Checks: the shift as designed (its first period a chance pass, never two
    /// in a row; a shifted period that passes carries a Y unlike its frame's
    /// own, so one forwarded would show; more chance passes in the first 2 ms,
    /// which the watch must withhold as suspect); one session before the shift,
    /// exactly one restart after it, between `OUT_OF_STEP_NS` and ~4 ms after
    /// the shifted half was queued, and no input half lost
    /// (`tasks::input_overruns`: the restart was the bridge's request, not an
    /// overrun's); the emulated buffer's own checks; the head as in the
    /// end-to-end test (every period decodes, a frame sent or park, in order,
    /// park only after the last frame: the hold spans the outage), with one
    /// outage: the last frame before it the one before the shift (the chance
    /// pass confirms it; up to 4 fewer by the pacing), the first after it the
    /// `GOOD_RUN`-th good period after the heal plus the recovery run (+ the
    /// usual slack); no period made from the shifted line's bits (counted apart
    /// from other unknown periods); the laser gate off before the input, on
    /// within 10 ms and until the shift, off once (within ~2.9 ms of the shifted
    /// half, for at least 1 ms), back on within ~2.7 ms of the healed half and on
    /// until the input stops, off within 6 ms after.
    ///
    /// Jumpers: those of `bridge_tasks_xy3_to_xy2_end_to_end` (the backchannel
    /// one unused); none for the emulated buffer.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy3_to_xy2_restart_under_running_clock(board: Board) {
        let b = baked(RESTART_N);
        let recovery = b.recovery;
        let f = b.config.failsafe;
        let frame_us = 1_000_000 / u64::from(b.config.output.frame_rate_hz);
        // A half of the XY3-100 input (64 bytes a line: 21.3 frames).
        let xy3_half_us = (xy3::rx::WINDOW as u64 / 2 * frame_us).div_ceil(3);
        let limit_us = xy3::step::OUT_OF_STEP_NS / 1000;
        let good_run = u32::from(xy3::step::GOOD_RUN);
        // The shift, checked as designed; it starts `lead_us` into its half.
        let s = shift_start();
        let shift_half = s - s % SRC_FRAMES as u32;
        let lead_us = u64::from(s - shift_half) * frame_us;
        // The restart: the shifted half plays at most a ring half after it was
        // queued; its first bad period is decoded once its XY3 half is complete
        // and drained (a batch); the window is judged at batch times; `xy3_in`
        // takes the request after its next half.
        let restart_us =
            RING_HALF_US + lead_us + limit_us + 2 * xy3_half_us + 2 * BATCH_US + MARGIN_US;
        // The gate goes off `input_timeout_us` after the last valid frame, which
        // the bridge saw at most a half and a batch after the shift played, at
        // the next batch.
        let off_us = RING_HALF_US
            + lead_us
            + u64::from(f.input_timeout_us)
            + xy3_half_us
            + 2 * BATCH_US
            + SAMPLE_US
            + MARGIN_US;
        // Back on: the healed half plays after at most a ring half; `GOOD_RUN`
        // good periods close the watch's window, the next confirms the last,
        // `recovery_frames` more make the bridge run; their XY3 half completes,
        // the next batch drains it and sets the gate.
        let back_us = RING_HALF_US
            + (u64::from(good_run) + 1 + u64::from(recovery)) * frame_us
            + xy3_half_us
            + BATCH_US
            + SAMPLE_US
            + MARGIN_US;
        // The hold outlasts the longest outage these bounds allow (restart, the
        // heal's lag of up to two ring halves, recovery): the head never parks.
        assert!(
            u64::from(f.input_timeout_us) + u64::from(f.hold_us)
                > restart_us + 2 * RING_HALF_US + back_us,
            "failsafe.hold_us shorter than the outage"
        );

        let span = s..s + SHIFT_MAX;
        assert!(
            span.clone()
                .all(|k| shifted_head_y(k) != Some(e2e_positions(k)[1])),
            "a shifted Y word passes as its frame's own Y"
        );
        let (mut run, mut longest, mut chance) = (0u32, 0u32, 0u32);
        for k in span.clone() {
            run = if shifted_head_y(k).is_some() {
                run + 1
            } else {
                0
            };
            longest = longest.max(run);
            chance += u32::from(run > 0);
        }
        assert!(
            longest < 2,
            "{} chance passes in a row: the documented residual could forward one",
            longest
        );
        let limit_frames = (limit_us / frame_us) as u32;
        let early = (s + 1..s + limit_frames)
            .filter(|&k| shifted_head_y(k).is_some())
            .count();
        assert!(
            early >= 1,
            "no chance pass for the suspect watch to withhold"
        );
        defmt::info!(
            "shift from frame {}: {} chance passes in {} frames, {} in the first {}, at most {} in a row",
            s,
            chance,
            SHIFT_MAX,
            early,
            limit_frames,
            longest
        );

        let spawner = current_spawner().await;
        let (fw, hb, x) = Firmware::take(board);
        let _head_status = head_status_ok(&b);
        let (tx, idle, mut source) = start_source(hb.tx_dma, &b);
        // The buffer, emulated, before `xy3_in` takes PF14.
        let gate = SckGate::arm(GateIrq);
        fw.spawn(spawner, &b);
        let mut head = head_read_back(x, &b).await;

        // Phases, set by the source: 0 before the input, 1 while frames in step
        // are written, 2 once the shifted half is queued, 3 once the healed half
        // is, 4 once the last frame is (`stop_at`: once it played), 5 done.
        let phase = Cell::new(0u8);
        let input_at = Cell::new(Instant::now());
        let shift_at = Cell::new(Instant::now());
        let heal = Cell::new(None::<u32>);
        let heal_at = Cell::new(Instant::now());
        let stop_at = Cell::new(None);
        let underrun = Cell::new(false);
        let opens_at_shift = Cell::new(0u32);
        let overruns_at_input = Cell::new(0u32);

        let source_run = async {
            embassy_time::Timer::after_millis(30).await;
            let mut half = [0u32; SRC_FRAMES * SRC_TPF];
            for h in 0..RESTART_N / SRC_FRAMES as u32 {
                let k0 = h * SRC_FRAMES as u32;
                if k0 == shift_half {
                    opens_at_shift.set(gate.counts().opens);
                }
                // The restart heals the slip: once a new session has let the clock
                // in, Y plays in step from this half on.
                let restarted = gate.counts().opens > opens_at_shift.get();
                if k0 > s && heal.get().is_none() && (restarted || k0 >= s + SHIFT_MAX) {
                    heal.set(Some(k0));
                }
                for (i, slot) in half.chunks_exact_mut(SRC_TPF).enumerate() {
                    let k = k0 + i as u32;
                    let [x, y, z] = wire_words(k);
                    let out_of_step = k >= s && heal.get().is_none_or(|hk| k < hk);
                    let y = if out_of_step { shifted_y(k) } else { y };
                    tx.encode_words([x, y, z, 0, 0], slot).unwrap();
                }
                if !source.write(&half).await {
                    underrun.set(true);
                }
                if h == 0 {
                    input_at.set(Instant::now());
                    overruns_at_input.set(tasks::input_overruns());
                    phase.set(1);
                }
                if k0 == shift_half {
                    shift_at.set(Instant::now());
                    phase.set(2);
                }
                if heal.get() == Some(k0) {
                    heal_at.set(Instant::now());
                    phase.set(3);
                }
            }
            phase.set(4);
            if !source.finish(&mut half, idle).await {
                underrun.set(true);
            }
            stop_at.set(Some(Instant::now()));
            embassy_time::Timer::after_millis(300).await;
            phase.set(5);
        };

        // The gate every 100 us: before the shift and after the stop as in the
        // end-to-end test, the outage between.
        let mut watch = GateWatch::default();
        let mut outage = Outage::default();
        let gate_sampler = async {
            loop {
                let g = laser_gate_high();
                let p = phase.get();
                let since_input = input_at.get().elapsed();
                let since_stop = stop_at.get().map(|t: Instant| t.elapsed());
                match p {
                    0 | 1 => watch.sample(p, g, since_input, since_stop),
                    2 | 3 => {
                        let since_heal = (p == 3).then(|| heal_at.get().elapsed());
                        outage.sample(g, shift_at.get().elapsed(), since_heal);
                    }
                    4 => watch.sample(2, g, since_input, since_stop),
                    _ => break,
                }
                embassy_time::Timer::after_micros(100).await;
            }
        };

        let mut log = HeadLog::default();
        let mut shifted = 0u32;
        // A period that is no frame sent: made from the shifted line's bits if
        // its X names a shifted frame and Y is that frame's shifted word.
        let reader = read_head(
            &mut head,
            &phase,
            5,
            (RESTART_N, b.park, None),
            &mut log,
            |v, k| {
                let out_of_step = k >= s && heal.get().map_or(k < s + SHIFT_MAX, |hk| k < hk);
                let made =
                    out_of_step && shifted_head_y(k) == Some(v[1]) && e2e_positions(k)[2] == v[2];
                shifted += u32::from(made);
                made
            },
        );
        let (_, _, reading) = embassy_futures::join::join3(source_run, gate_sampler, reader).await;
        drop(source);
        let counts = gate.counts();
        let overruns = tasks::input_overruns().wrapping_sub(overruns_at_input.get());
        let heal = heal.get().expect("the line never healed");
        let restart_after_us = counts
            .closed_at_us
            .wrapping_sub(shift_at.get().as_micros() as u32);
        let heal_after_us = (heal_at.get().as_micros() as u32).wrapping_sub(counts.closed_at_us);
        defmt::info!("head: {}, made from the shifted line: {}", log, shifted);
        defmt::info!("gate: {}; outage: {}", watch, outage);
        defmt::info!(
            "sck gate: {}; restart {} us after the shifted half was queued, healed half queued {} us after it (frame {}); input overruns {}",
            counts,
            restart_after_us,
            heal_after_us,
            heal,
            overruns
        );

        assert!(
            !underrun.get(),
            "the source's DMA ran out of words (test bench too slow)"
        );
        reading.check();
        // The restart: one, asked by the bridge, at its time; the emulated buffer
        // held the clock off while it mattered.
        counts.check();
        assert_eq!(opens_at_shift.get(), 1, "sessions before the shift");
        assert_eq!(counts.opens, 2, "sessions in all (one restart)");
        assert_eq!(overruns, 0, "input halves lost (an overrun restarts too)");
        assert!(
            u64::from(heal_after_us) <= 2 * RING_HALF_US + MARGIN_US,
            "the source healed {} us after the restart (test bench too slow)",
            heal_after_us
        );
        assert!(
            (limit_us + lead_us - 100..=restart_us).contains(&u64::from(restart_after_us)),
            "restart {} us after the shifted half was queued",
            restart_after_us
        );
        // The head: every period a frame sent or park, none made from the shifted
        // line, in order across one outage that the hold spans.
        log.head.check();
        assert_eq!(
            shifted, 0,
            "frames made from the shifted line's bits reached the head"
        );
        assert_eq!(log.unknown, 0, "head periods that are no frame sent");
        log.seq.check_outages(RESTART_N, recovery, 1);
        let (last, first) = log.seq.gap.expect("no outage");
        assert!(
            last < s && last + 5 >= s,
            "last frame {} before the outage (shift at {})",
            last,
            s
        );
        // Chance passes just before the heal count towards the good run.
        let before = (1..good_run)
            .take_while(|&i| shifted_head_y(heal - i).is_some())
            .count() as u32;
        let lo = heal + good_run - 1 - before + recovery - 1;
        let hi = heal + good_run + u32::from(xy3::rx::LOCK_PERIODS) + recovery + 10;
        assert!(
            (lo..hi).contains(&first),
            "first frame {} after the outage (healed at {}, expected {}..{})",
            first,
            heal,
            lo,
            hi
        );
        // The laser gate.
        watch.check();
        // At least 1 ms off: the gate goes off 1 ms after the shift's last good
        // period and comes back after the restart, the heal and the recovery run.
        outage.check(off_us, back_us, 10);
        assert!(!laser_gate_high(), "gate on at the end");
    }

    /// The overrun test's source: frames sent (150 ms, room for the stall's
    /// attempts from 40 ms in).
    const OVERRUN_N: u32 = 15_000;
    /// The stall (us): a busy loop in the CEC interrupt at P5, above the line
    /// executor (P6, `app::LINE_PRIORITY`) and below the DMA handlers (P0), so the
    /// DMA transfer-complete counts that embassy's rings detect a lap by stay exact
    /// (a critical section would merge two laps' interrupts into one and could hide
    /// the overrun it is meant to cause).
    const STALL_US: u64 = 300;
    /// The stall of `bridge_tasks_xy3_to_xy2_stall_beyond_output`: longer than the
    /// head output's ring (500 us), so the output runs dry whatever its phase and
    /// plays idle for at least 200 us; short enough that the source's queue (at
    /// least [`SRC_QUEUED_US`] where it starts) outlasts it and the catch-up.
    const LONG_STALL_US: u64 = 700;
    /// The source's DMA (DMA1 S6) time into its half at which the long stall may
    /// start: up to this the source has written the half that just freed (thread
    /// mode, from [`E_MIN_US`]) and holds 1000 - 150 = 850 us of words.
    const SRC_E_MAX_US: u16 = 150;
    const SRC_QUEUED_US: u64 = 1000 - SRC_E_MAX_US as u64;
    /// The source's ring (words, `start_source`) and words per microsecond.
    const SRC_RING: u16 = (2 * SRC_FRAMES * SRC_TPF) as u16;
    const SRC_WORDS_PER_US: u16 = 5;
    /// The ring guard's bound (`wave_out`, "No stale words"): the gate goes off
    /// and the head goes idle at the first output half boundary the bridge has not
    /// refilled for, at most two halves (2 x 250 us) after the stall starts, plus
    /// the guard's latency and the probe's resolution (1 us ticks).
    const GUARD_SLACK_US: u64 = 10;
    /// XY3-100 input: line X's ring (`line::xy3_in`, two halves of
    /// `channels::XY3_HALF` bytes) on DMA1 stream 0, filled at 3 bytes a frame
    /// period: 0.3 bytes/us at 100 kHz.
    const X_RING: u16 = 2 * xy_bridge::channels::XY3_HALF as u16;
    /// The X ring's fill, within its half, at which the stall may start: with
    /// [`STALL_US`] more bytes the DMA passes the read position (`xy3_in` reads each
    /// half at once, so its read position is the current half's start), an overrun
    /// (embassy: more than a ring written unread) whatever the pend latency.
    const U_LO: u16 = 48;
    /// The head output's ring (`bridge::bridge_wave_out`: two batches of
    /// `WAVE_BATCH` = 1000 words, 25 XY2-100 frames of 40 ticks at 4 MHz, 250 us)
    /// on DMA2 stream 1, and its words (ticks, `head_port::XY2_TICK_HZ`) per
    /// microsecond.
    const OUT_RING: u16 = 2000;
    const OUT_WORDS_PER_US: u16 = (XY2_TICK_HZ / 1_000_000) as u16;
    /// The output half's elapsed time at which the stall may start: from
    /// `E_MIN_US` the bridge has written the half that just freed (it runs before
    /// thread mode does), and up to `E_MAX_US` the written half outlasts the stall
    /// and the catch-up until the bridge's next write (500 - 120 = 380 us of
    /// queued words against 300 + [`CATCH_UP_US`]), so the head never underruns
    /// (which would replay the ring's stale batches: frames going back, which the
    /// head check counts).
    const E_MIN_US: u16 = 10;
    const E_MAX_US: u16 = 120;
    /// After the stall, before the bridge writes: the pending DMA and SYNC-mark
    /// handlers, then `xy3_in` (woken first: its X read returns the overrun, it
    /// drops its session and logs) and the bridge's copy of its batch. Estimated,
    /// not measured (tens of microseconds at 400-480 MHz).
    const CATCH_UP_US: u64 = 40;
    /// Attempts at meeting both windows (a poll of `POLL_US` each, from a start
    /// stepped through the input's and the output's phases) and the poll's length,
    /// short enough that with the stall thread mode is held at most 360 us (the
    /// source's ring holds at least a 500 us half, the read-back's 2 ms).
    const STALL_ATTEMPTS: u32 = 50;
    const POLL_US: u64 = 60;
    /// `line::xy3_in`'s wait after a failed session before the next (1 ms).
    const RESTART_WAIT_US: u64 = 1_000;

    /// `embassy_time` microseconds (low 32 bits) at the stall's start, and whether
    /// it ran.
    static STALL_AT_US: AtomicU32 = AtomicU32::new(0);
    static STALLED: AtomicBool = AtomicBool::new(false);
    /// The stall's length (us).
    static STALL_LEN_US: AtomicU32 = AtomicU32::new(STALL_US as u32);
    /// What the stall saw on the head's CLK (PD0) and the laser gate (PF13), in us
    /// from its start: CLK changes in all, the last one, the first time the gate
    /// read low (`u32::MAX`: never), and CLK changes from then on.
    static PROBE_EDGES: AtomicU32 = AtomicU32::new(0);
    static PROBE_LAST_EDGE_US: AtomicU32 = AtomicU32::new(0);
    static PROBE_GATE_OFF_US: AtomicU32 = AtomicU32::new(u32::MAX);
    static PROBE_EDGES_AFTER_OFF: AtomicU32 = AtomicU32::new(0);
    /// The ring guard's miss count (`tasks::guard_misses`, the statistics' count)
    /// at the stall's start and end, and once the test's source finished.
    static PROBE_MISSES_AT_START: AtomicU32 = AtomicU32::new(0);
    static PROBE_MISSES_AT_END: AtomicU32 = AtomicU32::new(0);
    static MISSES_AT_INPUT: AtomicU32 = AtomicU32::new(0);
    static MISSES_AFTER: AtomicU32 = AtomicU32::new(0);

    /// The CEC interrupt: one busy loop of `STALL_LEN_US`, watching the head's CLK
    /// and the laser gate while the line executor (and everything below P5) is
    /// held: only the DMA and the ring guard (P0) act on the head meanwhile.
    struct StallHandler;

    impl Handler<CEC> for StallHandler {
        unsafe fn on_interrupt() {
            let t0 = Instant::now();
            STALL_AT_US.store(t0.as_micros() as u32, Ordering::Relaxed);
            PROBE_MISSES_AT_START.store(tasks::guard_misses(), Ordering::Relaxed);
            let len = Duration::from_micros(u64::from(STALL_LEN_US.load(Ordering::Relaxed)));
            let clk = || pac::GPIOD.idr().read().idr(0) == pac::gpio::vals::Idr::HIGH;
            let mut level = clk();
            let (mut edges, mut last, mut off, mut after) = (0u32, 0u32, u32::MAX, 0u32);
            loop {
                let t = t0.elapsed();
                if t >= len {
                    break;
                }
                let us = t.as_micros() as u32;
                let now = clk();
                if now != level {
                    level = now;
                    edges += 1;
                    last = us;
                    if off != u32::MAX {
                        after += 1;
                    }
                }
                if off == u32::MAX && !laser_gate_high() {
                    off = us;
                }
            }
            PROBE_EDGES.store(edges, Ordering::Relaxed);
            PROBE_LAST_EDGE_US.store(last, Ordering::Relaxed);
            PROBE_GATE_OFF_US.store(off, Ordering::Relaxed);
            PROBE_EDGES_AFTER_OFF.store(after, Ordering::Relaxed);
            PROBE_MISSES_AT_END.store(tasks::guard_misses(), Ordering::Relaxed);
            STALLED.store(true, Ordering::Relaxed);
        }
    }

    /// Which stall a test wants.
    #[derive(Clone, Copy, PartialEq, Eq)]
    enum StallKind {
        /// [`STALL_US`], timed so that the head output does not run dry
        /// (`bridge_tasks_xy3_to_xy2_restart_after_overrun`: the restart alone).
        WithinOutput,
        /// [`LONG_STALL_US`]: the head output runs dry
        /// (`bridge_tasks_xy3_to_xy2_stall_beyond_output`).
        BeyondOutput,
    }

    impl StallKind {
        fn us(self) -> u64 {
            match self {
                StallKind::WithinOutput => STALL_US,
                StallKind::BeyondOutput => LONG_STALL_US,
            }
        }
    }

    /// Where the stall starts: line X's fill within its half (bytes) and the head
    /// output's time into its half (us).
    #[derive(Clone, Copy, Debug, defmt::Format)]
    struct StallPoint {
        x_fill: u16,
        out_us: u16,
        attempt: u32,
    }

    /// Polls the DMA positions for up to [`POLL_US`] and, inside one critical
    /// section with the check (nothing at P6 can run between), pends the stall once
    /// they are in their windows: for [`StallKind::WithinOutput`] line X's fill and
    /// the head output's phase, for [`StallKind::BeyondOutput`] the source's phase
    /// (X laps at any fill, the output runs dry at any phase).
    fn try_stall(attempt: u32, kind: StallKind) -> Option<StallPoint> {
        let end = Instant::now() + Duration::from_micros(POLL_US);
        while Instant::now() < end {
            let hit = cortex_m::interrupt::free(|_| {
                let x = pac::DMA1.st(0).ndtr().read().ndt();
                let o = pac::DMA2.st(1).ndtr().read().ndt();
                let src = pac::DMA1.st(6).ndtr().read().ndt();
                // NDTR counts down from the ring's length (wrapping: never above it
                // while the rings run).
                let x_fill = X_RING.wrapping_sub(x) % X_RING % (X_RING / 2);
                let out_us =
                    OUT_RING.wrapping_sub(o) % OUT_RING % (OUT_RING / 2) / OUT_WORDS_PER_US;
                let src_us =
                    SRC_RING.wrapping_sub(src) % SRC_RING % (SRC_RING / 2) / SRC_WORDS_PER_US;
                let ok = match kind {
                    StallKind::WithinOutput => {
                        x_fill >= U_LO && (E_MIN_US..=E_MAX_US).contains(&out_us)
                    }
                    StallKind::BeyondOutput => (E_MIN_US..=SRC_E_MAX_US).contains(&src_us),
                };
                if ok {
                    CEC::pend();
                }
                ok.then_some(StallPoint {
                    x_fill,
                    out_us,
                    attempt,
                })
            });
            if hit.is_some() {
                return hit;
            }
        }
        None
    }

    /// An XY3-100 input session restart after a real SPI DMA ring overrun while
    /// the controller's clock runs, through the firmware's tasks (spawned as in
    /// `bridge_tasks_xy3_to_xy2_end_to_end`, with its source, wiring and head
    /// read-back, and the emulated SCK-bus buffer of
    /// `bridge_tasks_xy3_to_xy2_restart_under_running_clock`). The source plays
    /// 15 000 frames in step; from 40 ms in, the test stalls the line executor for
    /// [`STALL_US`] with a P5 busy loop (`StallHandler`). The line executor runs
    /// both `line::xy3_in` and `bridge_wave_out` (`app::controller_xy3`,
    /// `app::head_wave`), so a stall that laps the input's 128-byte rings (427 us)
    /// starves the output as well, whose ring holds 500 us: at an arbitrary moment
    /// only 250..500 us are queued, and an output underrun replays the ring's
    /// stale batches at the head. So the stall starts where both are known
    /// ([`try_stall`]): line X at least [`U_LO`] bytes into its half (300 us more
    /// lap the ring: overrun certain) and the output 10..120 us into its half (the
    /// next batch is written, 380 us or more queued: no underrun). Since the ring
    /// guard (`wave_out`, "No stale words") an underrun would no longer replay old
    /// batches (the head would get idle words, the gate off), so the output window
    /// is not needed for safety any more: it keeps this test to the input restart
    /// alone; `bridge_tasks_xy3_to_xy2_stall_beyond_output` runs the output dry on
    /// purpose. The X read then
    /// returns the overrun, `xy3_in` counts it, waits 1 ms and starts a new session
    /// behind the buffer.
    ///
    /// Checks: the stall ran (within 50 attempts); exactly one input overrun
    /// (`tasks::input_overruns`: the X ring's, and no input half lost otherwise);
    /// one restart (two closes and opens of the emulated buffer, its own checks),
    /// closed 1 ms + the stall after it started (+ a batch and the margin); the
    /// head as in the end-to-end test (every period decodes, a frame sent or park,
    /// none made from other bytes, in order: a replay of stale batches would go
    /// back, park only after the last frame) with exactly one outage, the first
    /// frame after it at least the stall, the restart wait and the recovery run
    /// after the last before it, and at most that plus what the restart's
    /// latency, the lost half, the pacing and the margins add (the hold spans it:
    /// no park); the laser gate off before the input, on within 10 ms and until
    /// the stall, off once within `input_timeout_us` + two batches of the stall
    /// (for at least 0.5 ms), back on only after the new session opened and
    /// within the lock and recovery run of it, on until the input stops, off
    /// within 6 ms after.
    ///
    /// Jumpers: those of `bridge_tasks_xy3_to_xy2_end_to_end` (the backchannel
    /// one unused); none for the emulated buffer.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy3_to_xy2_restart_after_overrun(board: Board) {
        overrun_run(board, StallKind::WithinOutput).await;
    }

    /// A line-executor stall longer than the head output's queued words (the ring
    /// guard, `wave_out` "No stale words"), through the same tasks, source,
    /// read-back and emulated buffer as
    /// `bridge_tasks_xy3_to_xy2_restart_after_overrun`: a [`LONG_STALL_US`] (700 us)
    /// P5 busy loop from where the source holds at least [`SRC_QUEUED_US`] of words
    /// (at any output phase: the output's 250..500 us run dry), which laps the
    /// input ring as well, so the input restarts as in that test. The stall itself
    /// watches the head's CLK (PD0) and the laser gate (PF13) while only P0 runs.
    ///
    /// Checks: those of the overrun test (every head period a frame sent or park,
    /// in order, no unknown one: no old batch replayed, positions never back; one
    /// outage, the hold spanning it; one restart; the gate's outage), and, seen
    /// during the stall: the head was clocking at its start, its CLK stops (idle
    /// words) no later than the gate goes off, which is within two output halves
    /// (500 us) + [`GUARD_SLACK_US`] of the stall's start, no CLK edge after that
    /// for the rest of the stall (at least 200 us of idle), and the gate stays off
    /// through it.
    ///
    /// Jumpers: those of `bridge_tasks_xy3_to_xy2_end_to_end` (the backchannel
    /// one unused); none for the emulated buffer.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy3_to_xy2_stall_beyond_output(board: Board) {
        overrun_run(board, StallKind::BeyondOutput).await;
        let edges = PROBE_EDGES.load(Ordering::Relaxed);
        let last = u64::from(PROBE_LAST_EDGE_US.load(Ordering::Relaxed));
        let off = PROBE_GATE_OFF_US.load(Ordering::Relaxed);
        let after = PROBE_EDGES_AFTER_OFF.load(Ordering::Relaxed);
        defmt::info!(
            "stall probe: {} CLK edges, the last at {} us; gate off at {} us, {} edges after",
            edges,
            last,
            off,
            after
        );
        assert!(edges > 0, "the head was not clocking when the stall began");
        assert!(off != u32::MAX, "the gate never went off during the stall");
        let off = u64::from(off);
        assert!(
            off <= 2 * BATCH_US + GUARD_SLACK_US,
            "gate off {} us into the stall (bound {})",
            off,
            2 * BATCH_US + GUARD_SLACK_US
        );
        assert!(
            last <= off + 2,
            "head clocked at {} us, after the gate went off at {} us",
            last,
            off
        );
        // Idle from there to the stall's end: at least 700 - 512 us.
        assert_eq!(after, 0, "head CLK edges after the gate went off");
        // Counted (`tasks::guard_misses`, the statistics' count): during the
        // stall every boundary into an unfilled half, the first within two halves
        // (500 us) of its start, then one per half (250 us) to its end at 700 us:
        // 1..=3. After it, the half the late claim skips (`ring_guard::Claim::Late`),
        // and one more if a boundary fell before the bridge's claim: 1..=2.
        let at_end = PROBE_MISSES_AT_END.load(Ordering::Relaxed);
        let during = at_end.wrapping_sub(PROBE_MISSES_AT_START.load(Ordering::Relaxed));
        let later = MISSES_AFTER.load(Ordering::Relaxed).wrapping_sub(at_end);
        assert!(
            (1..=3).contains(&during),
            "{} guard misses during the stall",
            during
        );
        assert!(
            (1..=2).contains(&later),
            "{} guard misses after the stall",
            later
        );
    }

    /// The body of the two overrun tests, for a stall of `kind`.
    async fn overrun_run(board: Board, kind: StallKind) {
        let stall_us = kind.us();
        let b = baked(OVERRUN_N);
        let recovery = b.recovery;
        let f = b.config.failsafe;
        let frame_us = 1_000_000 / u64::from(b.config.output.frame_rate_hz);
        assert_eq!(frame_us, 10, "the windows are written for 100 kHz");
        // Whole frames fill each output half (the bridge writes a half a batch),
        // so the output DMA's half boundary is the bridge's write boundary.
        let out_tpf = XY2_TICK_HZ / b.config.output.frame_rate_hz;
        assert_eq!(u32::from(OUT_RING / 2) % out_tpf, 0, "output batch != half");
        let xy3_half_us = (xy3::rx::WINDOW as u64 / 2 * frame_us).div_ceil(3);
        let half_frames = (xy3::rx::WINDOW as u64 / 2).div_ceil(3);
        // The windows as designed: the stall laps X's ring from the lowest fill;
        // within the output's queued words or beyond all of them; within the
        // source's.
        assert!(
            u64::from(U_LO) + stall_us * 3 / frame_us > u64::from(X_RING),
            "the stall does not lap the input ring"
        );
        match kind {
            StallKind::WithinOutput => assert!(
                u64::from(E_MAX_US) + stall_us + CATCH_UP_US < 2 * BATCH_US,
                "the stall could underrun the head output"
            ),
            StallKind::BeyondOutput => {
                assert!(
                    stall_us >= 2 * BATCH_US + 200,
                    "the stall does not outlast the head output"
                );
                assert!(
                    stall_us + u64::from(E_MIN_US) + CATCH_UP_US < SRC_QUEUED_US,
                    "the stall could underrun the source"
                );
            }
        }

        // The gate goes off `input_timeout_us` after the last valid frame (before
        // the stall), at a batch; back on once the new session's first periods
        // lock, the recovery run passes, their half completes and a batch drains
        // it.
        let off_us =
            u64::from(f.input_timeout_us).max(stall_us) + 2 * BATCH_US + SAMPLE_US + MARGIN_US;
        let back_us = (u64::from(xy3::rx::LOCK_PERIODS) + 2 + u64::from(recovery)) * frame_us
            + xy3_half_us
            + 2 * BATCH_US
            + SAMPLE_US
            + MARGIN_US;
        let outage_us = stall_us + RESTART_WAIT_US + back_us;
        assert!(
            u64::from(f.input_timeout_us) + u64::from(f.hold_us) > outage_us,
            "failsafe.hold_us shorter than the outage"
        );

        let spawner = current_spawner().await;
        let (fw, hb, x) = Firmware::take(board);
        let _head_status = head_status_ok(&b);
        let (tx, idle, mut source) = start_source(hb.tx_dma, &b);
        let gate = SckGate::arm(GateIrq);
        STALLED.store(false, Ordering::Relaxed);
        STALL_LEN_US.store(stall_us as u32, Ordering::Relaxed);
        CEC::set_priority(Priority::P5);
        CEC::unpend();
        // SAFETY: the handler bound for CEC is `StallHandler`, which only waits
        // and writes its two atomics.
        unsafe { CEC::enable() };
        fw.spawn(spawner, &b);
        let mut head = head_read_back(x, &b).await;

        // Phases: 0 before the input, 1 while it runs in step, 2 once the stall
        // ran, 3 once the last frame is queued (`stop_at`: once it played), 4 done.
        let phase = Cell::new(0u8);
        let input_at = Cell::new(Instant::now());
        let stall_at = Cell::new(Instant::now());
        let open_at = Cell::new(None::<Instant>);
        let stop_at = Cell::new(None);
        let underrun = Cell::new(false);
        let overruns_at_input = Cell::new(0u32);
        let point = Cell::new(None::<StallPoint>);

        let source_run = async {
            embassy_time::Timer::after_millis(30).await;
            let mut half = [0u32; SRC_FRAMES * SRC_TPF];
            for h in 0..OVERRUN_N / SRC_FRAMES as u32 {
                for (i, slot) in half.chunks_exact_mut(SRC_TPF).enumerate() {
                    let [x, y, z] = wire_words(h * SRC_FRAMES as u32 + i as u32);
                    tx.encode_words([x, y, z, 0, 0], slot).unwrap();
                }
                if !source.write(&half).await {
                    underrun.set(true);
                }
                if h == 0 {
                    input_at.set(Instant::now());
                    overruns_at_input.set(tasks::input_overruns());
                    MISSES_AT_INPUT.store(tasks::guard_misses(), Ordering::Relaxed);
                    phase.set(1);
                }
            }
            phase.set(3);
            if !source.finish(&mut half, idle).await {
                underrun.set(true);
            }
            stop_at.set(Some(Instant::now()));
            embassy_time::Timer::after_millis(300).await;
            phase.set(4);
        };

        // The stall, from 40 ms into the input (the gate is on by 10 ms), its
        // polls started 37 us further into the phases each attempt.
        let stall = async {
            while phase.get() < 1 || input_at.get().elapsed() < Duration::from_millis(40) {
                embassy_time::Timer::after_millis(1).await;
            }
            for attempt in 0..STALL_ATTEMPTS {
                embassy_time::Timer::after_micros(400 + 37 * u64::from(attempt % 7)).await;
                // Only while the frames in step play (not into the source's end).
                if phase.get() != 1 {
                    return;
                }
                if let Some(p) = try_stall(attempt, kind) {
                    // The stall ran before this line (P5 over thread mode).
                    point.set(Some(p));
                    let now = Instant::now();
                    let ago =
                        (now.as_micros() as u32).wrapping_sub(STALL_AT_US.load(Ordering::Relaxed));
                    stall_at.set(now - Duration::from_micros(u64::from(ago)));
                    phase.set(2);
                    return;
                }
            }
        };

        let mut watch = GateWatch::default();
        let mut outage = Outage::default();
        let gate_sampler = async {
            loop {
                let g = laser_gate_high();
                let p = phase.get();
                let since_input = input_at.get().elapsed();
                let since_stop = stop_at.get().map(|t: Instant| t.elapsed());
                match p {
                    0 | 1 => watch.sample(p, g, since_input, since_stop),
                    2 => {
                        if open_at.get().is_none() && gate.counts().opens >= 2 {
                            open_at.set(Some(Instant::now()));
                        }
                        let since_open = open_at.get().map(|t| t.elapsed());
                        outage.sample(g, stall_at.get().elapsed(), since_open);
                    }
                    3 => watch.sample(2, g, since_input, since_stop),
                    _ => break,
                }
                embassy_time::Timer::after_micros(100).await;
            }
        };

        let mut log = HeadLog::default();
        let reader = read_head(
            &mut head,
            &phase,
            4,
            (OVERRUN_N, b.park, None),
            &mut log,
            |_, _| false,
        );
        let (_, _, _, reading) =
            embassy_futures::join::join4(source_run, stall, gate_sampler, reader).await;
        drop(source);
        CEC::disable();
        MISSES_AFTER.store(tasks::guard_misses(), Ordering::Relaxed);
        let counts = gate.counts();
        let overruns = tasks::input_overruns().wrapping_sub(overruns_at_input.get());
        let close_after_us = counts
            .closed_at_us
            .wrapping_sub(STALL_AT_US.load(Ordering::Relaxed));
        defmt::info!("head: {}", log);
        defmt::info!("gate: {}; outage: {}", watch, outage);
        defmt::info!(
            "stall at {}: sck gate {}, closed {} us after the stall's start; input overruns {}",
            point.get(),
            counts,
            close_after_us,
            overruns
        );

        assert!(
            !underrun.get(),
            "the source's DMA ran out of words (test bench too slow)"
        );
        reading.check();
        assert!(
            point.get().is_some(),
            "no stall point in {} attempts",
            STALL_ATTEMPTS
        );
        assert!(STALLED.load(Ordering::Relaxed), "the stall never ran");
        // The ring guard: no miss while the bridge kept up (before the stall;
        // within the output's queue, none at all).
        let misses_at_input = MISSES_AT_INPUT.load(Ordering::Relaxed);
        let misses_at_stall = PROBE_MISSES_AT_START.load(Ordering::Relaxed);
        defmt::info!(
            "guard misses: {} at the input, {} at the stall, {} at its end, {} after",
            misses_at_input,
            misses_at_stall,
            PROBE_MISSES_AT_END.load(Ordering::Relaxed),
            MISSES_AFTER.load(Ordering::Relaxed)
        );
        assert_eq!(
            misses_at_stall, misses_at_input,
            "guard misses before the stall"
        );
        if kind == StallKind::WithinOutput {
            assert_eq!(
                MISSES_AFTER.load(Ordering::Relaxed),
                misses_at_input,
                "guard misses (the output's queue outlasts the stall)"
            );
        }
        // The overrun and its restart.
        assert_eq!(overruns, 1, "input overruns (the stall's X ring lap)");
        counts.check();
        assert_eq!(counts.closes, 2, "SCK-bus buffer closes (one restart)");
        assert_eq!(counts.opens, 2, "sessions in all (one restart)");
        assert!(
            (stall_us + RESTART_WAIT_US..=stall_us + RESTART_WAIT_US + BATCH_US + MARGIN_US)
                .contains(&u64::from(close_after_us)),
            "restart {} us after the stall's start",
            close_after_us
        );
        // The head: every period a frame sent or park, in order (no stale batch
        // replayed), across one outage that the hold spans.
        log.head.check();
        assert_eq!(log.unknown, 0, "head periods that are no frame sent");
        log.seq.check_outages(OVERRUN_N, recovery, 1);
        let (last, first) = log.seq.gap.expect("no outage");
        let lost = u64::from(first - last);
        // The last frame before the outage played before the stall (the X half in
        // progress then is lost with the overrun, up to a half of frames earlier,
        // and the pacing skips up to 4); the new session opens at least the stall
        // and the restart wait later (at most a batch and the margin more), and
        // its first frame forwarded is the recovery run's end as at the start
        // (`FrameSeq::check`: `recovery - 1 ..recovery + 10`).
        let lo = (stall_us + RESTART_WAIT_US) / frame_us + u64::from(recovery) - 1;
        let hi = (stall_us + RESTART_WAIT_US + BATCH_US + MARGIN_US) / frame_us
            + half_frames
            + 4
            + u64::from(recovery)
            + 10;
        assert!(
            (lo..=hi).contains(&lost),
            "outage from frame {} to {} ({} frames, expected {}..={})",
            last,
            first,
            lost,
            lo,
            hi
        );
        // The laser gate.
        watch.check();
        // Off from `input_timeout_us` after the last valid frame (before the
        // stall; at most a batch and the slot lag later: ~1.75 ms after it) until
        // the recovery run after the new session (which opens 1.3 ms after the
        // stall: on again no earlier than ~2.3 ms after it): 0.5 ms at least.
        outage.check(off_us, back_us, 5);
        assert!(!laser_gate_high(), "gate on at the end");
    }
}
