//! Hardware-in-the-loop self-tests (issue 6): every head-side output is looped back to
//! a controller-side input with jumper wires on one NUCLEO-H743ZI2, and the real
//! drivers send and receive through them. Wiring and how to run: README.md (section "Firmware"),
//! "Hardware-in-the-loop self-tests". `embedded-test` runs each test after a reset, so
//! every test starts from a fresh `board::init`.
#![no_std]
#![no_main]

use defmt_rtt as _;

/// A small deterministic bit source for test patterns (xorshift32).
struct Prng(u32);

impl Prng {
    fn bit(&mut self) -> bool {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        self.0 & 1 == 1
    }
}

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use embassy_stm32::gpio::{
        AfType, AnyPin, Flex, Input, Level, Output, OutputType, Pull, Speed,
    };
    use embassy_stm32::mode::Async;
    use embassy_stm32::pac::timer::vals::FilterValue;
    use embassy_stm32::peripherals::PA15;
    use embassy_stm32::peripherals::PG8;
    use embassy_stm32::timer::low_level::{InputCaptureMode, InputTISelection, Timer};
    use embassy_stm32::timer::{self, Ch1, Ch4, Channel as TimChannel, TimerPin, UpDma};
    use embassy_stm32::usart::{RingBufferedUartRx, Uart, UartTx};
    use embassy_stm32::{dma, pac, peripherals, Peri};
    use embassy_time::{with_timeout, Duration};
    use shared::hans::frame::{write_slot, Frame, RING_BYTES};
    use shared::hans::rx::{HansRx, Mode as HansMode, RxEvent};
    use shared::hans::tx::Transmitter;
    use shared::head_port;
    use shared::model::Alarms;
    use shared::model::FaultKind;
    use shared::xy2;
    use shared::xy2::rx::{Event as Xy2Event, PinMap, Receiver as Xy2Receiver};
    use shared::xy2::status_line::{StatusOut as WordOut, StatusWordConfig, StatusWordReceiver};
    use shared::xy2::tx::Transmitter as Xy2Tx;
    use shared::xy2::{
        decode as xy2_decode, encode as xy2_encode, Frame as Frame2, Health, LinkConfig, Mode,
        Parity, StatusError, StatusLevel, StatusWord,
    };
    use shared::xy3;
    use shared::xy3::back::{Event, Packet, Parser, Sender, SEND_BUF_LEN};
    use shared::xy3::{Frame as Frame3, FrameSize};
    use xy_bridge::board::HANS_FS_HZ;
    use xy_bridge::board::{self, Board};
    use xy_bridge::drivers::backchannel;
    use xy_bridge::drivers::hans_lines::HansInput;
    use xy_bridge::drivers::oversample_clock;
    use xy_bridge::drivers::serial_tx::SerialTx;
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    use xy_bridge::drivers::status_level::{StatusIn, StatusOut};
    use xy_bridge::drivers::status_word_out::{StatusWordOut, FRAME_BITS};
    use xy_bridge::drivers::sync_marks::SyncMarks;
    use xy_bridge::drivers::wave_out::{timing_critical, WaveOut};
    use xy_bridge::drivers::xy2_sampler::Xy2Sampler;
    use xy_bridge::tasks::Irqs;
    use xy_bridge::{dma_ring, hans_rings};

    use super::Prng;

    /// Head-side port-D bits used here: pair 1, 2, 3.
    const P1: u32 = 0;
    const P2: u32 = 1;
    const P3: u32 = 2;
    const P4: u32 = 3;
    /// Every output low.
    const ALL_LOW: u32 = (1 << (P1 + 16)) | (1 << (P2 + 16)) | (1 << (P3 + 16));
    /// A timeout long enough for a few DMA halves.
    const WAIT: Duration = Duration::from_millis(200);

    fn level(bit: u32, high: bool) -> u32 {
        if high {
            1 << bit
        } else {
            1 << (bit + 16)
        }
    }

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// XY2-100 out -> XY2-100 in. Jumpers: PD0 (CLK) -> PE7, PD1 (SYNC) -> PG0,
    /// PD2 (X) -> PG1. 512 bits with XY2 SYNC timing and random X go out through
    /// `WaveOut`; `Xy2Sampler` must return exactly those bits, one per CLK falling
    /// edge, and the CC1 status sampler must see the X levels on port G too.
    #[test]
    async fn xy2_waveform_loopback(board: Board) {
        const BITS: usize = 512;
        let r = board.res;
        let w = r.wave;
        let _p1 = Output::new(w.pins.p1, Level::Low, Speed::VeryHigh);
        let _p2 = Output::new(w.pins.p2, Level::Low, Speed::VeryHigh);
        let _p3 = Output::new(w.pins.p3, Level::Low, Speed::VeryHigh);
        let in_ring = dma_ring!(".sram2", u16, 2 * BITS);
        let x = r.xy2_in;
        // SYNC, X, Y, Z out of their analog reset state (as `line::xy2_in`).
        let _data = x.data.inputs();
        let mut sampler = Xy2Sampler::new(x.tim, x.clk, x.dma, Irqs, pac::GPIOG, in_ring);
        let ring = dma_ring!(".sram2", u32, 4 * BITS);
        let mut out =
            WaveOut::new(w.tim, w.dma, Irqs, pac::GPIOD, ring, ALL_LOW, 4_000_000).unwrap();
        let status_ring = dma_ring!(".sram2", u16, 8 * BITS);
        out.start_status_sampler(w.status_dma, Irqs, pac::GPIOG, status_ring)
            .unwrap();
        out.start();

        let mut prng = Prng(0x1234_5678);
        let mut x_bits = [false; BITS];
        let mut half = [0u32; 2 * BITS];
        for (i, pair) in half.chunks_exact_mut(2).enumerate() {
            let x = prng.bit();
            x_bits[i] = x;
            let data = level(P2, i % 20 != 19) | level(P3, x);
            pair[0] = data | level(P1, true);
            pair[1] = data | level(P1, false);
        }
        out.write_half(&half).await.unwrap();

        let mut got = [0u16; BITS];
        with_timeout(WAIT, sampler.read_exact(&mut got))
            .await
            .unwrap()
            .unwrap();
        for (i, s) in got.iter().enumerate() {
            assert_eq!(s & 1 == 1, i % 20 != 19, "SYNC at bit {}", i);
            assert_eq!(s >> 1 & 1 == 1, x_bits[i], "X at bit {}", i);
        }

        // Status samples, one per tick, aligned to the first word written: sample 2i
        // (bit i's CLK-high tick) must carry bit i's X level, from the first one on.
        embassy_time::Timer::after_micros(20).await;
        let mut samples = [0u16; 8 * BITS];
        let read = out.read_status(&mut samples).unwrap();
        assert!(!read.restart, "realigned without an underrun");
        assert!(read.samples >= 2 * BITS, "{} status samples", read.samples);
        for (i, s) in samples[..2 * BITS].iter().step_by(2).enumerate() {
            assert_eq!(s >> 1 & 1 == 1, x_bits[i], "status sample {}", 2 * i);
        }
    }

    /// One sample per bit of per-tick status samples (the CLK-high ticks, even ticks
    /// counted from `tick`), as `tasks/head_word.rs` takes them for an even number of
    /// ticks per frame, fed to `rx`.
    fn per_bit(
        samples: &[u16],
        tick: &mut usize,
        rx: &mut StatusWordReceiver,
        sink: &mut impl FnMut(Result<StatusWord, StatusError>),
    ) {
        for &s in samples {
            if tick.is_multiple_of(2) {
                rx.feed(&[s], sink);
            }
            *tick += 1;
        }
    }

    /// Slaved output (README "Slaved timing"): frame slots and idle slots (clock
    /// stopped, every line low) mixed at random, as the bridge loop writes them when
    /// the input leaves slots empty. Jumpers as `xy2_waveform_loopback`. The
    /// TIM1 sampler takes a sample per CLK falling edge, so an idle slot must add no
    /// sample: what comes back is exactly the frames' bits back to back, with
    /// their SYNC pattern and X words (the gaps invisible to our receiver).
    #[test]
    async fn xy2_slaved_idle_slots_loopback(board: Board) {
        use shared::xy2::tx::{Transmitter, TxFrame};
        use shared::xy2::{encode, Frame as Frame2};
        const TICKS: usize = 40;
        const SLOTS: usize = 25;
        let r = board.res;
        let w = r.wave;
        let _p1 = Output::new(w.pins.p1, Level::Low, Speed::VeryHigh);
        let _p2 = Output::new(w.pins.p2, Level::Low, Speed::VeryHigh);
        let _p3 = Output::new(w.pins.p3, Level::Low, Speed::VeryHigh);
        let in_ring = dma_ring!(".sram2", u16, 2 * 20 * SLOTS);
        let x = r.xy2_in;
        // SYNC, X, Y, Z out of their analog reset state (as `line::xy2_in`).
        let _data = x.data.inputs();
        let mut sampler = Xy2Sampler::new(x.tim, x.clk, x.dma, Irqs, pac::GPIOG, in_ring);
        let ring = dma_ring!(".sram2", u32, 2 * TICKS * SLOTS);
        let mut out =
            WaveOut::new(w.tim, w.dma, Irqs, pac::GPIOD, ring, ALL_LOW, 4_000_000).unwrap();
        let link = LinkConfig::default();
        let tx = Transmitter::new(head_port::xy2_pins(false), TICKS, link).unwrap();
        out.start();

        let mut prng = Prng(0x0BAD_CAFE);
        let mut half = [0u32; TICKS * SLOTS];
        let mut sent: heapless::Vec<u32, SLOTS> = heapless::Vec::new();
        for (i, slot) in half.chunks_exact_mut(TICKS).enumerate() {
            // Slot 0 always carries a frame, then about half of the slots do.
            if i > 0 && prng.bit() {
                slot.fill(tx.idle_word());
                continue;
            }
            let v = (i as u16).wrapping_mul(2_459) ^ 0x5A5A;
            let f = Frame2::Position16(v);
            tx.write_frame(
                slot,
                &TxFrame {
                    x: f,
                    y: f,
                    z: None,
                },
            )
            .unwrap();
            sent.push(encode(f, &link).unwrap()).unwrap();
        }
        out.write_half(&half).await.unwrap();

        let mut got = [0u16; 20 * SLOTS];
        let got = &mut got[..20 * sent.len()];
        with_timeout(WAIT, sampler.read_exact(got))
            .await
            .unwrap()
            .unwrap();
        for (k, (frame, word)) in got.chunks_exact(20).zip(&sent).enumerate() {
            for (b, s) in frame.iter().enumerate() {
                assert_eq!(s & 1 == 1, b != 19, "SYNC, frame {} bit {}", k, b);
                let x = word >> (19 - b) & 1 == 1;
                assert_eq!(s >> 1 & 1 == 1, x, "X, frame {} bit {}", k, b);
            }
        }
    }

    /// Ticks per frame slot (XY2-100 at 100 kHz on the 4 MHz tick) and slots per
    /// batch of the XY2-100 STATUS word tests.
    const TPF: usize = 40;
    const FRAMES: usize = 25;

    /// What the XY2-100 STATUS word tests run on (jumper PD3 -> PG9): `WaveOut` on
    /// TIM8 plays CLK on PD0 and a head's STATUS line on PD3, its CC1 sampler takes
    /// port G once per tick; the link, and the firmware's receiver geometry (20
    /// samples per 40-tick frame, offset 1).
    struct StatusWordBench {
        out: WaveOut<'static, peripherals::TIM8>,
        link: LinkConfig,
        geometry: StatusWordConfig,
        /// CLK and STATUS out, STATUS in: configured while the bench lives.
        _pins: (Output<'static>, Output<'static>, Input<'static>),
    }

    impl StatusWordBench {
        /// Configures the pins and starts the output with its status sampler (once
        /// per test: the rings are `dma_ring!`s).
        fn start(board: Board) -> Self {
            let r = board.res;
            let w = r.wave;
            let clk = Output::new(w.pins.p1, Level::Low, Speed::VeryHigh);
            let status = Output::new(w.pins.p4, Level::Low, Speed::VeryHigh);
            let status_in = Input::new(r.head_status, Pull::None);
            let ring = dma_ring!(".sram2", u32, 2 * FRAMES * TPF);
            let mut out =
                WaveOut::new(w.tim, w.dma, Irqs, pac::GPIOD, ring, ALL_LOW, 4_000_000).unwrap();
            let status_ring = dma_ring!(".sram2", u16, 4 * FRAMES * TPF);
            out.start_status_sampler(w.status_dma, Irqs, pac::GPIOG, status_ring)
                .unwrap();
            out.start();
            let link = LinkConfig {
                mode: Mode::Standard16,
                parity: Parity::WholeFrame,
            };
            let geometry = StatusWordConfig {
                pin: 9,
                samples_per_period: (TPF / 2) as u16,
                offset: 1,
                link,
            };
            StatusWordBench {
                out,
                link,
                geometry,
                _pins: (clk, status, status_in),
            }
        }
    }

    /// Fills `batch` ([`FRAMES`] slots) with frames `first..`: a CLK pulse on P1 per
    /// bit and the head's STATUS frame `frame(k)` on P4, each bit set at a CLK
    /// falling edge; `None` is an idle slot (no clock, STATUS low).
    fn status_word_batch(batch: &mut [u32], first: usize, frame: impl Fn(usize) -> Option<u32>) {
        for (f, slot) in batch.chunks_exact_mut(TPF).enumerate() {
            let bits = frame(first + f);
            for (i, pair) in slot.chunks_exact_mut(2).enumerate() {
                pair[0] = level(P1, bits.is_some());
                let status = bits.map_or(0, |v| level(P4, v >> (19 - i) & 1 == 1));
                pair[1] = level(P1, false) | status;
            }
        }
    }

    /// XY2-100 STATUS word, head side. Jumper: PD3 -> PG9 (the head's STATUS input).
    /// PD3 plays a head that shifts a status frame out on our clock, changing its
    /// line on every CLK falling edge (PD0, no jumper needed); the TIM8 CC1 sampler's
    /// aligned samples must give back every frame through `shared`'s
    /// `StatusWordReceiver` at the firmware's geometry (20 samples per 40-tick frame,
    /// offset 1), and the one frame sent with a flipped parity bit must be refused.
    #[test]
    async fn xy2_status_word_loopback(board: Board) {
        const BATCHES: usize = 4;
        const BAD: usize = 37;
        let StatusWordBench {
            mut out,
            link,
            geometry,
            _pins,
        } = StatusWordBench::start(board);
        let mut rx = StatusWordReceiver::new(geometry).unwrap();
        let word = |k: usize| StatusWord::from_alarms(Alarms((k as u32).wrapping_mul(7) & 0xF));
        let frame = |k: usize| word(k).to_frame(&link) ^ u32::from(k == BAD);
        let mut got: heapless::Vec<Result<StatusWord, StatusError>, 160> = heapless::Vec::new();
        let mut batch = [0u32; FRAMES * TPF];
        let mut samples = [0u16; 4 * FRAMES * TPF];
        let mut tick = 0;
        // One batch more than the frames: its idle slots (no clock, STATUS held) let
        // the last frame's last bit be sampled.
        for b in 0..=BATCHES {
            status_word_batch(&mut batch, b * FRAMES, |k| {
                (k < BATCHES * FRAMES).then(|| frame(k))
            });
            out.write_half(&batch).await.unwrap();
            let read = out.read_status(&mut samples).unwrap();
            assert!(!read.restart, "realigned without an underrun");
            per_bit(&samples[..read.samples], &mut tick, &mut rx, &mut |r| {
                let _ = got.push(r);
            });
        }
        embassy_time::Timer::after_micros(300).await;
        let read = out.read_status(&mut samples).unwrap();
        per_bit(&samples[..read.samples], &mut tick, &mut rx, &mut |r| {
            let _ = got.push(r);
        });
        assert!(got.len() >= BATCHES * FRAMES, "{} words", got.len());
        for (k, r) in got[..BATCHES * FRAMES].iter().enumerate() {
            if k == BAD {
                assert!(r.is_err(), "frame {} with a flipped bit passed", k);
            } else {
                assert_eq!(*r, Ok(word(k)), "frame {}", k);
            }
        }
    }

    /// XY2-100 head status word after a forced output underrun: as
    /// `xy2_status_word_loopback` (jumper PD3 -> PG9), but after two batches (whose
    /// frames must come back) the writer stops for 2 ms, so the DMA replays stale
    /// words and the status ring overruns too. `write_half` must report the underrun (that batch is dropped), the next
    /// `read_status` a restart (and no restart ever before), and from there the
    /// status frames of every batch written after the underrun must come back in
    /// order through a fresh `StatusWordReceiver` (the bridge's `StatusWordIn` does
    /// the same at the period of its next slot); the one with a flipped parity bit
    /// is refused. The frames before the underrun must have come back too.
    #[test]
    async fn xy2_status_realign_after_underrun(board: Board) {
        const BATCHES: usize = 8;
        const STALL_BEFORE: usize = 2;
        const BAD: usize = 5 * FRAMES + 7;
        let StatusWordBench {
            mut out,
            link,
            geometry,
            _pins,
        } = StatusWordBench::start(board);
        let mut rx = StatusWordReceiver::new(geometry).unwrap();
        let word = |k: usize| StatusWord::from_alarms(Alarms((k as u32).wrapping_mul(5) & 0xF));
        let frame = |k: usize| word(k).to_frame(&link) ^ u32::from(k == BAD);
        let mut before: heapless::Vec<Result<StatusWord, StatusError>, 160> = heapless::Vec::new();
        let mut after: heapless::Vec<Result<StatusWord, StatusError>, 160> = heapless::Vec::new();
        let mut restarted = false;
        let mut underruns = 0;
        let mut batch = [0u32; FRAMES * TPF];
        let mut samples = [0u16; 4 * FRAMES * TPF];
        let mut tick = 0;
        for b in 0..=BATCHES {
            status_word_batch(&mut batch, b * FRAMES, |k| (b < BATCHES).then(|| frame(k)));
            if b == STALL_BEFORE {
                // Let the written batches play and read their words (the status ring
                // holds 1 ms), then stall long enough for both rings to run over.
                embassy_time::Timer::after_micros(600).await;
                let read = out.read_status(&mut samples).unwrap();
                assert!(!read.restart, "realigned before the underrun");
                per_bit(&samples[..read.samples], &mut tick, &mut rx, &mut |r| {
                    let _ = before.push(r);
                });
                embassy_time::Timer::after_millis(2).await;
            }
            match out.write_half(&batch).await {
                Ok(()) => {}
                Err(e) => {
                    assert_eq!(b, STALL_BEFORE, "unexpected {} at batch {}", e, b);
                    underruns += 1;
                }
            }
            let read = out.read_status(&mut samples).unwrap();
            if read.restart {
                assert!(!restarted && underruns == 1, "restart at batch {}", b);
                restarted = true;
                rx = StatusWordReceiver::new(geometry).unwrap();
                tick = 0;
            }
            let sink = if restarted { &mut after } else { &mut before };
            per_bit(&samples[..read.samples], &mut tick, &mut rx, &mut |r| {
                let _ = sink.push(r);
            });
        }
        embassy_time::Timer::after_micros(300).await;
        let read = out.read_status(&mut samples).unwrap();
        assert!(!read.restart);
        per_bit(&samples[..read.samples], &mut tick, &mut rx, &mut |r| {
            let _ = after.push(r);
        });
        assert_eq!(underruns, 1, "the stall caused no underrun");
        assert!(restarted, "no realignment after the underrun");
        // Batch STALL_BEFORE was dropped; the frames of the batches before it came
        // back (the last one's last bit is sampled from the replayed ring, which may
        // end it differently).
        let played = STALL_BEFORE * FRAMES - 1;
        assert!(before.len() >= played, "{} words before", before.len());
        for (k, r) in before[..played].iter().enumerate() {
            assert_eq!(*r, Ok(word(k)), "frame {} before the underrun", k);
        }
        let first = (STALL_BEFORE + 1) * FRAMES;
        let expected = (BATCHES - STALL_BEFORE - 1) * FRAMES;
        assert!(
            after.len() >= expected,
            "{} words after the underrun",
            after.len()
        );
        for (i, r) in after[..expected].iter().enumerate() {
            let k = first + i;
            if k == BAD {
                assert!(r.is_err(), "frame {} with a flipped bit passed", k);
            } else {
                assert_eq!(*r, Ok(word(k)), "frame {} after the underrun", k);
            }
        }
    }

    /// The firmware's XY2 head geometry: its pins (`shared::head_port`: CLK PD0,
    /// SYNC PD1, X PD2, Y PD3; no Z), 40 ticks per frame at 4 MHz, 16-bit
    /// whole-frame parity.
    fn xy2_head_tx() -> (Xy2Tx, LinkConfig) {
        let link = LinkConfig {
            mode: Mode::Standard16,
            parity: Parity::WholeFrame,
        };
        (
            Xy2Tx::new(head_port::xy2_pins(false), 40, link).unwrap(),
            link,
        )
    }

    /// Position of frame `k` on axis `axis` (any 16-bit value will do).
    fn xy2_position(k: usize, axis: u16) -> u16 {
        (k as u16)
            .wrapping_mul(2654)
            .wrapping_add(axis.wrapping_mul(40503))
    }

    /// Fills `batch` (whole 40-tick slots) with frames `first..` from [`xy2_head_tx`];
    /// frame `bad` gets bit 7 of its X word flipped on the wire.
    fn xy2_batch(tx: &Xy2Tx, link: &LinkConfig, batch: &mut [u32], first: usize, bad: usize) {
        for (f, slot) in batch.chunks_exact_mut(tx.ticks_per_frame()).enumerate() {
            let k = first + f;
            let x = xy2_encode(Frame2::Position16(xy2_position(k, 0)), link).unwrap();
            let y = xy2_encode(Frame2::Position16(xy2_position(k, 1)), link).unwrap();
            let x = x ^ (u32::from(k == bad) << 7);
            tx.write_words(slot, [x, y, 0]).unwrap();
        }
    }

    /// XY2-100 frames end to end, driver to driver (through the bridge tasks:
    /// `bridge_tasks_xy2_to_xy3_end_to_end`): `shared::xy2::tx` encodes 100 frame
    /// periods at the firmware's head geometry ([`xy2_head_tx`]), `WaveOut` plays
    /// them (TIM8 -> GPIOD BSRR),
    /// `Xy2Sampler` takes port G on every CLK falling edge (TIM1 ETR -> DMA2 S0) and
    /// `shared::xy2::rx::Receiver` with the firmware's controller pin map (SYNC PG0,
    /// X PG1, Y PG2) must give back every frame in order; the period whose X word has
    /// a flipped bit must be an X check failure with no frame. Jumpers: PD0 -> PE7,
    /// PD1 -> PG0, PD2 -> PG1, PD3 -> PG2.
    #[test]
    async fn xy2_frames_loopback(board: Board) {
        const FRAMES: usize = 25;
        const BATCHES: usize = 4;
        const BAD: usize = 61;
        const HALF: usize = 500;
        let r = board.res;
        let w = r.wave;
        let _pins = [
            Output::new(w.pins.p1, Level::Low, Speed::VeryHigh),
            Output::new(w.pins.p2, Level::Low, Speed::VeryHigh),
            Output::new(w.pins.p3, Level::Low, Speed::VeryHigh),
            Output::new(w.pins.p4, Level::Low, Speed::VeryHigh),
        ];
        let (tx, link) = xy2_head_tx();
        let x = r.xy2_in;
        // SYNC, X, Y, Z out of their analog reset state (as `line::xy2_in`).
        let _data = x.data.inputs();
        let in_ring = dma_ring!(".sram2", u16, 2 * HALF);
        let mut sampler = Xy2Sampler::new(x.tim, x.clk, x.dma, Irqs, pac::GPIOG, in_ring);
        let ring = dma_ring!(".sram2", u32, 2 * 1000);
        let mut out = WaveOut::new(
            w.tim,
            w.dma,
            Irqs,
            pac::GPIOD,
            ring,
            tx.idle_word(),
            4_000_000,
        )
        .unwrap();
        out.start();

        let pins = PinMap {
            sync: 0,
            x: 1,
            y: 2,
            z: None,
        };
        let mut rx = Xy2Receiver::new(pins, link).unwrap();
        // The line idled low before the first edge (the sampler has no sample of
        // that): without it the receiver would drop the first frame as partial.
        rx.feed(&[0], &mut |_| {});
        let writer = async {
            let mut batch = [0u32; FRAMES * 40];
            for b in 0..BATCHES {
                xy2_batch(&tx, &link, &mut batch, b * FRAMES, BAD);
                out.write_half(&batch).await.unwrap();
            }
            // Idle afterwards: no more clock edges.
            batch.fill(tx.idle_word());
            out.write_half(&batch).await.unwrap();
        };
        let mut periods: heapless::Vec<Xy2Event, 128> = heapless::Vec::new();
        let reader = async {
            let mut half = [0u16; HALF];
            // 100 frames of 20 bits = 4 halves of 500 samples.
            for _ in 0..BATCHES * FRAMES * 20 / HALF {
                with_timeout(WAIT, sampler.read_exact(&mut half))
                    .await
                    .unwrap()
                    .unwrap();
                rx.feed(&half, &mut |e| {
                    let _ = periods.push(e);
                });
            }
        };
        embassy_futures::join::join(writer, reader).await;
        assert_eq!(
            periods.len(),
            BATCHES * FRAMES,
            "{} frame periods",
            periods.len()
        );
        for (k, e) in periods.iter().enumerate() {
            let Xy2Event::Frame(p) = e else {
                panic!("period {}: {:?}", k, e);
            };
            let y = Frame2::Position16(xy2_position(k, 1));
            assert_eq!(p.y, Ok(y), "Y of frame {}", k);
            if k == BAD {
                assert!(p.x.is_err(), "X of frame {} with a flipped bit passed", k);
            } else {
                let x = Frame2::Position16(xy2_position(k, 0));
                assert_eq!(p.x, Ok(x), "X of frame {}", k);
            }
        }
    }

    /// XY2-100 STATUS word towards the controller: `StatusWordOut` on the sampler's
    /// CLK edges (TIM1 COM request -> DMA2 S7 -> GPIOA BSRR) drives PA0, and the
    /// sampler's own port-G samples read it back on PG9 at every falling edge, where
    /// a controller reads STATUS (DMA2 serves S0 before S7 on the same edge, so the
    /// sample shows the word of the edge before). The head side plays back-to-back
    /// frames ([`xy2_head_tx`]). After `refresh` found the frame phase, every status
    /// frame (the 20 samples of the next controller frame's bits, `shared`'s
    /// `StatusWordReceiver` with 20 samples per period, offset 0) must be word A, and
    /// after the switch word B: at least 100 of each, in that order, never a failed
    /// or mixed frame. Jumpers: PD0 -> PE7, PD1 -> PG0, PA0 -> PG9.
    #[test]
    async fn xy2_status_word_out_loopback(board: Board) {
        const FRAMES: usize = 25;
        const HALF: usize = 500;
        const HALVES: usize = 16;
        const SWITCH: usize = 8;
        let r = board.res;
        let w = r.wave;
        let _pins = [
            Output::new(w.pins.p1, Level::Low, Speed::VeryHigh),
            Output::new(w.pins.p2, Level::Low, Speed::VeryHigh),
        ];
        let _status_in = Input::new(r.head_status, Pull::None);
        let (tx, link) = xy2_head_tx();
        let x = r.xy2_in;
        // SYNC, X, Y, Z out of their analog reset state (as `line::xy2_in`).
        let _data = x.data.inputs();
        // Declared first: the stream's channel outlives everything that borrows it.
        let mut slot = None;
        let in_ring = dma_ring!(".sram2", u16, 2 * HALF);
        let mut sampler = Xy2Sampler::prepare(x.tim, x.clk, x.dma, Irqs, pac::GPIOG, in_ring);
        let status_ring = dma_ring!(".sram2", u32, 2 * HALF);
        let pin = Output::new(r.ctrl_status, Level::Low, Speed::VeryHigh);
        let mut word_out = StatusWordOut::new(
            &mut sampler,
            x.status_dma,
            Irqs,
            &mut slot,
            pac::GPIOA,
            pin,
            status_ring,
            1 << 16,
            0,
        )
        .unwrap();
        sampler.start();
        let ring = dma_ring!(".sram2", u32, 2 * 1000);
        let mut out = WaveOut::new(
            w.tim,
            w.dma,
            Irqs,
            pac::GPIOD,
            ring,
            tx.idle_word(),
            4_000_000,
        )
        .unwrap();
        out.start();

        let encoder = WordOut::new(0, StatusLevel::default()).unwrap();
        let a = StatusWord::ALL_OK;
        let b = StatusWord::from_alarms(Alarms::INPUT_LOST);
        let frame_words = |word: StatusWord| {
            let mut words = [0u32; FRAME_BITS];
            encoder.word_frame(word, &link, &mut words);
            words
        };
        let (words_a, words_b) = (frame_words(a), frame_words(b));
        let geometry = StatusWordConfig {
            pin: 9,
            samples_per_period: 20,
            offset: 0,
            link,
        };
        let writer = async {
            let mut batch = [0u32; FRAMES * 40];
            for b in 0..=HALVES {
                xy2_batch(&tx, &link, &mut batch, b * FRAMES, usize::MAX);
                out.write_half(&batch).await.unwrap();
            }
        };
        let mut got: heapless::Vec<Result<StatusWord, StatusError>, 512> = heapless::Vec::new();
        let mut phase_found = false;
        let reader = async {
            let mut half = [0u16; HALF];
            let mut rx: Option<StatusWordReceiver> = None;
            for h in 0..HALVES {
                with_timeout(WAIT, sampler.read_exact(&mut half))
                    .await
                    .unwrap()
                    .unwrap();
                let words = if h < SWITCH { &words_a } else { &words_b };
                word_out.refresh(&half, sampler.last_start(), words);
                phase_found |= word_out.phase().is_some();
                let mut sink = |r| {
                    let _ = got.push(r);
                };
                match rx.as_mut() {
                    Some(rx) => rx.feed(&half, &mut sink),
                    None => {
                        // Status frames start on the sample after a frame end
                        // (SYNC low after 19 high samples).
                        let sync = |i: usize| half[i] & 1 == 1;
                        if let Some(end) =
                            (20..HALF).find(|&i| !sync(i) && !sync(i - 20) && (i - 19..i).all(sync))
                        {
                            let mut fresh = StatusWordReceiver::new(geometry).unwrap();
                            fresh.feed(&half[end + 1..], &mut sink);
                            rx = Some(fresh);
                        }
                    }
                }
            }
        };
        embassy_futures::join::join(writer, reader).await;
        assert!(phase_found, "no frame phase found");
        // Before the first sweep reached the DMA the ring played its idle low.
        let start = got
            .iter()
            .position(|r| r.is_ok())
            .expect("no valid status word");
        let words = &got[start..];
        let switch = words
            .iter()
            .position(|r| *r != Ok(a))
            .unwrap_or(words.len());
        assert!(switch >= 100, "{} words A", switch);
        for (i, r) in words[switch..].iter().enumerate() {
            assert_eq!(*r, Ok(b), "word {} after the switch", i);
        }
        assert!(
            words.len() - switch >= 100,
            "{} words B",
            words.len() - switch
        );
    }

    /// XY3-100 out -> XY3-100 in. Jumpers: PD0 (SYNC) -> PA15 and PA4, PD1 (CLK) ->
    /// PC10, PD2 (X) -> PC12. 32 frames of 24 bits go out; SPI3 must receive their
    /// 96 bytes and the EXTI marks must say a frame ended after every third byte.
    #[test]
    async fn xy3_frames_and_sync_marks(board: Board) {
        const FRAMES: usize = 32;
        const SLOTS: usize = 28; // 3 idle bits, 1 bit SYNC lead, 24 data bits
        const BYTES: usize = FRAMES * 3;
        let r = board.res;
        let w = r.wave;
        let _p1 = Output::new(w.pins.p1, Level::High, Speed::VeryHigh);
        let _p2 = Output::new(w.pins.p2, Level::Low, Speed::VeryHigh);
        let _p3 = Output::new(w.pins.p3, Level::Low, Speed::VeryHigh);
        let x = r.xy3_in;
        let mut marks = SyncMarks::new(x.sync, x.exti, Irqs, (2 * BYTES) as u16);
        let rx_ring = dma_ring!(".sram1", u8, 2 * BYTES);
        let l = x.x;
        let mut rx =
            SpiSlaveRx::new(l.spi, l.sck, l.mosi, Some(l.nss), l.dma, Irqs, rx_ring).unwrap();
        let idle = level(P1, true) | level(P2, false) | level(P3, false);
        let ring = dma_ring!(".sram2", u32, 4 * FRAMES * SLOTS);
        let mut out = WaveOut::new(w.tim, w.dma, Irqs, pac::GPIOD, ring, idle, 4_800_000).unwrap();
        out.start();

        let word = |k: usize| ((k as u32).wrapping_mul(0x0102_0305) ^ 0x00A5_5AC3) & 0xFF_FFFF;
        let mut half = [0u32; 2 * FRAMES * SLOTS];
        for (k, frame) in half.chunks_exact_mut(2 * SLOTS).enumerate() {
            for (slot, pair) in frame.chunks_exact_mut(2).enumerate() {
                if slot < 3 {
                    pair.fill(idle);
                } else if slot == 3 {
                    pair.fill(level(P1, false) | level(P2, false) | level(P3, false));
                } else {
                    let bit = word(k) >> (23 - (slot - 4)) & 1 == 1;
                    let data = level(P1, false) | level(P3, bit);
                    pair[0] = data | level(P2, true);
                    pair[1] = data | level(P2, false);
                }
            }
        }
        out.write_half(&half).await.unwrap();

        let mut got = [0u8; BYTES];
        with_timeout(WAIT, rx.read_exact(&mut got))
            .await
            .unwrap()
            .unwrap();
        for (k, bytes) in got.chunks_exact(3).enumerate() {
            let w = u32::from(bytes[0]) << 16 | u32::from(bytes[1]) << 8 | u32::from(bytes[2]);
            assert_eq!(w, word(k), "frame {}", k);
        }
        // The last SYNC edge comes one idle slot after the last byte.
        embassy_time::Timer::after_micros(50).await;
        let mut ends = [0u32; FRAMES + 1];
        let n = marks.drain(&mut ends);
        assert_eq!(n, FRAMES, "marks: {:?}", &ends[..n]);
        for (k, end) in ends[..n].iter().enumerate() {
            assert_eq!(*end as usize, 3 * (k + 1), "mark {}", k);
        }
    }

    /// XY3-100 out -> XY3-100 in, end to end through `shared`'s transmitter and
    /// receiver, as the firmware runs them. Jumpers: PD0 (SYNC) -> PA15, PE11 and PA4;
    /// PD1 (CLK) -> PC10 and PE12; PD2 (X) -> PC12; PD3 (Y) -> PE14. 120 periods of
    /// 24-bit X and Y position frames at 100 kHz (`xy3::tx`, 50 ticks at 5 MHz) are
    /// received by SPI3 (X) and SPI4 (Y) with the EXTI frame-end marks and decoded by
    /// `xy3::rx::Receiver`, fed in 60-byte chunks with the marks due so far: every
    /// period must give back both frames in order, except period 45, whose Y bit 10
    /// is flipped on the wire: Y must fail its check there (X still decodes), and the
    /// period must not count as good.
    #[test]
    async fn xy3_receiver_loopback(board: Board) {
        const FRAMES: usize = 120;
        const TPF: usize = 50;
        const BYTES: usize = 3 * FRAMES;
        const BAD: usize = 45;
        let r = board.res;
        let w = r.wave;
        let _sync = Output::new(w.pins.p1, Level::High, Speed::VeryHigh);
        let _clk = Output::new(w.pins.p2, Level::Low, Speed::VeryHigh);
        let _x = Output::new(w.pins.p3, Level::Low, Speed::VeryHigh);
        let _y = Output::new(w.pins.p4, Level::Low, Speed::VeryHigh);
        let tx = xy3::tx::Transmitter::new(&xy3::tx::TxConfig {
            pins: xy3::tx::OutPinMap {
                clk: P2 as u8,
                sync: P1 as u8,
                data: [Some(P3 as u8), Some(P4 as u8), None, None, None],
            },
            size: FrameSize::Bits24,
            idle_ticks: xy3::tx::MIN_IDLE_TICKS,
        })
        .unwrap();
        assert_eq!(tx.ticks_per_frame(), TPF);

        let i = r.xy3_in;
        let (lx, ly) = (i.x, i.y);
        // Both rings hold the whole transfer: nothing is read until it is all in.
        let x_ring = dma_ring!(".sram1", u8, 512);
        let y_ring = dma_ring!(".sram1", u8, 512);
        let mut rx_x =
            SpiSlaveRx::new(lx.spi, lx.sck, lx.mosi, Some(lx.nss), lx.dma, Irqs, x_ring).unwrap();
        let mut rx_y =
            SpiSlaveRx::new(ly.spi, ly.sck, ly.mosi, Some(ly.nss), ly.dma, Irqs, y_ring).unwrap();
        let mut marks = SyncMarks::new(i.sync, i.exti, Irqs, 512);

        // The output ring holds every frame plus idle, so no write can come late.
        let mut idle = [0u32; TPF];
        tx.idle(&mut idle).unwrap();
        // One lap of idle plays before the first written word: 7000 words fit.
        let ring = dma_ring!(".sram1", u32, (FRAMES + 40) * TPF);
        let mut out =
            WaveOut::new(w.tim, w.dma, Irqs, pac::GPIOD, ring, idle[0], 5_000_000).unwrap();
        out.start();

        let x_of =
            |k: usize| Frame3::Position24(((k as u32).wrapping_mul(0x1357) ^ 0x4_0000) & 0xF_FFFF);
        let y_of =
            |k: usize| Frame3::Position24(((k as u32).wrapping_mul(0x2468) ^ 0x9ABC) & 0xF_FFFF);
        let mut batch = [0u32; 20 * TPF];
        // Six batches of 20 frames, then one idle batch.
        for b in 0..=FRAMES / 20 {
            for (f, slot) in batch.chunks_exact_mut(TPF).enumerate() {
                let k = b * 20 + f;
                if k >= FRAMES {
                    tx.idle(slot).unwrap();
                    continue;
                }
                tx.encode(&[Some(x_of(k)), Some(y_of(k)), None, None, None], slot)
                    .unwrap();
                if k == BAD {
                    // Word 2b + 1 sets bit b's level; swap Y's set and reset there.
                    let word = &mut slot[2 * 10 + 1];
                    let ybits = (1 << P4) | (1 << (P4 + 16));
                    assert!(*word & ybits != 0 && *word & ybits != ybits);
                    *word ^= ybits;
                }
            }
            out.write_half(&batch).await.unwrap();
        }
        let (mut bx, mut by) = ([0u8; BYTES], [0u8; BYTES]);
        with_timeout(WAIT, rx_x.read_exact(&mut bx))
            .await
            .unwrap()
            .unwrap();
        with_timeout(WAIT, rx_y.read_exact(&mut by))
            .await
            .unwrap()
            .unwrap();
        embassy_time::Timer::after_micros(50).await;
        let mut ends = [0u32; FRAMES + 1];
        let n = marks.drain(&mut ends);
        assert_eq!(n, FRAMES, "marks");

        let periods = xy3_decode::<{ FRAMES + 8 }>(xy3::rx::Lines::XY, &[&bx, &by], &ends[..n]);
        assert_eq!(periods.len(), FRAMES, "periods");
        for (k, p) in periods.iter().enumerate() {
            assert_eq!(p.end as usize, 3 * (k + 1), "end of period {}", k);
            assert_eq!(p.lines[0], Some(Ok(x_of(k))), "X in period {}", k);
            if k == BAD {
                assert!(
                    matches!(p.lines[1], Some(Err(xy3::rx::RxError::Check(_)))),
                    "Y in period {}: {:?}",
                    k,
                    p.lines[1]
                );
                assert!(!p.all_ok());
            } else {
                assert_eq!(p.lines[1], Some(Ok(y_of(k))), "Y in period {}", k);
            }
        }
    }

    /// Feeds whole received lines (axis order) and their frame ends to a fresh
    /// `xy3::rx::Receiver` as the firmware's bridge loop does: 60-byte chunks, each
    /// with the ends whose bytes are in (at most 20 wait at a time).
    fn xy3_decode<const N: usize>(
        lines: xy3::rx::Lines,
        bytes: &[&[u8]],
        ends: &[u32],
    ) -> heapless::Vec<xy3::rx::Period, N> {
        const CHUNK: usize = 60;
        let mut receiver = xy3::rx::Receiver::new(lines);
        let mut periods = heapless::Vec::new();
        let len = bytes[0].len();
        let (mut next_end, mut from) = (0, 0);
        while from < len {
            let to = (from + CHUNK).min(len);
            let mut chunk: heapless::Vec<&[u8], 5> = heapless::Vec::new();
            for line in bytes {
                chunk.push(&line[from..to]).unwrap();
            }
            receiver.push_bytes(&chunk).unwrap();
            from = to;
            let due = ends[next_end..]
                .iter()
                .take_while(|&&e| e as usize <= to)
                .count();
            receiver.push_ends(&ends[next_end..next_end + due]);
            next_end += due;
            while let Some(p) = receiver.poll() {
                periods.push(p).unwrap();
            }
        }
        receiver.push_ends(&ends[next_end..]);
        while let Some(p) = receiver.poll() {
            periods.push(p).unwrap();
        }
        periods
    }

    /// All five XY3-100 data lines, as the firmware receives them with
    /// `controller.xy3.lines = ["x", "y", "z", "u", "w"]` and an XY3-100 head.
    /// Jumpers: PD0 (SYNC) -> PA15, PE11, PF6, PG10, PB12 and PA4; PD1 (CLK) -> PC10,
    /// PE12, PF7, PA5 and PB10; PD2 (X) -> PC12; PD3 (Y) -> PE14; PD10 (Z) -> PF9;
    /// PD14 (U) -> PB5; PD15 (W) -> PB15. 100 periods of five 24-bit position frames
    /// at 100 kHz go out through `xy3::tx`; SPI3, SPI4, SPI5, SPI1 (NSS on PG10, since
    /// PA4 is the EXTI input) and SPI2 receive them with the EXTI frame-end marks, and
    /// `xy3::rx::Receiver` must give back every line's frame in every period, except
    /// period 30, whose W bit 5 is flipped on the wire: W fails its check there, the
    /// four other lines still decode and the period is not good.
    #[test]
    async fn xy3_five_lines_loopback(board: Board) {
        use shared::model::Axis;
        const FRAMES: usize = 100;
        const TPF: usize = 50;
        const BYTES: usize = 3 * FRAMES;
        const BAD: usize = 30;
        /// Port-D bits of the data pairs 3, 4, 5, 7, 8 (X, Y, Z, U, W).
        const PINS: [u32; 5] = [P3, P4, 10, 14, 15];
        let r = board.res;
        let w = r.wave;
        let p = w.pins;
        // SYNC idles high (a rising edge before the first frame would be a mark).
        let _sync = Output::new(p.p1, Level::High, Speed::VeryHigh);
        let _pins = [
            p.p2.into(),
            p.p3.into(),
            p.p4.into(),
            p.p5.into(),
            p.p7.into(),
            p.p8.into(),
        ]
        .map(|pin: Peri<'static, AnyPin>| Output::new(pin, Level::Low, Speed::VeryHigh));
        let data = PINS.map(|b| Some(b as u8));
        let tx = xy3::tx::Transmitter::new(&xy3::tx::TxConfig {
            pins: xy3::tx::OutPinMap {
                clk: P2 as u8,
                sync: P1 as u8,
                data,
            },
            size: FrameSize::Bits24,
            idle_ticks: xy3::tx::MIN_IDLE_TICKS,
        })
        .unwrap();
        assert_eq!(tx.ticks_per_frame(), TPF);

        let i = r.xy3_in;
        // Every ring holds the whole transfer: nothing is read until it is all in.
        let rings = [
            dma_ring!(".sram1", u8, 512),
            dma_ring!(".sram1", u8, 512),
            dma_ring!(".sram1", u8, 512),
            dma_ring!(".sram1", u8, 512),
            dma_ring!(".sram1", u8, 512),
        ];
        let [rx_r, ry_r, rz_r, ru_r, rw_r] = rings;
        let (lx, ly, lz, lu, lw) = (i.x, i.y, i.z, i.u, i.w);
        let mut rx = [
            SpiSlaveRx::new(lx.spi, lx.sck, lx.mosi, Some(lx.nss), lx.dma, Irqs, rx_r).unwrap(),
            SpiSlaveRx::new(ly.spi, ly.sck, ly.mosi, Some(ly.nss), ly.dma, Irqs, ry_r).unwrap(),
            SpiSlaveRx::new(lz.spi, lz.sck, lz.mosi, Some(lz.nss), lz.dma, Irqs, rz_r).unwrap(),
            SpiSlaveRx::new(lu.spi, lu.sck, lu.mosi, Some(lu.nss), lu.dma, Irqs, ru_r).unwrap(),
            SpiSlaveRx::new(lw.spi, lw.sck, lw.mosi, Some(lw.nss), lw.dma, Irqs, rw_r).unwrap(),
        ];
        let mut marks = SyncMarks::new(i.sync, i.exti, Irqs, 512);

        let mut idle = [0u32; TPF];
        tx.idle(&mut idle).unwrap();
        let ring = dma_ring!(".sram1", u32, (FRAMES + 40) * TPF);
        let mut out =
            WaveOut::new(w.tim, w.dma, Irqs, pac::GPIOD, ring, idle[0], 5_000_000).unwrap();
        out.start();

        // A different position per line and period.
        let pos = |line: usize, k: usize| {
            let salt = 0x1357 + 0x1111 * line as u32;
            Frame3::Position24(((k as u32).wrapping_mul(salt) ^ ((line as u32) << 16)) & 0xF_FFFF)
        };
        let mut batch = [0u32; 20 * TPF];
        // Five batches of 20 frames, then one idle batch.
        for b in 0..=FRAMES / 20 {
            for (f, slot) in batch.chunks_exact_mut(TPF).enumerate() {
                let k = b * 20 + f;
                if k >= FRAMES {
                    tx.idle(slot).unwrap();
                    continue;
                }
                let frames = [0, 1, 2, 3, 4].map(|line| Some(pos(line, k)));
                tx.encode(&frames, slot).unwrap();
                if k == BAD {
                    // Word 2b + 1 sets bit b's level; swap W's set and reset there.
                    let word = &mut slot[2 * 5 + 1];
                    let wbits = (1 << PINS[4]) | (1 << (PINS[4] + 16));
                    assert!(*word & wbits != 0 && *word & wbits != wbits);
                    *word ^= wbits;
                }
            }
            out.write_half(&batch).await.unwrap();
        }
        let mut got = [[0u8; BYTES]; 5];
        for (line, bytes) in rx.iter_mut().zip(got.iter_mut()) {
            with_timeout(WAIT, line.read_exact(bytes))
                .await
                .unwrap()
                .unwrap();
        }
        embassy_time::Timer::after_micros(50).await;
        let mut ends = [0u32; FRAMES + 1];
        let n = marks.drain(&mut ends);
        assert_eq!(n, FRAMES, "marks");

        let lines: [&[u8]; 5] = [&got[0], &got[1], &got[2], &got[3], &got[4]];
        let periods = xy3_decode::<{ FRAMES + 8 }>(xy3::rx::Lines::ALL, &lines, &ends[..n]);
        assert_eq!(periods.len(), FRAMES, "periods");
        for (k, p) in periods.iter().enumerate() {
            assert_eq!(p.end as usize, 3 * (k + 1), "end of period {}", k);
            for (line, axis) in Axis::ALL.iter().enumerate() {
                let got = p.lines[axis.index()];
                if k == BAD && *axis == Axis::W {
                    assert!(
                        matches!(got, Some(Err(xy3::rx::RxError::Check(_)))),
                        "W in period {}: {:?}",
                        k,
                        got
                    );
                } else {
                    assert_eq!(got, Some(Ok(pos(line, k))), "{:?} in period {}", axis, k);
                }
            }
            assert_eq!(p.all_ok(), k != BAD, "period {}", k);
        }
    }

    /// HANS-100 out -> an SPI slave clocked by the SAI's own bit clock. Jumpers: PE6
    /// (SAI1_SD_A) -> PC12, PE5 (SAI1_SCK_A, test only) -> PC10. The 1000-bit ring of
    /// 8 frames must come back bit for bit (from whatever bit the SPI started on).
    #[test]
    async fn hans_serial_loopback(board: Board) {
        let r = board.res;
        // SAFETY: PE5 is not used by `board` or any driver; the test only routes the
        // SAI's bit clock to it so the SPI slave can sample synchronously.
        let sck_pin = unsafe { peripherals::PE5::steal() };
        let mut sck = Flex::new(sck_pin);
        sck.set_as_af_unchecked(6, AfType::output(OutputType::PushPull, Speed::VeryHigh));

        let mut expected = [0u8; RING_BYTES];
        for slot in 0..8u32 {
            let frame = Frame::new(slot * 0x1_1111, 0xF_FFFF - slot, 0x5_A5A5 ^ slot).unwrap();
            write_slot(&mut expected, slot as usize, &frame).unwrap();
        }
        let x = r.xy3_in;
        const LEN: usize = 2 * RING_BYTES;
        let rx_ring = dma_ring!(".sram1", u8, 2 * LEN);
        let no_nss: Option<Peri<'static, PA15>> = None;
        let l = x.x;
        let mut rx = SpiSlaveRx::new(l.spi, l.sck, l.mosi, no_nss, l.dma, Irqs, rx_ring).unwrap();
        let ring = dma_ring!(".sram2", u8, RING_BYTES);
        ring.copy_from_slice(&expected);
        let h = r.hans_out;
        let mut slot = None;
        let tx = SerialTx::new(h.sai, h.sd, h.dma, Irqs, &mut slot, ring);

        let mut got = [0u8; LEN];
        with_timeout(WAIT, rx.read_exact(&mut got))
            .await
            .unwrap()
            .unwrap();
        let bit = |buf: &[u8], i: usize| buf[i / 8] >> (7 - i % 8) & 1;
        let ring_bits = 8 * RING_BYTES;
        let found = (0..ring_bits)
            .any(|r| (0..8 * LEN).all(|j| bit(&got, j) == bit(&expected, (r + j) % ring_bits)));
        assert!(found, "ring pattern not received");
        assert!(tx.sending_slot() < 8);
    }

    /// Captures `words.len()` SPI6 words (40 MHz fs from TIM3 CH2) and decodes them
    /// with `shared`'s HANS-100 receiver as `status::hans_status` does (channel 1);
    /// returns the frames and the number of frames that failed a check.
    fn hans_decode(words: &[u16], frames: &mut heapless::Vec<Frame, 48>) -> usize {
        let mut rx = HansRx::new(HANS_FS_HZ, HansMode::Normal { channel: 1 }).unwrap();
        let mut bad = 0;
        rx.push(&[words], &mut |ev| match ev {
            RxEvent::Frame(f) => frames.push(f).unwrap(),
            RxEvent::Fault {
                kind: FaultKind::CheckFailed,
                ..
            } => bad += 1,
            RxEvent::Fault { .. } => {}
        });
        bad
    }

    /// HANS-100 out -> HANS STATUS in, the head-side status path end to end. Jumpers:
    /// PE6 (SAI1_SD_A) -> PG14 (SPI6 MOSI), PC7 (TIM3 CH2, fs) -> PB3 (SPI6 SCK). The
    /// SAI replays 8 frames, slot 5 with one bit flipped; SPI6 oversamples 1024 words
    /// (16 384 samples, 41 frame periods) into the BDMA ring in SRAM4 and the HANS-100
    /// receiver must give back at least 28 frames, each the ring's next frame in
    /// order, never slot 5, whose copies must fail their check instead.
    #[test]
    async fn hans_status_in_loopback(board: Board) {
        const BAD: usize = 5;
        let r = board.res;
        let mut ring_bytes = [0u8; RING_BYTES];
        let frame_of = |slot: u32| Frame::new(slot * 0x1_2345, 0xF_FFFF - slot, 0x3_C3C3 ^ slot);
        for slot in 0..8u32 {
            write_slot(&mut ring_bytes, slot as usize, &frame_of(slot).unwrap()).unwrap();
        }
        // One bit in the middle of slot 5 (inside a complement pair).
        let flip = BAD * 125 + 60;
        ring_bytes[flip / 8] ^= 0x80 >> (flip % 8);

        let s = r.hans_status_in;
        let mut fs = oversample_clock::start(r.fs.tim, None, Some(r.fs.status));
        fs.status.run();
        let rx_ring = dma_ring!(".sram4", u16, 2048);
        let no_nss: Option<Peri<'static, PG8>> = None;
        let mut rx = SpiSlaveRx::new(s.spi, s.sck, s.mosi, no_nss, s.dma, Irqs, rx_ring).unwrap();
        let ring = dma_ring!(".sram2", u8, RING_BYTES);
        ring.copy_from_slice(&ring_bytes);
        let h = r.hans_out;
        let mut channel = None;
        let _tx = SerialTx::new(h.sai, h.sd, h.dma, Irqs, &mut channel, ring);

        let mut words = [0u16; 1024];
        with_timeout(WAIT, rx.read_exact(&mut words))
            .await
            .unwrap()
            .unwrap();
        let mut frames = heapless::Vec::new();
        let bad = hans_decode(&words, &mut frames);
        assert!(frames.len() >= 28, "{} frames", frames.len());
        assert!(bad >= 2, "{} check failures", bad);
        let slot_of = |f: &Frame| (0..8u32).find(|&s| frame_of(s).unwrap() == *f);
        let mut last = slot_of(&frames[0]).expect("frame not from the ring");
        for f in &frames[1..] {
            let slot = slot_of(f).expect("frame not from the ring");
            assert_ne!(slot as usize, BAD, "corrupted frame delivered");
            let step = if (last as usize + 1) % 8 == BAD { 2 } else { 1 };
            assert_eq!(slot, (last + step) % 8, "after slot {}", last);
            last = slot;
        }
    }

    /// The HANS-100 head output as the bridge loop drives it: the ring starts as zeros
    /// (no frame on the line), then `shared::hans::tx::Transmitter::update` puts frame
    /// k = 1, 2, ... two slots ahead of the DMA about every slot period, for longer
    /// than SPI6 captures (2048 words, 819 us). Jumpers as `hans_status_in_loopback`.
    /// Every decoded frame must be one of those written, in non-decreasing k (the
    /// line never replays an older one), with at least 10 distinct k.
    #[test]
    async fn hans_paced_update_loopback(board: Board) {
        const MAX_K: u32 = 1000;
        let r = board.res;
        let frame_of = |k: u32| Frame::new((k * 0x1111) & 0xF_FFFF, 0x8_0000 + k, k).unwrap();
        let s = r.hans_status_in;
        let mut fs = oversample_clock::start(r.fs.tim, None, Some(r.fs.status));
        fs.status.run();
        let rx_ring = dma_ring!(".sram4", u16, 4096);
        let no_nss: Option<Peri<'static, PG8>> = None;
        let mut rx = SpiSlaveRx::new(s.spi, s.sck, s.mosi, no_nss, s.dma, Irqs, rx_ring).unwrap();
        let ring = dma_ring!(".sram2", u8, RING_BYTES);
        let h = r.hans_out;
        let mut channel = None;
        let mut out = SerialTx::new(h.sai, h.sd, h.dma, Irqs, &mut channel, ring);

        let mut words = [0u16; 2048];
        let updates = async {
            let mut tx = Transmitter::new();
            let end = embassy_time::Instant::now() + Duration::from_micros(1500);
            let mut k = 1;
            while embassy_time::Instant::now() < end && k < MAX_K {
                let remaining = out.remaining();
                out.update(|buf| tx.update(buf, remaining, &frame_of(k)))
                    .unwrap();
                k += 1;
                embassy_time::Timer::after_micros(10).await;
            }
        };
        let capture = with_timeout(WAIT, rx.read_exact(&mut words));
        let (_, captured) = embassy_futures::join::join(updates, capture).await;
        captured.unwrap().unwrap();

        let mut frames = heapless::Vec::new();
        hans_decode(&words, &mut frames);
        let k_of = |f: &Frame| (1..MAX_K).find(|&k| frame_of(k) == *f);
        let mut last = 0;
        let mut distinct = 0;
        for f in &frames {
            let k = k_of(f).expect("frame not written by the test");
            assert!(k >= last, "frame {} after {}", k, last);
            distinct += usize::from(k != last);
            last = k;
        }
        assert!(distinct >= 10, "{} distinct frames", distinct);
    }

    /// HANS-100 head output -> HANS-100 controller input, all five channels. Jumpers:
    /// PE6 (SAI1_SD_A) -> PD7 (CH1), PC1 (CH2), PC12 (CH3), PE14 (CH4), PF9 (CH5);
    /// PC6 (TIM3 CH1, fs) -> PA5, PB10, PC10, PE12, PF7 (the SCK bus). The SAI replays
    /// 8 frames, slot 5 with one bit flipped. `HansInput` starts the five SPIs with fs
    /// held low (the same code as `hans_in`), and captures 1024 words per channel (41 frame
    /// periods), fed to the receiver 64 words at a time as `hans_decode` does. In
    /// super mode every channel must verify at least 28 frames on its own (so every
    /// channel is wired and aligned), and in super, vote3 (1, 3, 5) and normal
    /// (channel 2) mode the frames published must be the ring's, in order, never
    /// slot 5.
    #[test]
    async fn hans_controller_loopback(board: Board) {
        const WORDS: usize = 1024;
        const CHUNK: usize = 64;
        const BAD: usize = 5;
        let r = board.res;
        let frame_of = |slot: u32| {
            Frame::new(
                0x8_0000 ^ (slot * 0x2_4681),
                slot * 0x1_0101,
                0x1_E1E1 ^ slot,
            )
        };
        let mut ring_bytes = [0u8; RING_BYTES];
        for slot in 0..8u32 {
            write_slot(&mut ring_bytes, slot as usize, &frame_of(slot).unwrap()).unwrap();
        }
        let flip = BAD * 125 + 60;
        ring_bytes[flip / 8] ^= 0x80 >> (flip % 8);

        let mut fs = oversample_clock::start(r.fs.tim, Some(r.fs.ctrl), None);
        // Rings twice the capture: `read` fills channel 1's capture first while the
        // others keep filling.
        let mut input = HansInput::new(r.xy3_in, r.hans_in, hans_rings!(2 * WORDS));
        // The line is driven before the capture starts.
        let ring = dma_ring!(".sram2", u8, RING_BYTES);
        ring.copy_from_slice(&ring_bytes);
        let o = r.hans_out;
        let mut channel = None;
        let _tx = SerialTx::new(o.sai, o.sd, o.dma, Irqs, &mut channel, ring);
        let mut lines = input.start(0b1_1111, Irqs, &mut fs.ctrl).unwrap();

        let mut words = [[0u16; WORDS]; 5];
        with_timeout(WAIT, lines.read(&mut words))
            .await
            .unwrap()
            .unwrap();

        let slot_of = |f: &Frame| (0..8u32).find(|&s| frame_of(s).unwrap() == *f);
        let modes = [
            HansMode::Super,
            HansMode::Vote3 {
                channels: [1, 3, 5],
            },
            HansMode::Normal { channel: 2 },
        ];
        for mode in modes {
            let mut rx = HansRx::new(HANS_FS_HZ, mode).unwrap();
            let mut frames: heapless::Vec<Frame, 48> = heapless::Vec::new();
            for at in (0..WORDS).step_by(CHUNK) {
                let chunks = [0, 1, 2, 3, 4].map(|n| &words[n][at..at + CHUNK]);
                rx.push(&chunks, &mut |ev| {
                    if let RxEvent::Frame(f) = ev {
                        frames.push(f).unwrap();
                    }
                });
            }
            assert!(frames.len() >= 28, "{:?}: {} frames", mode, frames.len());
            let mut last = slot_of(&frames[0]).expect("frame not from the ring");
            for f in &frames[1..] {
                let slot = slot_of(f).expect("frame not from the ring");
                assert_ne!(slot as usize, BAD, "{:?}: corrupted frame delivered", mode);
                let step = if (last as usize + 1) % 8 == BAD { 2 } else { 1 };
                assert_eq!(slot, (last + step) % 8, "{:?}: after slot {}", mode, last);
                last = slot;
            }
            if mode == HansMode::Super {
                for ch in 1..=5u8 {
                    let ok = rx.stats(ch).unwrap().frames_ok;
                    assert!(ok >= 28, "CH{} verified {} frames", ch, ok);
                }
            }
        }
    }

    /// HANS STATUS out -> a HANS input. Jumpers: PA0 (SAI2_SD_B) -> PG14 (SPI6 MOSI),
    /// PC7 (TIM3 CH2, fs) -> PB3 (SPI6 SCK). As `hans_status_out` does, the bridge's
    /// STATUS frames (`Bridge::hans_status_frame` for a HANS-100 controller, the head
    /// reporting over-temperature) go into SAI2 block B's ring six at a time, two
    /// slots ahead of the DMA (`SerialTx::write_ahead`), every 200 us while SPI6
    /// captures 2048 words (819 us). Every decoded frame must be one the bridge made,
    /// none may fail its check (no slot is written while it is sent), and
    /// `StatusReceiver` must read the over-temperature back.
    #[test]
    async fn hans_status_out_loopback(board: Board) {
        let r = board.res;
        let mut config = shared::bridge::Config::default();
        config.controller.protocol = shared::bridge::Protocol::Hans;
        let mut bridge = shared::bridge::Bridge::new(&config).unwrap();
        bridge.head_status_mut().alarms = Alarms::TEMPERATURE;
        let mut made: heapless::Vec<Frame, 64> = heapless::Vec::new();

        // The ring starts full of the bridge's frames (the task starts from zeros)
        // and the line is driven before the capture starts, so any frame failing
        // its check would be a slot written while the DMA was sending it.
        let ring = dma_ring!(".sram2", u8, RING_BYTES);
        for slot in 0..8 {
            let f = bridge.hans_status_frame();
            write_slot(ring, slot, &f).unwrap();
            made.push(f).unwrap();
        }
        let o = r.hans_status_out;
        let mut channel = None;
        let mut out = SerialTx::new(o.sai, r.ctrl_status, o.dma, Irqs, &mut channel, ring);
        let mut fs = oversample_clock::start(r.fs.tim, None, Some(r.fs.status));
        fs.status.run();
        let s = r.hans_status_in;
        let rx_ring = dma_ring!(".sram4", u16, 4096);
        let no_nss: Option<Peri<'static, PG8>> = None;
        let mut rx = SpiSlaveRx::new(s.spi, s.sck, s.mosi, no_nss, s.dma, Irqs, rx_ring).unwrap();

        let mut words = [0u16; 2048];
        let refresh = async {
            let end = embassy_time::Instant::now() + Duration::from_micros(1500);
            while embassy_time::Instant::now() < end && made.len() + 6 <= made.capacity() {
                let batch = [(); 6].map(|_| bridge.hans_status_frame());
                assert_eq!(out.write_ahead(&batch).unwrap(), 6);
                made.extend_from_slice(&batch).unwrap();
                embassy_time::Timer::after_micros(200).await;
            }
        };
        let capture = with_timeout(WAIT, rx.read_exact(&mut words));
        let (_, captured) = embassy_futures::join::join(refresh, capture).await;
        captured.unwrap().unwrap();

        let mut frames = heapless::Vec::new();
        let bad = hans_decode(&words, &mut frames);
        assert_eq!(bad, 0, "STATUS frames failed their check");
        assert!(frames.len() >= 28, "{} frames", frames.len());
        let mut receiver = shared::hans::StatusReceiver::new();
        let mut status = shared::model::HeadStatus::default();
        for f in &frames {
            assert!(made.contains(f), "frame not made by the bridge");
            receiver.apply(f, &mut status);
        }
        assert!(
            status.alarms.contains(Alarms::TEMPERATURE),
            "alarms {:#x}",
            status.alarms.0
        );
    }

    /// Sends `packet` with `shared`'s sender on `tx` and waits until `rx` parses it
    /// back (other bytes, e.g. a resync after a rate change, are skipped).
    async fn packet_crosses(
        tx: &mut UartTx<'static, Async>,
        rx: &mut RingBufferedUartRx<'static>,
        sender: &mut Sender,
        packet: &Packet,
    ) {
        let mut parser = Parser::default();
        let mut out = [0u8; SEND_BUF_LEN];
        let n = sender.send(0, packet, &mut out).unwrap();
        tx.write(&out[..n]).await.unwrap();
        let mut buf = [0u8; 64];
        loop {
            let n = with_timeout(WAIT, rx.read(&mut buf))
                .await
                .unwrap()
                .unwrap();
            for &byte in &buf[..n] {
                if let Some(Event::Packet(raw)) = parser.push(byte) {
                    if Packet::decode(raw.ty, raw.payload).as_ref() == Ok(packet) {
                        return;
                    }
                }
            }
        }
    }

    /// UART7 duplex (TX + DE as the firmware builds it), its TX and ring RX.
    fn uart7(
        b: board::BackRes,
        baud: u32,
    ) -> (UartTx<'static, Async>, RingBufferedUartRx<'static>) {
        let uart = Uart::new_with_de(
            b.uart,
            b.rx,
            b.tx,
            b.de,
            b.tx_dma,
            b.rx_dma,
            Irqs,
            backchannel::config(baud),
        )
        .unwrap();
        let (tx, rx) = uart.split();
        (tx, backchannel::head_rx(rx, dma_ring!(".sram3", u8, 256)))
    }

    /// Backchannel towards the controller: UART7 TX -> RX. Jumper: PE8 -> PA8.
    /// Packets sent with `shared`'s sender must be parsed back, before and after a
    /// baud change.
    #[test]
    async fn backchannel_loopback(board: Board) {
        let (mut tx, mut rx) = uart7(board.res.back, 115_200);
        let mut sender = Sender::default();
        for (round, baud) in [115_200u32, 921_600].into_iter().enumerate() {
            if round > 0 {
                tx.set_baudrate(baud).unwrap();
                sender.note_rate_change();
            }
            let packet = Packet::FrameErrorCount([1, 2, 3, 4, baud]);
            packet_crosses(&mut tx, &mut rx, &mut sender, &packet).await;
        }
    }

    /// The head's backchannel UART (USART2, its own rate) against UART7. Jumpers:
    /// PD5 (USART2 TX) -> PA8 (UART7 RX) and PE8 (UART7 TX) -> PD6 (USART2 RX, the
    /// head-side pair-6 input). Packets cross both ways at 115200 baud; then each
    /// UART is switched through its own handle (`set_baudrate` on one must not be
    /// needed for the other's rate: separate BRRs) to 921600 and they cross again;
    /// at last only USART2 goes back to 115200 and a packet from UART7 (still at
    /// 921600) must not be parsed, the proof that the two rates are independent.
    #[test]
    async fn head_backchannel_loopback(board: Board) {
        let (mut ctrl_tx, mut ctrl_rx) = uart7(board.res.back, 115_200);
        let h = board.res.head_back;
        let head = Uart::new(
            h.uart,
            h.rx,
            h.tx,
            h.tx_dma,
            h.rx_dma,
            Irqs,
            backchannel::config(115_200),
        )
        .unwrap();
        let (mut head_tx, head_rx) = head.split();
        let mut head_rx = backchannel::head_rx(head_rx, dma_ring!(".sram3", u8, 256));
        let mut sender = Sender::default();
        for (round, baud) in [115_200u32, 921_600].into_iter().enumerate() {
            if round > 0 {
                head_rx.set_baudrate(baud).unwrap();
                ctrl_tx.set_baudrate(baud).unwrap();
                sender.note_rate_change();
            }
            let to_head = Packet::FrameErrorCount([round as u32, 0, 0, 0, baud]);
            packet_crosses(&mut ctrl_tx, &mut head_rx, &mut sender, &to_head).await;
            let from_head = Packet::FrameErrorCount([0, round as u32, 0, 0, baud]);
            packet_crosses(&mut head_tx, &mut ctrl_rx, &mut sender, &from_head).await;
        }
        // Rates apart: USART2 back at 115200, UART7 still at 921600.
        head_rx.set_baudrate(115_200).unwrap();
        let mut out = [0u8; SEND_BUF_LEN];
        let packet = Packet::FrameErrorCount([7, 7, 7, 7, 7]);
        let n = sender.send(0, &packet, &mut out).unwrap();
        ctrl_tx.write(&out[..n]).await.unwrap();
        ctrl_tx.flush().await.unwrap();
        let mut parser = Parser::default();
        let mut buf = [0u8; 64];
        // Whatever arrives (framing errors are allowed) never parses as the packet;
        // bounded, in case the receiver reports an error on every read.
        for _ in 0..64 {
            let n = match with_timeout(Duration::from_millis(20), head_rx.read(&mut buf)).await {
                Err(_) => break,
                Ok(r) => r.unwrap_or(0),
            };
            for &byte in &buf[..n] {
                if let Some(Event::Packet(raw)) = parser.push(byte) {
                    assert_ne!(Packet::decode(raw.ty, raw.payload).as_ref(), Ok(&packet));
                }
            }
        }
    }

    /// TIM5 as a 32-bit edge stamper for two pins: CH1 (PA0) and CH4 (PA3) capture
    /// the counter on both edges, and one DMA stream per channel copies each capture
    /// into a buffer (register sequence: RM0433, chapter "General-purpose timers
    /// (TIM2/TIM3/TIM4/TIM5)", input capture mode; TIMx_CCMR1/2, TIMx_CCER,
    /// TIMx_DIER.CCxDE). TIM5 counts the 240 MHz timer clock (200 MHz on revision Y)
    /// undivided, so a capture never wraps (17.9 s).
    struct EdgeCapture {
        timer: Timer<'static, peripherals::TIM5>,
        /// CH1 and CH4 inputs, kept configured.
        pins: [Flex<'static>; 2],
        dma: [dma::Channel<'static>; 2],
        request: [dma::Request; 2],
    }

    /// What one [`EdgeCapture::run`] captured: per channel the level before the
    /// first edge and the number of edges in its buffer.
    struct Captured {
        initial_high: [bool; 2],
        edges: [usize; 2],
    }

    impl EdgeCapture {
        /// The two capture channels in `EdgeCapture`'s order.
        const CHANNELS: [TimChannel; 2] = [TimChannel::Ch1, TimChannel::Ch4];

        fn new(
            tim: Peri<'static, peripherals::TIM5>,
            ch1: Peri<'static, impl TimerPin<peripherals::TIM5, Ch1>>,
            ch4: Peri<'static, impl TimerPin<peripherals::TIM5, Ch4>>,
            ch1_dma: Peri<'static, peripherals::DMA2_CH0>,
            ch4_dma: Peri<'static, peripherals::DMA2_CH7>,
            irq: Irqs,
        ) -> Self {
            // Pulls give a missing jumper a defined level: TX idles high, DE low.
            let (af1, af4) = (ch1.af_num(), ch4.af_num());
            let mut p1 = Flex::new(ch1);
            p1.set_as_af_unchecked(af1, AfType::input(Pull::Up));
            let mut p4 = Flex::new(ch4);
            p4.set_as_af_unchecked(af4, AfType::input(Pull::Down));
            // DMAMUX1 inputs TIM5_CH1 / TIM5_CH4 (RM0433 §17.3.2), from embassy's table.
            let request = [
                <peripherals::DMA2_CH0 as timer::Dma<peripherals::TIM5, Ch1>>::request(&ch1_dma),
                <peripherals::DMA2_CH7 as timer::Dma<peripherals::TIM5, Ch4>>::request(&ch4_dma),
            ];
            let dma = [
                dma::Channel::new(ch1_dma, irq),
                dma::Channel::new(ch4_dma, irq),
            ];
            let timer = Timer::new(tim);
            timer.regs_gp32().psc().write_value(0);
            timer.regs_gp32().arr().write_value(u32::MAX);
            for ch in Self::CHANNELS {
                // CCxS = TIx, a filter of 8 timer clocks (both channels alike, so it
                // delays both the same), no prescaler, both edges (CCxP = CCxNP = 1).
                timer.set_input_ti_selection(ch, InputTISelection::Normal);
                timer.set_input_capture_filter(ch, FilterValue::FCK_INT_N8);
                timer.set_input_capture_prescaler(ch, 0);
                timer.set_input_capture_mode(ch, InputCaptureMode::BothEdges);
            }
            Self {
                timer,
                pins: [p1, p4],
                dma,
                request,
            }
        }

        /// Capture ticks per second.
        fn hz(&self) -> u32 {
            self.timer.get_clock_frequency().0
        }

        /// Captures both pins from counter 0 while `activity` runs: CH1's edge times
        /// into `ch1`, CH4's into `ch4`. A full buffer fails the test (edges lost).
        async fn run(
            &mut self,
            ch1: &mut [u32],
            ch4: &mut [u32],
            activity: impl core::future::Future<Output = ()>,
        ) -> Captured {
            let t = &self.timer;
            t.stop();
            t.reset();
            let lens = [ch1.len(), ch4.len()];
            let [dma1, dma4] = &mut self.dma;
            // Direct mode (the default options): every capture lands in memory at once,
            // so a stopped stream has written all it counted.
            let options = dma::TransferOptions::default();
            // SAFETY: CCR1 / CCR4 are readable 32-bit registers of TIM5, which this
            // struct owns; the buffers outlive the transfers (dropped below).
            let mut transfers = unsafe {
                [
                    dma1.read(self.request[0], t.regs_gp32().ccr(0).as_ptr(), ch1, options),
                    dma4.read(self.request[1], t.regs_gp32().ccr(3).as_ptr(), ch4, options),
                ]
            };
            for ch in Self::CHANNELS {
                t.clear_input_interrupt(ch);
                t.set_cc_dma_enable_state(ch, true);
                t.enable_channel(ch, true);
            }
            let initial_high = [self.pins[0].is_high(), self.pins[1].is_high()];
            t.start();
            activity.await;
            for ch in Self::CHANNELS {
                t.enable_channel(ch, false);
                t.set_cc_dma_enable_state(ch, false);
            }
            t.stop();
            let mut edges = [0; 2];
            for (i, tr) in transfers.iter_mut().enumerate() {
                tr.request_pause();
                while tr.is_running() {}
                let left = tr.get_remaining_transfers() as usize;
                assert!(left > 0, "capture buffer {} full: edges lost", i);
                edges[i] = lens[i] - left;
            }
            Captured {
                initial_high,
                edges,
            }
        }
    }

    /// UART7's DE timing as its registers hold it (RM0433 §48.4 and §48.7, CR1.DEAT / DEDT in
    /// sample times; BRR, PRESC and CR1.OVER8 give the bit time), checked
    /// against what `backchannel::config(baud)` asked for. The register values, not
    /// the request, are what the capture is judged by.
    fn uart7_de_setup(baud: u32, capture_hz: u32) -> shared::rs485::Setup {
        const PRESC_DIV: [u32; 12] = [1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128, 256];
        let u = pac::UART7;
        let cr1 = u.cr1().read();
        let over8 = cr1.over8() == pac::usart::vals::Over8::OVERSAMPLING8;
        let brr = u32::from(u.brr().read().brr());
        // With 8x oversampling BRR[2:0] holds USARTDIV[3:1] (USARTDIV[0] is 0).
        let usartdiv = if over8 {
            (brr & !0xF) | ((brr & 0x7) << 1)
        } else {
            brr
        };
        let presc = PRESC_DIV[usize::from(u.presc().read().prescaler().to_bits())];
        let kernel_hz = embassy_stm32::rcc::frequency::<peripherals::UART7>().0;
        let asked = backchannel::config(baud);
        // embassy halves the times for 8x oversampling (its unit is 1/16 bit).
        let unit = |t: u8| if over8 { t / 2 } else { t };
        assert_eq!(
            cr1.deat(),
            unit(asked.de_assertion_time),
            "DEAT at {}",
            baud
        );
        assert_eq!(
            cr1.dedt(),
            unit(asked.de_deassertion_time),
            "DEDT at {}",
            baud
        );
        let setup = shared::rs485::Setup {
            kernel_hz,
            kernel_clocks_per_bit: usartdiv * presc,
            samples_per_bit: if over8 { 8 } else { 16 },
            lead_samples: u32::from(cr1.deat()),
            tail_samples: u32::from(cr1.dedt()),
            capture_hz,
            // Four UART kernel clocks: the input synchronisers and the skew between
            // the DE and TX outputs.
            tolerance_ns: 40,
        };
        // The bit time is the one asked for, within 0.5 %: embassy picks 16x
        // oversampling for 921600 too, so BRR = 109 clocks (-0.45 %; 8x would give
        // 217 half-clocks, 0.01 %).
        let actual = kernel_hz / setup.kernel_clocks_per_bit;
        assert!(
            actual.abs_diff(baud) * 200 < baud,
            "{} baud for {}",
            actual,
            baud
        );
        setup
    }

    /// RS-485 driver enable of the backchannel towards the controller: UART7 as the
    /// firmware builds it (`Uart::new_with_de`, `backchannel::config`: DE active high,
    /// CR1.DEAT = DEDT = 8 sample times at 16x oversampling, i.e. half a bit: 4.34 us
    /// at 115200 baud, 545 ns at 921600). Jumpers: PE8 (UART7_TX) -> PA0 (TIM5_CH1),
    /// PF8 (UART7_DE) -> PA3 (TIM5_CH4), PD5 (USART2_TX) -> PA8 (UART7_RX). TIM5
    /// stamps every TX and DE edge ([`EdgeCapture`]) while, at 115200 and then (after
    /// `set_baudrate`, as the firmware switches rates) 921600 baud: the line idles,
    /// UART7 sends two packets from `shared`'s sender (the second holds 0x00 and 0xFF
    /// bytes) 300 us apart, and USART2 sends a packet that UART7 must receive.
    /// `shared::rs485::check` then requires, against UART7's registers read back:
    /// TX decodes to exactly the bytes sent, each packet back to back; DE is low at
    /// the start and has exactly one pulse per packet, so it is low while idle and
    /// while receiving; each pulse rises the configured lead before the first start
    /// edge and falls the configured tail after the end of the last stop bit (so it
    /// covers every stop bit), each within [configured - 40 ns, configured + one
    /// sample + 40 ns] (the USART switches DE on its 1/16-bit sample clock).
    #[test]
    async fn backchannel_de_timing(board: Board) {
        let r = board.res;
        let (mut tx, mut rx) = uart7(r.back, 115_200);
        let h = r.head_back;
        let mut head_tx =
            UartTx::new(h.uart, h.tx, h.tx_dma, Irqs, backchannel::config(115_200)).unwrap();
        // SAFETY: neither TIM5 nor PA3 is taken by `board` or any driver (README
        // "Peripheral allocation": TIM5 spare); only this test uses them.
        let (tim5, pa3) = unsafe { (peripherals::TIM5::steal(), peripherals::PA3::steal()) };
        let x = r.xy2_in;
        let mut capture = EdgeCapture::new(tim5, r.ctrl_status, pa3, x.dma, x.status_dma, Irqs);
        let tx_edges = dma_ring!(".sram2", u32, 1024);
        let de_edges = dma_ring!(".sram2", u32, 64);
        let mut sender = Sender::default();
        let mut head_sender = Sender::default();
        for (round, baud) in [115_200u32, 921_600].into_iter().enumerate() {
            if round > 0 {
                tx.set_baudrate(baud).unwrap();
                head_tx.set_baudrate(baud).unwrap();
                sender.note_rate_change();
                head_sender.note_rate_change();
            }
            // Re-enabled, a USART may send an idle frame: let it pass uncaptured.
            embassy_time::Timer::after_millis(1).await;
            let setup = uart7_de_setup(baud, capture.hz());
            let mut first = [0u8; SEND_BUF_LEN];
            let packet = Packet::FrameErrorCount([1, 2, 3, 4, baud]);
            let n_first = sender.send(0, &packet, &mut first).unwrap();
            let mut second = [0u8; SEND_BUF_LEN];
            let packet = Packet::FrameErrorCount([u32::MAX, 0, 0x5555_5555, 0xAAAA_AAAA, baud]);
            let n_second = sender.send(0, &packet, &mut second).unwrap();
            let messages: [&[u8]; 2] = [&first[..n_first], &second[..n_second]];
            let from_head = Packet::FrameErrorCount([9, 9, 9, round as u32, baud]);
            let activity = async {
                embassy_time::Timer::after_micros(100).await;
                for m in messages {
                    tx.write(m).await.unwrap();
                    tx.flush().await.unwrap();
                    embassy_time::Timer::after_micros(300).await;
                }
                packet_crosses(&mut head_tx, &mut rx, &mut head_sender, &from_head).await;
                embassy_time::Timer::after_micros(100).await;
            };
            let got = capture
                .run(&mut tx_edges[..], &mut de_edges[..], activity)
                .await;
            let tx_line = shared::rs485::Edges {
                initial_high: got.initial_high[0],
                times: &tx_edges[..got.edges[0]],
            };
            let de_line = shared::rs485::Edges {
                initial_high: got.initial_high[1],
                times: &de_edges[..got.edges[1]],
            };
            let measured = shared::rs485::check(&setup, tx_line, de_line, &messages);
            match measured {
                Ok(m) => defmt::info!("{} baud: {}", baud, m),
                Err(e) => panic!("{} baud: {}", baud, e),
            }
        }
    }

    /// XY2-100 STATUS level: controller-side output -> head-side debounced input.
    /// The level at start-up (`StatusOut` starts at fault) is reported first, then
    /// each change. Jumper: PA0 -> PG9.
    #[test]
    async fn status_level_loopback(board: Board) {
        let r = board.res;
        let setting = StatusLevel::default();
        let mut out = StatusOut::new(Output::new(r.ctrl_status, Level::High, Speed::Low), setting);
        let mut input = StatusIn::new(Input::new(r.head_status, Pull::None), setting);
        for health in [Health::Fault, Health::Ok, Health::Fault, Health::Ok] {
            out.set(health);
            let seen = with_timeout(WAIT, input.changed()).await.unwrap();
            assert_eq!(seen, health);
        }
    }

    /// Ticks per frame and tick rate of the XY2-100 source ([`Xy2Source`]): 100 kHz
    /// frames at a 2 MHz clock, as a controller sends them.
    const SRC_TPF: usize = 40;
    const SRC_TICK_HZ: u32 = 4_000_000;
    /// Frames per half of the source's ring (0.5 ms).
    const SRC_FRAMES: usize = 50;

    /// A test-only XY2-100 controller: TIM4's update event requests one DMA1 stream 6
    /// transfer per tick (DMAMUX request TIM4_UP) that writes the next word of a
    /// circular ring into GPIOE's BSRR, as `WaveOut` does on TIM8 for the head side
    /// (TIM4 is free in every pairing, and `WaveOut` is built for TIM1 / TIM8 only;
    /// register sequence: RM0433 "General-purpose timers", time-base unit and
    /// TIMx_DIER.UDE). Words from `shared::xy2::tx` on PE2 (CLK), PE3 (SYNC), PE4
    /// (X), PE9 (Y), PE10 (Z).
    struct Xy2Source {
        timer: Timer<'static, peripherals::TIM4>,
        ring: dma::WritableRingBuffer<'static, u32>,
        /// The five pins, kept outputs.
        _pins: [Output<'static>; 5],
    }

    /// The source's port-E pins, in `OutPinMap` order.
    const SRC_PINS: xy2::tx::OutPinMap = xy2::tx::OutPinMap {
        clk: 2,
        sync: 3,
        x: 4,
        y: 9,
        z: Some(10),
    };

    impl Xy2Source {
        /// Starts playing `idle` from the ring (no clock edges until frames are
        /// written).
        fn start(
            dma: Peri<'static, peripherals::DMA1_CH6>,
            ring: &'static mut [u32],
            idle: u32,
        ) -> Self {
            // SAFETY: TIM4 and PE2/3/4/9/10 are in no `board::Resources` group and no
            // firmware task uses them; this test is their only user.
            let (tim, pins) = unsafe {
                (
                    peripherals::TIM4::steal(),
                    [
                        peripherals::PE2::steal().into(),
                        peripherals::PE3::steal().into(),
                        peripherals::PE4::steal().into(),
                        peripherals::PE9::steal().into(),
                        peripherals::PE10::steal().into(),
                    ],
                )
            };
            let _pins =
                pins.map(|p: Peri<'static, AnyPin>| Output::new(p, Level::Low, Speed::VeryHigh));
            let timer = Timer::new(tim);
            let timer_hz = timer.get_clock_frequency().0;
            assert_eq!(timer_hz % SRC_TICK_HZ, 0, "TIM4 clock {} Hz", timer_hz);
            let regs = timer.regs_gp16();
            regs.psc().write_value(0);
            regs.arr()
                .write(|w| w.set_arr((timer_hz / SRC_TICK_HZ - 1) as u16));
            timer.generate_update_event();
            regs.sr().write_value(pac::timer::regs::SrGp16(0));
            ring.fill(idle);
            let request = UpDma::<peripherals::TIM4>::request(&*dma);
            UpDma::<peripherals::TIM4>::remap(&*dma);
            let channel = dma::Channel::new(dma, Irqs);
            // SAFETY: BSRR is a valid 32-bit write-only register for as long as the
            // port exists (forever); the ring lives for 'static and the DMA reads it
            // only through the ring buffer, which owns it.
            let mut ring = unsafe {
                dma::WritableRingBuffer::new(
                    channel,
                    request,
                    pac::GPIOE.bsrr().as_ptr() as *mut u32,
                    ring,
                    timing_critical(),
                )
            };
            ring.start();
            regs.dier().modify(|w| w.set_ude(true));
            timer.start();
            Xy2Source { timer, ring, _pins }
        }

        /// Queues `words` behind what plays; `false`: the DMA ran out of written
        /// words first (it replayed old ones).
        async fn write(&mut self, words: &[u32]) -> bool {
            self.ring.write_exact(words).await.is_ok()
        }
    }

    impl Drop for Xy2Source {
        fn drop(&mut self) {
            self.timer.stop();
        }
    }

    /// Controller frame `k`'s positions (X, Y, Z): each axis an odd multiple of `k`
    /// plus a constant, modulo 2^16, so every `k < 2^16` has its own X and `k`
    /// follows back from X alone ([`frame_of_x`]).
    fn e2e_positions(k: u32) -> [u16; 3] {
        [
            (k.wrapping_mul(0x9E37).wrapping_add(0x1234)) as u16,
            (k.wrapping_mul(0x7F4B).wrapping_add(0x4321)) as u16,
            (k.wrapping_mul(0x3C6F).wrapping_add(0x0F0F)) as u16,
        ]
    }

    /// The `k` whose X is `x` ([`e2e_positions`]): the inverse of the odd factor
    /// modulo 2^16 (Newton's iteration, each step doubles the correct low bits).
    fn frame_of_x(x: u16) -> u32 {
        let a: u16 = 0x9E37;
        let mut inv = a;
        for _ in 0..4 {
            inv = inv.wrapping_mul(2u16.wrapping_sub(a.wrapping_mul(inv)));
        }
        u32::from(x.wrapping_sub(0x1234).wrapping_mul(inv))
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
        /// First and last frame number seen.
        first: Option<u32>,
        last: Option<u32>,
        /// Frames seen for the first time, repeats of the last one, steps back.
        distinct: u32,
        repeats: u32,
        backwards: u32,
        /// Largest step between two distinct frames.
        max_step: u32,
        /// The frame with the flipped parity bit was seen.
        bad_seen: bool,
        /// Park periods; of them before the first frame; frames after a park.
        park: u32,
        park_before_first: u32,
        frames_after_park: u32,
    }

    /// The whole bridge through its own tasks, for the baked default pairing
    /// (`bridge.toml`: XY2-100 controller -> XY3-100 head, 16 -> 20 bits, axis map
    /// identity, Z from the input, free-running at 100 kHz): the firmware's `app`
    /// functions spawn the supervisor (watchdog, laser gate), LEDs and statistics,
    /// `line::xy2_in` and `bridge_wave_out` in the line executor, the STATUS level
    /// and head backchannel tasks, as `app::spawn_bridge` does for this pairing.
    /// [`Xy2Source`] plays 30 000 frames from `shared::xy2::tx` into the
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
        use shared::bridge::{AfterHold, Timing, ZSource};
        use shared::model::Axis;
        use xy_bridge::app::{self, Executors};
        use xy_bridge::config::{self, Controller, Head, Roles};
        const N: u32 = 30_000;
        const BAD: u32 = 12_345;
        const CHUNK: usize = xy3::rx::WINDOW / 2;

        // The baked configuration this test is written for.
        let config = config::load().unwrap();
        let roles = Roles::of(&config);
        assert_eq!(
            roles,
            Roles {
                controller: Controller::Xy2,
                head: Head::Xy3
            },
            "build the HIL with the default bridge.toml (README, HIL)"
        );
        let a = config.axes;
        assert!(
            !a.swap_xy && !a.invert_x && !a.invert_y && !a.invert_z,
            "axis map"
        );
        assert_eq!((a.offset_x, a.offset_y, a.offset_z), (0, 0, 0), "offsets");
        assert_eq!(config.z.source, ZSource::Input);
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
        let mut source = Xy2Source::start(
            hb.tx_dma,
            dma_ring!(".sram1", u32, 2 * SRC_FRAMES * SRC_TPF),
            tx.idle_word(),
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
        app::controller_xy2(spawner, ex, &config, r.xy2_in, r.ctrl_status, r.back.de);
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
        let pf = pac::GPIOF;
        let t0 = Instant::now();
        while pf.odr().read().odr(11) != pac::gpio::vals::Odr::HIGH {
            assert!(
                t0.elapsed() < Duration::from_millis(100),
                "head drivers never enabled"
            );
            embassy_time::Timer::after_micros(100).await;
        }
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
        // Head side read back, started now that the head's lines idle (SYNC high,
        // CLK low; before, the unconfigured pins floated): SPI3 (X), SPI4 (Y), SPI5
        // (Z) slaves selected by the head's SYNC, and the SYNC marks, whose every
        // rising edge from here is a frame end.
        let i = r.xy3_in;
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

        let gate_high = || pf.idr().read().idr(board::LASER_GATE_PIN) == pac::gpio::vals::Idr::HIGH;
        let status =
            || status_level.health(pac::GPIOA.idr().read().idr(0) == pac::gpio::vals::Idr::HIGH);

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
            // Two idle halves: once both are queued the last frame has played (the
            // ring holds one lap of written words at most) and the ring holds
            // nothing but idle.
            phase.set(2);
            half.fill(tx.idle_word());
            for _ in 0..2 {
                if !source.write(&half).await {
                    underrun.set(true);
                }
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
        #[derive(Default, Debug, defmt::Format)]
        struct Levels {
            gate_before: u32,
            status_before: u32,
            gate_on_after_us: Option<u64>,
            gate_drops: u32,
            status_ok_after_us: Option<u64>,
            status_drops: u32,
            gate_late: u32,
            status_late: u32,
            samples_after: u32,
        }
        let mut lv = Levels::default();
        let sampler = async {
            loop {
                let p = phase.get();
                let (g, st) = (gate_high(), status());
                match p {
                    0 => {
                        lv.gate_before += u32::from(g);
                        lv.status_before += u32::from(st == Health::Ok);
                    }
                    1 => {
                        let t = input_at.get().elapsed().as_micros();
                        match (lv.gate_on_after_us, g) {
                            (None, true) => lv.gate_on_after_us = Some(t),
                            (Some(_), false) => lv.gate_drops += 1,
                            _ => {}
                        }
                        match (lv.status_ok_after_us, st == Health::Ok) {
                            (None, true) => lv.status_ok_after_us = Some(t),
                            (Some(_), false) => lv.status_drops += 1,
                            _ => {}
                        }
                    }
                    2 => {
                        let Some(t) = stop_at.get().map(|t: Instant| t.elapsed()) else {
                            embassy_time::Timer::after_micros(100).await;
                            continue;
                        };
                        lv.samples_after += 1;
                        if t > Duration::from_millis(6) && g {
                            lv.gate_late += 1;
                        }
                        if t > Duration::from_millis(250) && st == Health::Ok {
                            lv.status_late += 1;
                        }
                    }
                    _ => break,
                }
                embassy_time::Timer::after_micros(100).await;
            }
        };

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
                        log.park += 1;
                        log.park_before_first += u32::from(log.first.is_none());
                        continue;
                    }
                    let k = frame_of_x((v[0] >> 4) as u16);
                    if k >= N || head_of(k) != v {
                        log.unknown += 1;
                        continue;
                    }
                    log.frames_after_park += u32::from(log.park > 0);
                    log.bad_seen |= k == BAD;
                    log.first.get_or_insert(k);
                    match log.last {
                        Some(last) if k == last => log.repeats += 1,
                        Some(last) if k < last => log.backwards += 1,
                        Some(last) => {
                            log.distinct += 1;
                            log.max_step = log.max_step.max(k - last);
                        }
                        None => log.distinct += 1,
                    }
                    log.last = Some(log.last.map_or(k, |l| l.max(k)));
                }
            }
        };
        let deadline = async {
            while phase.get() < 3 {
                embassy_time::Timer::after_millis(1).await;
            }
            embassy_time::Timer::after_millis(50).await;
        };
        let reader = async { matches!(select(reader, deadline).await, Either::First(())) };
        let (_, _, _, read_to_the_end) =
            embassy_futures::join::join4(source_run, head_sim, sampler, reader).await;
        drop(source);
        defmt::info!("head: {}", log);
        defmt::info!("levels: {}", lv);

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
        assert!(
            !log.bad_seen,
            "the frame with a flipped parity bit reached the head"
        );
        assert_eq!(log.backwards, 0, "frames out of order");
        assert_eq!(log.park_before_first, 0, "park before the first frame");
        assert_eq!(log.frames_after_park, 0, "frames after the park");
        let first = log.first.expect("no frame reached the head");
        assert!(
            (recovery - 1..recovery + 10).contains(&first),
            "first frame {}",
            first
        );
        assert!(
            log.last.is_some_and(|l| l + 4 >= N - 1),
            "last frame {:?}",
            log.last
        );
        assert!(log.max_step <= 4, "a step of {} frames", log.max_step);
        assert!(
            log.distinct >= (N - recovery) * 6 / 10,
            "{} distinct frames",
            log.distinct
        );
        assert!(log.park >= 1000, "{} park periods", log.park);
        // The laser gate and the STATUS towards the controller.
        assert_eq!(lv.gate_before, 0, "gate on before the input");
        assert_eq!(lv.status_before, 0, "STATUS OK before the input");
        let on = lv.gate_on_after_us.expect("gate never on");
        assert!(on < 10_000, "gate on {} us after the input", on);
        assert_eq!(lv.gate_drops, 0, "gate off while the input runs");
        let ok = lv.status_ok_after_us.expect("STATUS never OK");
        assert!(ok < 200_000, "STATUS OK {} us after the input", ok);
        assert_eq!(lv.status_drops, 0, "STATUS fault while the input runs");
        assert!(
            lv.samples_after > 1000,
            "{} samples after the input",
            lv.samples_after
        );
        assert_eq!(
            lv.gate_late, 0,
            "gate still on 6 ms after the input stopped"
        );
        assert_eq!(
            lv.status_late, 0,
            "STATUS still OK 250 ms after the input stopped"
        );
        assert!(!gate_high(), "gate on at the end");
    }

    /// The laser gate after `board::init` (no jumpers): PF13 must be an output
    /// (MODER), written low (ODR) and low at the pad (IDR: the input stage reads
    /// the pin in output mode too), and `Board::laser_gate` must say so. The test
    /// never drives the gate high: a board with its transceivers fitted may have a
    /// laser behind it.
    #[test]
    fn laser_gate_is_off_after_init(board: Board) {
        use pac::gpio::vals::{Idr, Moder, Odr};
        let pin = board::LASER_GATE_PIN;
        let port = pac::GPIOF;
        assert_eq!(
            port.moder().read().moder(pin),
            Moder::OUTPUT,
            "PF13 not driven"
        );
        assert_eq!(port.odr().read().odr(pin), Odr::LOW, "PF13 written high");
        assert_eq!(port.idr().read().idr(pin), Idr::LOW, "PF13 high at the pad");
        assert!(board.laser_gate.is_set_low());
    }

    /// Hot code in ITCM (no jumpers; firmware/tcm.rs, `memory.x`). `__pre_init`
    /// copied `.itcm` from flash before `main`: the running image must equal its load
    /// image byte for byte, `hans::Frame::decode` (a per-frame `shared::hans::frame`
    /// function, which the linker script puts there) must have its address in
    /// `.itcm`, not in flash, and calls through that address must run: a frame's
    /// pattern decodes to the frame, the pattern with one bit flipped is refused.
    /// `HansRx::new`, a constructor, is kept in flash as cold code (`.flash_cold`).
    #[test]
    fn itcm_holds_the_hot_code(_board: Board) {
        let itcm = xy_bridge::tcm::itcm();
        assert!(itcm.start > 0 && itcm.start < itcm.end && itcm.end <= 0x1_0000);
        let (run, load) = xy_bridge::tcm::itcm_load_image();
        let differ = run.iter().zip(load).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "ITCM bytes that differ from the flash image");
        let decode: fn(u128) -> Result<Frame, _> = Frame::decode;
        let addr = decode as usize & !1;
        assert!(
            itcm.contains(&addr),
            "hans::Frame::decode at {:#x}, not in ITCM",
            addr
        );
        let frame = Frame::new(0x1_2345, 0xF_EDCB, 0x5_A5A5).unwrap();
        assert_eq!(decode(frame.encode()), Ok(frame));
        assert!(decode(frame.encode() ^ 1 << 60).is_err());
        let new: fn(u32, HansMode) -> Result<HansRx, _> = HansRx::new;
        assert!(
            !itcm.contains(&(new as usize & !1)),
            "HansRx::new (cold) in ITCM"
        );
    }
}
