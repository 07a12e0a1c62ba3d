//! XY3-100 head output -> the controller-side XY3-100 input (SPI slaves, SYNC marks).

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::{level, P1, P2, P3, P4, WAIT};
    use embassy_stm32::gpio::{AnyPin, Level, Output, Speed};
    use embassy_stm32::{pac, Peri};
    use embassy_time::with_timeout;
    use shared::xy3;
    use shared::xy3::{Frame as Frame3, FrameSize};
    use xy_bridge::board::{self, Board};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    use xy_bridge::drivers::sync_marks::SyncMarks;
    use xy_bridge::drivers::wave_out::WaveOut;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
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

        let mut idle = [0u32; TPF];
        tx.idle(&mut idle).unwrap();
        // Two batches: each write is one half (the ring guard's unit); the loop
        // below only encodes 20 frames between writes, far within a half (200 us).
        let ring = dma_ring!(".sram1", u32, 2 * 20 * TPF);
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
        // Two batches, one half each (the ring guard's unit).
        let ring = dma_ring!(".sram1", u32, 2 * 20 * TPF);
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
}
