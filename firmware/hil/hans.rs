//! HANS-100: the SAI outputs (head data, STATUS towards the controller) against the
//! SPI inputs (controller channels, head STATUS).

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::WAIT;
    use embassy_stm32::gpio::{AfType, Flex, OutputType, Speed};
    use embassy_stm32::peripherals::PA15;
    use embassy_stm32::peripherals::PG8;
    use embassy_stm32::{peripherals, Peri};
    use embassy_time::{with_timeout, Duration};
    use shared::hans::frame::{write_slot, Frame, RING_BYTES};
    use shared::hans::rx::{HansRx, Mode as HansMode, RxEvent};
    use shared::hans::tx::Transmitter;
    use shared::model::Alarms;
    use shared::model::FaultKind;
    use xy_bridge::board::HANS_FS_HZ;
    use xy_bridge::board::{self, Board};
    use xy_bridge::drivers::hans_lines::HansInput;
    use xy_bridge::drivers::oversample_clock;
    use xy_bridge::drivers::serial_tx::SerialTx;
    use xy_bridge::drivers::spi_slave_rx::SpiSlaveRx;
    use xy_bridge::tasks::Irqs;
    use xy_bridge::{dma_ring, hans_rings};

    #[init]
    fn init() -> Board {
        board::init()
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
}
