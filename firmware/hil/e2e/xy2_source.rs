//! The XY2-100 controller the end-to-end tests play into the controller-side XY2
//! input, the frame numbering they check the head against, and the watch on the
//! laser gate and the STATUS level towards that controller.

use core::cell::Cell;

use embassy_stm32::gpio::{AnyPin, Level, Output, Speed};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::UpDma;
use embassy_stm32::{dma, pac, peripherals, Peri};
use embassy_time::{Duration, Instant};
use shared::xy2;
use shared::xy2::{Health, StatusLevel};
use xy_bridge::board;
use xy_bridge::drivers::wave_out::timing_critical;
use xy_bridge::tasks::Irqs;

/// Ticks per frame and tick rate of the XY2-100 source ([`Xy2Source`]): 100 kHz
/// frames at a 2 MHz clock, as a controller sends them.
pub(super) const SRC_TPF: usize = 40;
const SRC_TICK_HZ: u32 = 4_000_000;
/// Frames per half of the source's ring (0.5 ms).
pub(super) const SRC_FRAMES: usize = 50;

/// A test-only XY2-100 controller: TIM4's update event requests one DMA1 stream 6
/// transfer per tick (DMAMUX request TIM4_UP) that writes the next word of a
/// circular ring into GPIOE's BSRR, as `WaveOut` does on TIM8 for the head side
/// (TIM4 is free in every pairing, and `WaveOut` is built for TIM1 / TIM8 only;
/// register sequence: RM0433 "General-purpose timers", time-base unit and
/// TIMx_DIER.UDE). Words from `shared::xy2::tx` on PE2 (CLK), PE3 (SYNC), PE4
/// (X), PE9 (Y), PE10 (Z).
pub(super) struct Xy2Source {
    timer: Timer<'static, peripherals::TIM4>,
    ring: dma::WritableRingBuffer<'static, u32>,
    /// The five pins, kept outputs.
    _pins: [Output<'static>; 5],
}

/// The source's port-E pins, in `OutPinMap` order.
pub(super) const SRC_PINS: xy2::tx::OutPinMap = xy2::tx::OutPinMap {
    clk: 2,
    sync: 3,
    x: 4,
    y: 9,
    z: Some(10),
};

impl Xy2Source {
    /// Starts playing `idle` from the ring (no clock edges until frames are
    /// written).
    pub(super) fn start(
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
    pub(super) async fn write(&mut self, words: &[u32]) -> bool {
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
pub(super) fn e2e_positions(k: u32) -> [u16; 3] {
    [
        (k.wrapping_mul(0x9E37).wrapping_add(0x1234)) as u16,
        (k.wrapping_mul(0x7F4B).wrapping_add(0x4321)) as u16,
        (k.wrapping_mul(0x3C6F).wrapping_add(0x0F0F)) as u16,
    ]
}

/// The `k` whose X is `x` ([`e2e_positions`]): the inverse of the odd factor
/// modulo 2^16 (Newton's iteration, each step doubles the correct low bits).
pub(super) fn frame_of_x(x: u16) -> u32 {
    let a: u16 = 0x9E37;
    let mut inv = a;
    for _ in 0..4 {
        inv = inv.wrapping_mul(2u16.wrapping_sub(a.wrapping_mul(inv)));
    }
    u32::from(x.wrapping_sub(0x1234).wrapping_mul(inv))
}

/// The laser gate (PF13 pad) and the XY2-100 STATUS level towards the controller
/// (PA0), sampled every 100 us through an end-to-end run: violations counted per
/// phase.
#[derive(Default, Debug, defmt::Format)]
pub(super) struct Levels {
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

impl Levels {
    /// Samples until `phase` reaches 3. Phases, set by the run's source: 0 before
    /// the input, 1 from `input_at` while frames are written, 2 once the last one
    /// is written (from `stop_at`, once set: the last frame played).
    pub(super) async fn watch(
        &mut self,
        phase: &Cell<u8>,
        input_at: &Cell<Instant>,
        stop_at: &Cell<Option<Instant>>,
        level: StatusLevel,
    ) {
        let gate_high =
            || pac::GPIOF.idr().read().idr(board::LASER_GATE_PIN) == pac::gpio::vals::Idr::HIGH;
        let status = || level.health(pac::GPIOA.idr().read().idr(0) == pac::gpio::vals::Idr::HIGH);
        loop {
            let (g, ok) = (gate_high(), status() == Health::Ok);
            match phase.get() {
                0 => {
                    self.gate_before += u32::from(g);
                    self.status_before += u32::from(ok);
                }
                1 => {
                    let t = input_at.get().elapsed().as_micros();
                    match (self.gate_on_after_us, g) {
                        (None, true) => self.gate_on_after_us = Some(t),
                        (Some(_), false) => self.gate_drops += 1,
                        _ => {}
                    }
                    match (self.status_ok_after_us, ok) {
                        (None, true) => self.status_ok_after_us = Some(t),
                        (Some(_), false) => self.status_drops += 1,
                        _ => {}
                    }
                }
                2 => {
                    if let Some(t) = stop_at.get().map(|t| t.elapsed()) {
                        self.samples_after += 1;
                        if t > Duration::from_millis(6) && g {
                            self.gate_late += 1;
                        }
                        if t > Duration::from_millis(250) && ok {
                            self.status_late += 1;
                        }
                    }
                }
                _ => break,
            }
            embassy_time::Timer::after_micros(100).await;
        }
    }

    /// The gate off before the input, on within 10 ms of it and until it stops,
    /// off within 6 ms after; the STATUS "fault" before, "OK" within 200 ms of the
    /// input and until it stops, "fault" again within 250 ms after.
    pub(super) fn check(&self) {
        defmt::info!("levels: {}", self);
        assert_eq!(self.gate_before, 0, "gate on before the input");
        assert_eq!(self.status_before, 0, "STATUS OK before the input");
        let on = self.gate_on_after_us.expect("gate never on");
        assert!(on < 10_000, "gate on {} us after the input", on);
        assert_eq!(self.gate_drops, 0, "gate off while the input runs");
        let ok = self.status_ok_after_us.expect("STATUS never OK");
        assert!(ok < 200_000, "STATUS OK {} us after the input", ok);
        assert_eq!(self.status_drops, 0, "STATUS fault while the input runs");
        assert!(
            self.samples_after > 1000,
            "{} samples after the input",
            self.samples_after
        );
        assert_eq!(
            self.gate_late, 0,
            "gate still on 6 ms after the input stopped"
        );
        assert_eq!(
            self.status_late, 0,
            "STATUS still OK 250 ms after the input stopped"
        );
    }
}
