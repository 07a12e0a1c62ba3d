//! XY2-100 head output (`WaveOut`) -> controller input (`Xy2Sampler`): bits, frames,
//! idle slots, and the STATUS word towards the controller.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::{level, Prng, ALL_LOW, P1, P2, P3, WAIT};
    use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
    use embassy_stm32::pac;
    use embassy_time::with_timeout;
    use shared::head_port;
    use shared::model::Alarms;
    use shared::xy2::rx::{Event as Xy2Event, PinMap, Receiver as Xy2Receiver};
    use shared::xy2::status_line::{StatusOut as WordOut, StatusWordConfig, StatusWordReceiver};
    use shared::xy2::tx::Transmitter as Xy2Tx;
    use shared::xy2::{
        encode as xy2_encode, Frame as Frame2, LinkConfig, Mode, Parity, StatusError, StatusLevel,
        StatusWord,
    };
    use xy_bridge::board::{self, Board};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::status_word_out::{StatusWordOut, FRAME_BITS};
    use xy_bridge::drivers::wave_out::WaveOut;
    use xy_bridge::drivers::xy2_sampler::Xy2Sampler;
    use xy_bridge::tasks::Irqs;

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
}
