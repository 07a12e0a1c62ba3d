//! The test-only controller the end-to-end tests play into the controller-side
//! inputs, and the frame numbering they check the head against.

use embassy_stm32::gpio::{AnyPin, Level, Output, Speed};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::UpDma;
use embassy_stm32::{dma, pac, peripherals, Peri};
use xy_bridge::drivers::wave_out::timing_critical;
use xy_bridge::tasks::Irqs;

/// A test-only controller on port E: TIM4's update event requests one DMA1
/// stream 6 transfer per tick (DMAMUX request TIM4_UP) that writes the next word
/// of a circular ring into GPIOE's BSRR, as `WaveOut` does on TIM8 for the head
/// side (TIM4 is free in every pairing, and `WaveOut` is built for TIM1 / TIM8
/// only; register sequence: RM0433 "General-purpose timers", time-base unit and
/// TIMx_DIER.UDE). Words from `shared::xy2::tx` or `shared::xy3::tx` on PE2, PE3,
/// PE4, PE9, PE10.
pub(super) struct BsrrSource {
    timer: Timer<'static, peripherals::TIM4>,
    ring: dma::WritableRingBuffer<'static, u32>,
    /// The five pins, kept outputs.
    _pins: [Output<'static>; 5],
}

impl BsrrSource {
    /// Starts playing `idle` from the ring at `tick_hz` words a second (no clock
    /// edges until frames are written).
    pub(super) fn start(
        dma: Peri<'static, peripherals::DMA1_CH6>,
        ring: &'static mut [u32],
        idle: u32,
        tick_hz: u32,
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
        assert_eq!(timer_hz % tick_hz, 0, "TIM4 clock {} Hz", timer_hz);
        let regs = timer.regs_gp16();
        regs.psc().write_value(0);
        regs.arr()
            .write(|w| w.set_arr((timer_hz / tick_hz - 1) as u16));
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
        BsrrSource { timer, ring, _pins }
    }

    /// Queues `words` behind what plays; `false`: the DMA ran out of written
    /// words first (it replayed old ones).
    pub(super) async fn write(&mut self, words: &[u32]) -> bool {
        self.ring.write_exact(words).await.is_ok()
    }

    /// Ends the input: queues two halves of `idle` through `half` (once both are
    /// queued the last frame has played, since the ring holds one lap of written
    /// words at most, and the ring holds nothing but idle); `false`: the DMA ran
    /// out of written words first.
    pub(super) async fn finish(&mut self, half: &mut [u32], idle: u32) -> bool {
        half.fill(idle);
        let mut queued = true;
        for _ in 0..2 {
            queued &= self.write(half).await;
        }
        queued
    }
}

impl Drop for BsrrSource {
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
