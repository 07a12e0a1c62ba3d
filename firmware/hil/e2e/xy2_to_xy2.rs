//! An XY2-100 controller -> XY2-100 head with the STATUS word on both sides:
//! `line::xy2_in` with the status word towards the controller
//! (`tasks/ctrl_word.rs`), and the waveform bridge loop with the XY2-100 encoder and
//! the head's status word (`tasks/head_word.rs`). Two images carry it, one per
//! geometry of `head_word`'s thinning: `configs/xy2-word-to-xy2-word.toml` (100 kHz,
//! 40 output ticks per frame period: 20 samples) and
//! `configs/xy2-word-to-xy2-word-odd.toml` (97.56 kHz, 41 ticks: 20 bits and one
//! idle tick, 21 samples). The test reads the geometry from the baked configuration;
//! nothing else in it depends on the head's rate (the read-backs and the test head
//! follow the head's clock edges, the controller side runs at its own 100 kHz).

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use core::cell::Cell;
    use core::sync::atomic::Ordering;

    use crate::e2e::checks::{
        assert_identity_axes, head_drivers_on, laser_gate_high, phase_end, AlarmGateWatch,
        FrameSeq, Xy2Periods, HEAD_XY2_PINS,
    };
    use crate::e2e::source::{e2e_positions, frame_of_x, BsrrSource};
    use crate::e2e::xy2_source::{SRC_FRAMES, SRC_PINS, SRC_TICK_HZ, SRC_TPF};
    use embassy_futures::select::{select, Either};
    use embassy_stm32::dma::{self, Transfer};
    use embassy_stm32::gpio::{AfType, AnyPin, Flex, Level, Output, Pull, Speed};
    use embassy_stm32::peripherals::{PA15, PB12, PE11, PF6, PG10};
    use embassy_stm32::timer::low_level::Timer;
    use embassy_stm32::{pac, peripherals, Peri};
    use embassy_time::{Duration, Instant};
    use shared::bridge::{AfterHold, StatusForm, Timing};
    use shared::head_port::XY2_TICK_HZ;
    use shared::model::{Alarms, Line};
    use shared::xy2::rx::Receiver as Xy2Receiver;
    use shared::xy2::status_line::{StatusWordConfig, StatusWordReceiver};
    use shared::xy2::tx::Transmitter as Xy2Tx;
    use shared::xy2::{
        decode as xy2_decode, encode as xy2_encode, Frame as Frame2, LinkConfig, Mode, StatusWord,
    };
    use xy_bridge::app::{self, Executors};
    use xy_bridge::board::{self, Board};
    use xy_bridge::channels::{BridgeSnapshot, BRIDGE_SNAPSHOT, SNAPSHOT_WANTED};
    use xy_bridge::config::{self, Roles};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    use xy_bridge::drivers::wave_out::timing_critical;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// Frames the source sends with their checks passing, and the one among them
    /// sent with its X parity bit flipped; then `TAIL` frames all with a
    /// flipped X parity bit (10 ms): the controller still clocks, the bridge loses
    /// its input.
    const N: u32 = 30_000;
    const BAD: u32 = 12_345;
    const TAIL: u32 = 1_000;
    /// SPI words (16 bits) per read of each read-back line: 1024 bits, ~0.5 ms.
    const CHUNK: usize = 64;
    /// The head's status word from 100 ms into the input (an alarm) to 200 ms.
    const ALARM_FROM_MS: u64 = 100;
    const ALARM_TO_MS: u64 = 200;
    /// DMA1 stream of the test head's STATUS player (DMA1 S5 = the head
    /// backchannel's RX, free here; DMA1 rather than DMA2, whose streams already
    /// serve ~12 M requests/s of the firmware's, so its request waits less) and the
    /// length of its ring: two status frames (words of a frame: one per head CLK
    /// falling edge).
    const HEAD_STREAM: usize = 5;
    const HEAD_RING: usize = 40;
    /// The test head's STATUS pin: PE5 (port E, beside the source's pins).
    const HEAD_STATUS_PIN: u32 = 5;

    /// A test-only XY2-100 head's STATUS output: TIM3 captures the head's CLK
    /// falling edges on CH1 (PC6, AF2; TIM3 only clocks HANS-100 SPIs, free here),
    /// and each capture requests one DMA1 stream 5 transfer (DMAMUX request
    /// TIM3_CH1) of the next word of a circular ring into GPIOE's BSRR, setting or
    /// resetting PE5 (RM0433 "General-purpose timers", input capture mode and
    /// TIMx_DIER.CC1DE). So bit k of a status frame goes out on the falling edge of
    /// bit k of the head's frame, as a head shifts it out on our clock
    /// (`shared::xy2::status_line`, "Status-word form"). The first edge the bridge
    /// sends is the first bit of its first frame, it sends whole frames, and the
    /// ring holds two whole frames, so the ring keeps the frame phase.
    struct HeadStatus {
        _timer: Timer<'static, peripherals::TIM3>,
        _transfer: Transfer<'static>,
        ring: *mut u32,
        _pins: (Flex<'static>, Output<'static>),
    }

    impl HeadStatus {
        /// Starts playing `frame` (a 20-bit status frame) on the head's clock.
        fn start(
            tim: Peri<'static, peripherals::TIM3>,
            clk: Peri<'static, peripherals::PC6>,
            dma: Peri<'static, peripherals::DMA1_CH5>,
            slot: &'static mut Option<dma::Channel<'static>>,
            frame: u32,
        ) -> Self {
            // SAFETY: PE5 is in no `board::Resources` group and no firmware task
            // uses it; this test is its only user (BsrrSource's words touch only
            // PE2/3/4/9/10).
            let status_pin: Peri<'static, AnyPin> = unsafe { peripherals::PE5::steal() }.into();
            let status = Output::new(status_pin, Level::Low, Speed::VeryHigh);
            // PC6 as TIM3_CH1 (AF2, datasheet alternate-function table), an input.
            let mut clk = Flex::new(clk);
            clk.set_as_af_unchecked(2, AfType::input(Pull::Down));
            let ring = dma_ring!(".sram2", u32, HEAD_RING);
            let words = frame_words(frame);
            for (i, w) in ring.iter_mut().enumerate() {
                *w = words[i % 20];
            }
            let ring: *mut [u32] = ring;
            let timer = Timer::new(tim);
            let regs = timer.regs_gp16();
            regs.psc().write_value(0);
            regs.arr().write(|w| w.set_arr(u16::MAX));
            // CC1 an input on TI1, no filter; capture on the falling edge
            // (CC1P = 1, CC1NP = 0).
            regs.ccmr_input(0).modify(|w| {
                w.set_ccs(0, pac::timer::vals::CcmrInputCcs::TI4);
                w.set_icf(0, pac::timer::vals::FilterValue::NO_FILTER);
            });
            regs.ccer().modify(|w| {
                w.set_ccp(0, true);
                w.set_ccnp(0, false);
                w.set_cce(0, true);
            });
            let request =
                embassy_stm32::timer::Dma::<peripherals::TIM3, embassy_stm32::timer::Ch1>::request(
                    &*dma,
                );
            embassy_stm32::timer::Dma::<peripherals::TIM3, embassy_stm32::timer::Ch1>::remap(&*dma);
            let channel = slot.insert(dma::Channel::new(dma, Irqs));
            let mut options = timing_critical();
            options.circular = true;
            // SAFETY: BSRR is a valid 32-bit write-only register of a port that
            // exists forever; the ring lives for 'static and is written afterwards
            // only by `set`, whole frames away from the DMA (its docs).
            let transfer = unsafe {
                channel.write_raw(
                    request,
                    ring as *const [u32],
                    pac::GPIOE.bsrr().as_ptr() as *mut u32,
                    options,
                )
            };
            regs.dier().modify(|w| w.set_ccde(0, true));
            timer.start();
            HeadStatus {
                _timer: timer,
                _transfer: transfer,
                ring: ring as *mut u32,
                _pins: (clk, status),
            }
        }

        /// Plays `frame` from now on without a torn frame: with interrupts off,
        /// rewrites the second half of the ring while the DMA is at least 4 words
        /// away from it in the first, then the first while the DMA is in the
        /// second, so the frames go old..., new... `false`: the head's clock did
        /// not run (the ring unchanged or half changed).
        fn set(&mut self, frame: u32) -> bool {
            let words = frame_words(frame);
            let dma = pac::DMA1.st(HEAD_STREAM);
            // The index of the next word the DMA plays.
            let pos = || HEAD_RING - dma.ndtr().read().ndt() as usize % HEAD_RING;
            cortex_m::interrupt::free(|_| {
                for half in [1, 0] {
                    // The DMA in the other half, >= 4 words (2 us) before this one.
                    let other = (1 - half) * 20;
                    let mut spins = 0u32;
                    while !(other + 2..other + 16).contains(&(pos() % HEAD_RING)) {
                        spins += 1;
                        // An NDTR read takes several core cycles: >= 40 us, well
                        // beyond the 20.5 us the head's clock needs to get here
                        // (a frame period takes 10 or 10.25 us), and < 1 ms with
                        // interrupts off
                        // if it does not run.
                        if spins > 5_000 {
                            return false;
                        }
                    }
                    for (i, w) in words.iter().enumerate() {
                        // SAFETY: the ring has HEAD_RING words; the DMA reads this
                        // half no sooner than 2 us from now (above), and these
                        // writes take well under that.
                        unsafe { self.ring.add(half * 20 + i).write_volatile(*w) };
                    }
                }
                true
            })
        }
    }

    /// The BSRR words of a status frame on PE5, MSB first.
    fn frame_words(frame: u32) -> [u32; 20] {
        core::array::from_fn(|i| {
            if frame >> (19 - i) & 1 == 1 {
                1 << HEAD_STATUS_PIN
            } else {
                1 << (HEAD_STATUS_PIN + 16)
            }
        })
    }

    /// What the head received, checked period by period against the frames sent.
    #[derive(Default, Debug, defmt::Format)]
    struct HeadLog {
        /// The periods decoded, and of them the ones before the input, with a
        /// line failing its check or missing, with a framing fault.
        head: Xy2Periods,
        /// Periods that are neither a frame sent with its checks passing nor park.
        unknown: u32,
        /// The frame numbers received, in order, and the park periods.
        seq: FrameSeq,
    }

    /// The STATUS words towards the controller, in the order they must come:
    /// 0 the bridge's "not yet" words (input lost, head status not yet in),
    /// 1 all OK, 2 the head's alarm, 3 all OK, 4 input lost (the tail).
    #[derive(Default, Debug, defmt::Format)]
    struct CtrlLog {
        /// Frames that failed to decode before the first word (the pin idles low
        /// until the frame phase is known), and after it.
        errors_before: u32,
        errors_after: u32,
        /// Words per stage, the stage reached, words that do not fit.
        stage: usize,
        counts: [u32; 5],
        unexpected: u32,
        /// Frame index (controller frame) of the first word.
        first_at: Option<u32>,
    }

    /// The whole bridge through its own tasks for an XY2-100 controller and an
    /// XY2-100 head with STATUS words on both sides (axis map identity, Z from the
    /// input, free-running at the baked rate: 100 kHz, 40 ticks per frame period, or
    /// 97.56 kHz, 41 ticks, the odd geometry of `head_word`'s thinning, module
    /// docs): `app`'s per-side functions spawn the
    /// supervisor (watchdog, laser gate), LEDs and statistics, `line::xy2_in` with
    /// the STATUS word towards the controller (`ctrl_word`, DMA2 S7 on TIM1 COM,
    /// PA0) and `bridge_wave_out` with the XY2-100 encoder and the head's STATUS
    /// word (`head_word`, TIM8 CC1 samples of PG9), as `app::spawn_bridge` does.
    /// [`BsrrSource`] plays the XY2-100 controller: 30 000 frames at 100 kHz, frame
    /// 12 345 with its X parity bit flipped, then 1000 frames all with it flipped
    /// (the clock runs, the input is lost), then nothing. [`HeadStatus`] plays the
    /// head's STATUS word on its clock: all OK, from 100 ms to 200 ms into the
    /// input a temperature alarm. The read-backs: the controller-side XY2 pins
    /// are the pairing's, so the head's output is read by four receive-only SPI
    /// slaves on the head's CLK (the XY3-100 / HANS-100 lines, free here: SPI1
    /// SYNC, SPI3 X, SPI4 Y, SPI5 Z; CPHA = 1 samples on the falling edge, where
    /// the data is steady, as a head does), the bits put together as port samples
    /// for `shared::xy2::rx::Receiver`; the STATUS towards the controller by SPI2
    /// on the source's CLK, one bit per falling edge as the controller reads it,
    /// bit j of that stream being the word read with the source's bit j (the
    /// source's clock starts with its first frame), through `StatusWordReceiver`
    /// (20 samples per frame, offset 0).
    ///
    /// Checks: the head as in the XY3-100 -> XY2-100 test (no period before the
    /// input; every period decodes and is a frame sent (16 bits both sides) or
    /// park; never back, steps of at most 4, >= 60 % distinct, the first at the
    /// end of the recovery run, the last within 4 of the last good one; the
    /// flipped frames never; park only after the last frame). The STATUS words
    /// towards the controller: the first within 10 ms of the input, none failing
    /// its check after it, in the order "not yet" words (input lost / status
    /// lost), all OK (>= 5000), the head's alarm word (>= 9000 of the 10 000
    /// frames), all OK (>= 5000), input lost (>= 500 of the tail's 1000), nothing
    /// else. The laser gate (PF13 pad): off before the input, on within 10 ms and
    /// without a gap until the head's alarm, off within 5 ms of it and while it
    /// lasts, on within 10 ms of its end and without a gap, off within 6 ms of the
    /// input's end and for good. The head's words as `head_word` judged them: none
    /// failing its check (the bridge's `Line::Status` counters, read from the
    /// snapshot the statistics task asks for), so no word was sampled off its bits
    /// anywhere in the run, not only the ones that reached the controller.
    ///
    /// Jumpers: source PE2 (CLK) -> PE7 and PB10, PE3 (SYNC) -> PG0, PE4 (X) ->
    /// PG1, PE9 (Y) -> PG2, PE10 (Z) -> PG3; STATUS towards the controller PA0 ->
    /// PB15; head PD0 (CLK) -> PA5, PC10, PE12, PF7 and PC6, PD1 (SYNC) -> PB5, PD2
    /// (X) -> PC12, PD3 (Y) -> PE14, PD10 (Z) -> PF9; head STATUS PE5 -> PG9.
    #[test]
    #[timeout(20)]
    async fn bridge_tasks_xy2_word_to_xy2_word_end_to_end(board: Board) {
        // The baked configuration this test is written for: its roles are the
        // image's (`bridge_pairing`), the settings its expectations rest on are
        // checked here.
        let config = config::load().unwrap();
        let roles = Roles::of(&config);
        assert_identity_axes(&config);
        assert_eq!(config.controller.xy2.status, StatusForm::Word);
        assert_eq!(config.head.xy2.status, StatusForm::Word);
        assert_eq!(config.controller.xy2.mode, Mode::Standard16);
        assert_eq!(config.head.xy2.mode, Mode::Standard16);
        assert_eq!(config.output.timing, Timing::FreeRunning);
        // The head's frame period in output ticks, as `tasks/encode.rs` derives it:
        // 40 at 100 kHz (20 STATUS samples a period) or 41 at 97.56 kHz (20 bits
        // and an idle tick: 21 samples, the last of them on the idle tick), the two
        // geometries of `head_word`'s thinning this test is reasoned for (at lower
        // rates free-running would skip more input frames than `FrameSeq` allows).
        let ticks = XY2_TICK_HZ / config.output.frame_rate_hz;
        assert!(
            matches!(ticks, 40 | 41),
            "{} output ticks per frame period",
            ticks
        );
        defmt::info!(
            "head at {} Hz: {} ticks per frame period",
            config.output.frame_rate_hz,
            ticks
        );
        assert_eq!(config.failsafe.after_hold, AfterHold::Park);
        assert_ne!(config.failsafe.status_timeout_us, 0);
        assert!(config.laser.off_on_head_alarm, "laser.off_on_head_alarm");
        let f = config.failsafe;
        let park = [f.park_x, f.park_y, f.park_z].map(|v| (v >> 4) as u16);
        assert!(
            (0..N + TAIL).all(|k| e2e_positions(k) != park),
            "a frame looks parked"
        );
        assert!(
            (0..N + TAIL).all(|k| frame_of_x(e2e_positions(k)[0]) == k),
            "frame_of_x"
        );
        let recovery = f.recovery_frames;
        let link = LinkConfig {
            mode: config.controller.xy2.mode,
            parity: config.controller.xy2.parity,
        };
        let head_link = LinkConfig {
            mode: config.head.xy2.mode,
            parity: config.head.xy2.parity,
        };
        // The flipped bit is the parity bit: the word still carries the frame's X
        // (which would show at the head if it got through), and fails its check.
        let bad_x = Frame2::Position16(e2e_positions(BAD)[0]);
        let bad_word = xy2_encode(bad_x, &link).unwrap() ^ 1;
        assert!(xy2_decode(bad_word, &link).is_err(), "flipped word passes");
        assert_eq!(xy2_decode(bad_word ^ 1, &link), Ok(bad_x));
        // The head's words, and what `ctrl_word` must choose: the bridge's word
        // for the head's alarms and its own (`Bridge::xy2_status_word`), "input
        // lost" while the input is not valid.
        let head_ok = StatusWord::ALL_OK;
        let head_alarm = StatusWord::from_alarms(Alarms::TEMPERATURE);
        assert_ne!(head_ok, head_alarm);
        let lost = StatusWord::from_alarms(Alarms::INPUT_LOST);
        let not_yet = [
            lost,
            StatusWord::from_alarms(Alarms::STATUS_LOST),
            StatusWord::from_alarms(Alarms::INPUT_LOST.union(Alarms::STATUS_LOST)),
        ];
        assert!(
            !not_yet.contains(&head_ok) && !not_yet.contains(&head_alarm),
            "a 'not yet' word looks like the head's"
        );
        let stages: [&[StatusWord]; 5] = [&not_yet, &[head_ok], &[head_alarm], &[head_ok], &[lost]];

        let spawner = unsafe {
            // SAFETY: `embedded-test` (feature `embassy-010`) runs async tests as
            // tasks of embassy's thread-mode executor, so the context is embassy's.
            embassy_executor::Spawner::for_current_executor()
        }
        .await;
        let r = board.res;

        // The controller side's source, idle, on the head backchannel's TX stream
        // (DMA1 S6; no backchannel in this pairing, its RX stream plays the head's
        // STATUS below).
        let tx = Xy2Tx::new(SRC_PINS, SRC_TPF, link).unwrap();
        let mut source = BsrrSource::start(
            r.head_back.tx_dma,
            dma_ring!(".sram1", u32, 2 * SRC_FRAMES * SRC_TPF),
            tx.idle_word(),
            SRC_TICK_HZ,
        );
        let i = r.xy3_in;
        // The STATUS towards the controller, read by SPI2 on the source's CLK
        // (started before the source clocks: bit 0 is the first frame's).
        let mut ctrl_status = SpiSlaveRx::new(
            i.w.spi,
            i.w.sck,
            i.w.mosi,
            None::<Peri<'static, PB12>>,
            i.w.dma,
            Irqs,
            dma_ring!(".sram1", u16, 16 * CHUNK),
        )
        .unwrap();

        // The firmware's tasks for this pairing, spawned as `app::spawn_bridge` does.
        let leds = [board.led_green, board.led_yellow, board.led_red];
        app::spawn_supervision(spawner, board.iwdg, board.laser_gate, leds, false);
        let ex = Executors::start();
        let head_enable = app::head_drivers(r.head_enable, r.head_mux, roles.head);
        app::controller_xy2(
            spawner,
            ex,
            &config,
            r.xy2_in,
            r.ctrl_status,
            r.back.de,
            i.sck_buffer_oe,
        );
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
        // The SCK-bus buffer stays off (an XY2-100 controller) and the pair-6
        // driver on (it carries the STATUS word).
        assert_eq!(
            pf.odr().read().odr(14),
            pac::gpio::vals::Odr::HIGH,
            "SCK-bus buffer (PF14) on"
        );
        assert_eq!(
            pf.odr().read().odr(8),
            pac::gpio::vals::Odr::HIGH,
            "pair-6 driver (PF8) off"
        );
        // The head's output read back now that its lines idle (CLK low): nothing
        // has clocked the SPIs yet, so bit 0 of each is the first frame's.
        let mut head_lines = (
            SpiSlaveRx::new(
                i.u.spi,
                i.u.sck,
                i.u.mosi,
                None::<Peri<'static, PG10>>,
                i.u.dma,
                Irqs,
                dma_ring!(".sram1", u16, 16 * CHUNK),
            )
            .unwrap(),
            SpiSlaveRx::new(
                i.x.spi,
                i.x.sck,
                i.x.mosi,
                None::<Peri<'static, PA15>>,
                i.x.dma,
                Irqs,
                dma_ring!(".sram1", u16, 16 * CHUNK),
            )
            .unwrap(),
            SpiSlaveRx::new(
                i.y.spi,
                i.y.sck,
                i.y.mosi,
                None::<Peri<'static, PE11>>,
                i.y.dma,
                Irqs,
                dma_ring!(".sram1", u16, 16 * CHUNK),
            )
            .unwrap(),
            SpiSlaveRx::new(
                i.z.spi,
                i.z.sck,
                i.z.mosi,
                None::<Peri<'static, PF6>>,
                i.z.dma,
                Irqs,
                dma_ring!(".sram1", u16, 16 * CHUNK),
            )
            .unwrap(),
        );
        // The test head's STATUS, all OK, on the head's clock.
        let head_slot = static_slot();
        let mut head_status = HeadStatus::start(
            r.fs.tim,
            r.fs.ctrl,
            r.head_back.rx_dma,
            head_slot,
            head_ok.to_frame(&head_link),
        );
        let mut rx = Xy2Receiver::new(HEAD_XY2_PINS, head_link).unwrap();

        // Phases: 0 before the input, 1 while good frames are written (head OK),
        // 2 the head's alarm, 3 head OK again, 4 from the tail on (`stop_at`: once
        // the last frame played), 5 done.
        let phase = Cell::new(0u8);
        let input_at = Cell::new(Instant::now());
        let alarm_at = Cell::new(Instant::now());
        let clear_at = Cell::new(Instant::now());
        let tail_at = Cell::new(Instant::now());
        let stop_at: Cell<Option<Instant>> = Cell::new(None);
        let underrun = Cell::new(false);

        let source_run = async {
            embassy_time::Timer::after_millis(30).await;
            let mut half = [0u32; SRC_FRAMES * SRC_TPF];
            for h in 0..(N + TAIL) / SRC_FRAMES as u32 {
                for (f, slot) in half.chunks_exact_mut(SRC_TPF).enumerate() {
                    let k = h * SRC_FRAMES as u32 + f as u32;
                    let [x, y, z] =
                        e2e_positions(k).map(|v| xy2_encode(Frame2::Position16(v), &link).unwrap());
                    let x = if k == BAD || k >= N { x ^ 1 } else { x };
                    tx.write_words(slot, [x, y, z]).unwrap();
                }
                if !source.write(&half).await {
                    underrun.set(true);
                }
                if h == 0 {
                    input_at.set(Instant::now());
                    phase.set(1);
                }
                if h == N / SRC_FRAMES as u32 {
                    tail_at.set(Instant::now());
                    phase.set(4);
                }
            }
            if !source.finish(&mut half, tx.idle_word()).await {
                underrun.set(true);
            }
            stop_at.set(Some(Instant::now()));
            embassy_time::Timer::after_millis(300).await;
            phase.set(5);
        };

        // The head's alarm, 100 ms into the input for 100 ms.
        let switched = Cell::new([false; 2]);
        let head_run = async {
            while phase.get() < 1 {
                embassy_time::Timer::after_millis(1).await;
            }
            let mut done = [false; 2];
            embassy_time::Timer::at(input_at.get() + Duration::from_millis(ALARM_FROM_MS)).await;
            done[0] = head_status.set(head_alarm.to_frame(&head_link));
            alarm_at.set(Instant::now());
            phase.set(2);
            embassy_time::Timer::at(input_at.get() + Duration::from_millis(ALARM_TO_MS)).await;
            done[1] = head_status.set(head_ok.to_frame(&head_link));
            clear_at.set(Instant::now());
            phase.set(3);
            switched.set(done);
        };

        // The gate every 100 us, per phase (set by the source and the test head).
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
                    4 => tail_at.get().elapsed(),
                    _ => break,
                };
                gate.sample(p, g, since);
                embassy_time::Timer::after_micros(100).await;
            }
        };

        // The STATUS words towards the controller, one bit per source falling edge.
        let mut ctrl = CtrlLog::default();
        let mut ctrl_overrun = false;
        let ctrl_reader = async {
            let mut srx = StatusWordReceiver::new(StatusWordConfig {
                pin: 0,
                samples_per_period: 20,
                offset: 0,
                link,
            })
            .unwrap();
            let mut words = [0u16; CHUNK];
            let mut bits = [0u16; 16 * CHUNK];
            let mut frame = 0u32;
            loop {
                let read = select(ctrl_status.read_exact(&mut words), async {
                    while phase.get() < 5 {
                        embassy_time::Timer::after_millis(1).await;
                    }
                })
                .await;
                match read {
                    Either::First(Ok(())) => {}
                    Either::First(Err(_)) => {
                        ctrl_overrun = true;
                        return;
                    }
                    Either::Second(()) => return,
                }
                for (w, b) in words.iter().zip(bits.chunks_exact_mut(16)) {
                    for (j, s) in b.iter_mut().enumerate() {
                        *s = w >> (15 - j) & 1;
                    }
                }
                srx.feed(&bits, &mut |r| {
                    let k = frame;
                    frame += 1;
                    let Ok(w) = r else {
                        if ctrl.first_at.is_some() {
                            ctrl.errors_after += 1;
                        } else {
                            ctrl.errors_before += 1;
                        }
                        return;
                    };
                    ctrl.first_at.get_or_insert(k);
                    let s = ctrl.stage;
                    if stages[s].contains(&w) {
                        ctrl.counts[s] += 1;
                    } else if s + 1 < stages.len() && stages[s + 1].contains(&w) {
                        ctrl.stage = s + 1;
                        ctrl.counts[s + 1] += 1;
                    } else {
                        ctrl.unexpected += 1;
                    }
                });
            }
        };

        // The head's output: the four lines' bits as port samples, period by period.
        let mut log = HeadLog::default();
        let mut head_overrun = false;
        let head_reader = async {
            let mut words = [[0u16; CHUNK]; 4];
            let mut samples = [0u16; 16 * CHUNK];
            let (sync, x, y, z) = &mut head_lines;
            while phase.get() < 5 {
                let [ws, wx, wy, wz] = &mut words;
                let reads = [
                    sync.read_exact(ws).await,
                    x.read_exact(wx).await,
                    y.read_exact(wy).await,
                    z.read_exact(wz).await,
                ];
                if reads.iter().any(Result::is_err) {
                    head_overrun = true;
                    return;
                }
                for (n, s) in samples.iter_mut().enumerate() {
                    let (w, j) = (n / 16, 15 - n % 16);
                    *s = words
                        .iter()
                        .enumerate()
                        .fold(0, |acc, (l, line)| acc | (line[w] >> j & 1) << l);
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
        let deadline = phase_end(&phase, 5, Duration::from_millis(50));
        let head_reader =
            async { matches!(select(head_reader, deadline).await, Either::First(())) };
        let (_, _, _, _, read_to_the_end) = embassy_futures::join::join5(
            source_run,
            head_run,
            gate_sampler,
            ctrl_reader,
            head_reader,
        )
        .await;
        drop(source);
        // The bridge still runs (parking): its counters cover the whole run.
        let status_faults = bridge_snapshot().await.counters.line(Line::Status);
        defmt::info!("head: {}", log);
        defmt::info!("controller STATUS: {}", ctrl);
        defmt::info!("gate: {}", gate);
        defmt::info!("head STATUS faults in the bridge: {}", status_faults);

        assert!(
            !underrun.get(),
            "the source's DMA ran out of words (test bench too slow)"
        );
        assert!(
            !head_overrun && !ctrl_overrun,
            "a read-back ring ran over (test bench too slow)"
        );
        assert!(
            read_to_the_end,
            "the head's output stopped (or never started)"
        );
        assert_eq!(
            switched.get(),
            [true; 2],
            "the head's clock did not run at a status switch"
        );
        // The head: nothing before the input, then what it got, in order, never a
        // frame that failed its check.
        log.head.check();
        assert_eq!(log.unknown, 0, "head periods that are no good frame sent");
        log.seq.check(N, recovery);
        // The head's words as `head_word` thinned and decoded them: every one of a
        // period that carried a frame passed its check.
        assert_eq!(
            status_faults.total(),
            0,
            "head STATUS words failing their check in head_word"
        );
        // The STATUS words towards the controller: `ctrl_word`'s choice for the
        // head's words and the input, in order, none broken once the phase is in.
        let first_word = ctrl
            .first_at
            .expect("no STATUS word towards the controller");
        assert!(
            first_word < 1000,
            "first STATUS word at frame {}",
            first_word
        );
        assert_eq!(ctrl.errors_after, 0, "STATUS words failing their check");
        assert_eq!(ctrl.unexpected, 0, "STATUS words out of order or unknown");
        assert_eq!(
            ctrl.stage, 4,
            "STATUS words stopped at stage {}",
            ctrl.stage
        );
        let [_, ok, alarm, ok_again, tail] = ctrl.counts;
        assert!(ok >= 5_000, "{} OK words before the alarm", ok);
        assert!(alarm >= 9_000, "{} alarm words", alarm);
        assert!(ok_again >= 5_000, "{} OK words after the alarm", ok_again);
        assert!(tail >= 500, "{} input-lost words in the tail", tail);
        // The laser gate.
        gate.check(500, 1000);
        assert!(!laser_gate_high(), "gate on at the end");
    }

    /// The bridge's snapshot (its counters), asked for as the statistics task asks
    /// for it. The statistics task asks once a second too and may take an answer
    /// first (or reset it): then ask again, every millisecond for up to 100 ms
    /// (the bridge answers after its current batch, ~0.25 ms). `try_take`, not
    /// `wait`: two tasks waiting on one `Signal` would wake each other in turn.
    async fn bridge_snapshot() -> BridgeSnapshot {
        for _ in 0..100 {
            SNAPSHOT_WANTED.store(true, Ordering::Relaxed);
            embassy_time::Timer::after_millis(1).await;
            if let Some(s) = BRIDGE_SNAPSHOT.try_take() {
                return s;
            }
        }
        panic!("the bridge gave no snapshot in 100 ms")
    }

    /// The slot that keeps the test head's DMA channel for the whole test.
    fn static_slot() -> &'static mut Option<dma::Channel<'static>> {
        static SLOT: static_cell::StaticCell<Option<dma::Channel<'static>>> =
            static_cell::StaticCell::new();
        SLOT.init(None)
    }
}
