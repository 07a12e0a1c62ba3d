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
    use embassy_stm32::gpio::{AfType, Flex, Input, Level, Output, OutputType, Pull, Speed};
    use embassy_stm32::peripherals::PA15;
    use embassy_stm32::usart::Uart;
    use embassy_stm32::{bind_interrupts, dma, pac, peripherals, usart, Peri};
    use embassy_time::{with_timeout, Duration};
    use shared::hans::frame::{write_slot, Frame, RING_BYTES};
    use shared::model::Alarms;
    use shared::xy2::status_line::{StatusWordConfig, StatusWordReceiver};
    use shared::xy2::{Health, LinkConfig, Mode, Parity, StatusError, StatusLevel, StatusWord};
    use shared::xy3::back::{Event, Packet, Parser, Sender, SEND_BUF_LEN};
    use xy_bridge::board::{self, Board};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::backchannel::{self, Backchannel};
    use xy_bridge::drivers::serial_tx::SerialTx;
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    use xy_bridge::drivers::status_level::{StatusIn, StatusOut};
    use xy_bridge::drivers::sync_marks::{SyncEdgeHandler, SyncMarks};
    use xy_bridge::drivers::wave_out::WaveOut;
    use xy_bridge::drivers::xy2_sampler::Xy2Sampler;

    use super::Prng;

    bind_interrupts!(struct Irqs {
        DMA1_STREAM0 => dma::InterruptHandler<peripherals::DMA1_CH0>;
        DMA2_STREAM0 => dma::InterruptHandler<peripherals::DMA2_CH0>;
        DMA2_STREAM1 => dma::InterruptHandler<peripherals::DMA2_CH1>;
        DMA2_STREAM2 => dma::InterruptHandler<peripherals::DMA2_CH2>;
        DMA2_STREAM3 => dma::InterruptHandler<peripherals::DMA2_CH3>;
        DMA2_STREAM5 => dma::InterruptHandler<peripherals::DMA2_CH5>;
        DMA2_STREAM6 => dma::InterruptHandler<peripherals::DMA2_CH6>;
        EXTI4 => SyncEdgeHandler;
        UART7 => usart::InterruptHandler<peripherals::UART7>;
    });

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

        // Status samples, one per bit (the CLK-high tick), aligned to the first word
        // written: kept sample i must carry bit i's X level, from the first one on.
        embassy_time::Timer::after_micros(20).await;
        let mut samples = [0u16; 8 * BITS];
        let n = out.read_status(&mut samples).unwrap();
        assert!(n >= BITS, "{} status samples", n);
        for (i, s) in samples[..BITS].iter().enumerate() {
            assert_eq!(s >> 1 & 1 == 1, x_bits[i], "status sample {}", i);
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
        const TPF: usize = 40;
        const FRAMES: usize = 25;
        const BATCHES: usize = 4;
        const BAD: usize = 37;
        let r = board.res;
        let w = r.wave;
        let _clk = Output::new(w.pins.p1, Level::Low, Speed::VeryHigh);
        let _status = Output::new(w.pins.p4, Level::Low, Speed::VeryHigh);
        let _status_in = Input::new(r.head_status, Pull::None);
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
        let mut rx = StatusWordReceiver::new(geometry).unwrap();
        let word = |k: usize| StatusWord::from_alarms(Alarms((k as u32).wrapping_mul(7) & 0xF));
        let frame = |k: usize| word(k).to_frame(&link) ^ u32::from(k == BAD);
        let mut got: heapless::Vec<Result<StatusWord, StatusError>, 160> = heapless::Vec::new();
        let mut batch = [0u32; FRAMES * TPF];
        let mut samples = [0u16; 4 * FRAMES * TPF];
        // One batch more than the frames: its idle slots (no clock, STATUS held) let
        // the last frame's last bit be sampled.
        for b in 0..=BATCHES {
            for (f, slot) in batch.chunks_exact_mut(TPF).enumerate() {
                let k = b * FRAMES + f;
                let bits = (k < BATCHES * FRAMES).then(|| frame(k));
                for (i, pair) in slot.chunks_exact_mut(2).enumerate() {
                    pair[0] = level(P1, bits.is_some());
                    let status = bits.map_or(0, |v| level(P4, v >> (19 - i) & 1 == 1));
                    pair[1] = level(P1, false) | status;
                }
            }
            out.write_half(&batch).await.unwrap();
            let n = out.read_status(&mut samples).unwrap();
            rx.feed(&samples[..n], &mut |r| {
                let _ = got.push(r);
            });
        }
        embassy_time::Timer::after_micros(300).await;
        let n = out.read_status(&mut samples).unwrap();
        rx.feed(&samples[..n], &mut |r| {
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
        let mut rx =
            SpiSlaveRx::new(x.spi, x.sck, x.mosi, Some(x.nss), x.dma, Irqs, rx_ring).unwrap();
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
        let mut rx = SpiSlaveRx::new(x.spi, x.sck, x.mosi, no_nss, x.dma, Irqs, rx_ring).unwrap();
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

    /// Backchannel: UART7 TX -> RX. Jumper: PE8 -> PA8. Packets sent with `shared`'s
    /// sender must be parsed back, before and after a baud change.
    #[test]
    async fn backchannel_loopback(board: Board) {
        let b = board.res.back;
        let uart = Uart::new_with_de(
            b.uart,
            b.rx,
            b.tx,
            b.de,
            b.tx_dma,
            b.rx_dma,
            Irqs,
            backchannel::config(115_200),
        )
        .unwrap();
        let ring = dma_ring!(".sram3", u8, 256);
        let mut back = Backchannel::duplex(uart, ring, true);
        let mut sender = Sender::default();
        let mut parser = Parser::default();
        for (round, baud) in [115_200u32, 921_600].into_iter().enumerate() {
            if round > 0 {
                back.set_baud(baud).unwrap();
                sender.note_rate_change();
            }
            let packet = Packet::FrameErrorCount([1, 2, 3, 4, baud]);
            let mut out = [0u8; SEND_BUF_LEN];
            let n = sender.send(0, &packet, &mut out).unwrap();
            back.tx.as_mut().unwrap().write(&out[..n]).await.unwrap();
            let rx = back.rx.as_mut().unwrap();
            let mut buf = [0u8; 64];
            let mut received = false;
            while !received {
                let n = with_timeout(WAIT, rx.read(&mut buf))
                    .await
                    .unwrap()
                    .unwrap();
                for &byte in &buf[..n] {
                    if let Some(Event::Packet(raw)) = parser.push(byte) {
                        if let Ok(p) = Packet::decode(raw.ty, raw.payload) {
                            if p == packet {
                                received = true;
                            }
                        }
                    }
                }
            }
        }
    }

    /// XY2-100 STATUS level: controller-side output -> head-side debounced input.
    /// Jumper: PA0 -> PG9.
    #[test]
    async fn status_level_loopback(board: Board) {
        let r = board.res;
        let setting = StatusLevel::default();
        let mut out = StatusOut::new(Output::new(r.ctrl_status, Level::High, Speed::Low), setting);
        let mut input = StatusIn::new(Input::new(r.head_status, Pull::None), setting);
        for health in [Health::Ok, Health::Fault, Health::Ok] {
            out.set(health);
            let seen = with_timeout(WAIT, input.changed()).await.unwrap();
            assert_eq!(seen, health);
        }
    }
}
