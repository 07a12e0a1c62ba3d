//! XY2-100 STATUS from the head: the word (`StatusWordReceiver` on the TIM8 CC1
//! samples), its realignment after an underrun, and the STATUS level.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::{level, ALL_LOW, P1, P4, WAIT};
    use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
    use embassy_stm32::{pac, peripherals};
    use embassy_time::with_timeout;
    use shared::model::Alarms;
    use shared::xy2::status_line::{StatusWordConfig, StatusWordReceiver};
    use shared::xy2::{Health, LinkConfig, Mode, Parity, StatusError, StatusLevel, StatusWord};
    use xy_bridge::board::{self, Board};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::status_level::{StatusIn, StatusOut};
    use xy_bridge::drivers::wave_out::WaveOut;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
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
    /// frames must come back) the writer stops for 2 ms, so the DMA runs past them
    /// (the ring guard sets the halves idle: `wave_out` "No stale words") and the
    /// status ring overruns too. `write_half` must report the underrun (that batch is dropped), the next
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
        // back (the last one's last bit is sampled from the idle words after it,
        // which may end it differently).
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
}
