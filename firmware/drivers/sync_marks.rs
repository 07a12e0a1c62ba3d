//! XY3-100 frame-end marks (`layouts.md` §2): the SYNC (= NSS) rising edge ends a
//! frame; an EXTI interrupt records where in the X ring that edge fell, so the decoder
//! can spot truncated / extended frames and realign after a glitch.
//!
//! The interrupt handler only reads the X stream's remaining-transfer counter
//! (DMA_SxNDTR, RM0433 §15.5.6) and pushes the ring index `len - NDTR` into a small
//! lock-free single-producer / single-consumer queue. The consumer (the task that reads
//! the X ring) turns indices into the monotonic byte counts the decoder wants with
//! [`SyncMarks::drain`]: it knows its own monotonic read count, and every mark lies
//! within one ring length ahead of the last index it consumed as long as the ring did
//! not overrun (which the ring reader reports separately). This avoids hooking
//! embassy's DMA interrupt to count laps.
//!
//! Register sequence (RM0433 §20 "Extended interrupt and event controller"):
//! 1. SYSCFG_EXTICRx routes the pin's port to the EXTI line, EXTI_RTSR1 selects the
//!    rising edge, EXTI_CPUIMR1 unmasks the line (§20 registers, done by embassy's
//!    `ExtiInput::new_blocking`);
//! 2. the NVIC line is enabled here with our own handler bound through
//!    `bind_interrupts!` ([`SyncEdgeHandler`]), which clears EXTI_CPUPR1 (§20 registers,
//!    write 1 to clear) and records the mark.
//!
//! Why not `heapless::spsc`: its producer half must be stored somewhere the ISR can
//! reach, which needs a `static` behind a lock or `static mut`; eight atomics do the
//! job with no unsafe at all.

use core::sync::atomic::{AtomicU16, AtomicU32, AtomicU8, Ordering};

use embassy_stm32::exti::{ExtiInput, TriggerEdge};
use embassy_stm32::gpio::Pull;
use embassy_stm32::interrupt::typelevel::{Handler, Interrupt, EXTI4};
use embassy_stm32::mode::Blocking;
use embassy_stm32::peripherals::{EXTI4 as EXTI4_CH, PA4};
use embassy_stm32::{pac, Peri};

use super::ring_index;

/// Queue depth: a frame is 3..4 bytes, so a drain per 64-byte X half (the firmware's
/// input task) finds at most 22 marks; 256 leaves room for a reader that is late by
/// several halves (a test draining a whole 512-byte ring at once finds up to 171).
const DEPTH: usize = 256;

/// The X data line's DMA stream (board allocation: SPI3 RX on DMA1 stream 0).
const X_STREAM: usize = 0;

/// Ring indices of SYNC rising edges, written by the ISR, read by [`SyncMarks`].
static QUEUE: [AtomicU16; DEPTH] = [const { AtomicU16::new(0) }; DEPTH];
/// Next slot the ISR writes (wrapping u8 index into a power-of-two queue).
static HEAD: AtomicU8 = AtomicU8::new(0);
/// Next slot the consumer reads.
static TAIL: AtomicU8 = AtomicU8::new(0);
/// X ring length in words; 0 = not armed (the ISR then records nothing).
static RING_LEN: AtomicU16 = AtomicU16::new(0);
/// Marks dropped because the queue was full (statistics).
static DROPPED: AtomicU32 = AtomicU32::new(0);

const _: () = assert!(DEPTH == 256, "HEAD/TAIL are u8 indices");

/// The EXTI4 handler: clears the pending bit and queues the X ring index.
pub struct SyncEdgeHandler;

impl Handler<EXTI4> for SyncEdgeHandler {
    unsafe fn on_interrupt() {
        pac::EXTI.pr(0).write(|w| w.set_line(4, true));
        let len = RING_LEN.load(Ordering::Relaxed);
        if len == 0 {
            return;
        }
        let ndtr = pac::DMA1.st(X_STREAM).ndtr().read().ndt();
        // The index of the next word (len <= u16::MAX: it fits back).
        let index = ring_index(usize::from(ndtr), usize::from(len)) as u16;
        let head = HEAD.load(Ordering::Relaxed);
        if head.wrapping_add(1) == TAIL.load(Ordering::Acquire) {
            DROPPED.fetch_add(1, Ordering::Relaxed);
            return;
        }
        QUEUE[usize::from(head)].store(index, Ordering::Relaxed);
        HEAD.store(head.wrapping_add(1), Ordering::Release);
    }
}

/// Armed SYNC edge capture; dropping it disarms the handler.
pub struct SyncMarks<'d> {
    _pin: ExtiInput<'d, Blocking>,
    len: u16,
    /// Ring index of the previous drained mark (or of the reader's position).
    last_index: u16,
    /// Monotonic count matching `last_index`.
    last_total: u32,
}

impl<'d> SyncMarks<'d> {
    /// Arms capture of SYNC rising edges on `PA4` for an X ring of `ring_len` words
    /// (must match the ring given to the X `SpiSlaveRx`, started at the same time).
    pub fn new(
        pin: Peri<'d, PA4>,
        ch: Peri<'d, EXTI4_CH>,
        _irq: impl embassy_stm32::interrupt::typelevel::Binding<EXTI4, SyncEdgeHandler> + 'd,
        ring_len: u16,
    ) -> Self {
        HEAD.store(0, Ordering::Relaxed);
        TAIL.store(0, Ordering::Relaxed);
        RING_LEN.store(ring_len, Ordering::Release);
        let pin = ExtiInput::new_blocking(pin, ch, Pull::None, TriggerEdge::Rising);
        EXTI4::unpend();
        // SAFETY: the handler bound for EXTI4 is `SyncEdgeHandler`, which touches only
        // atomics and two registers it owns (EXTI4 pending bit, a DMA counter read).
        unsafe { EXTI4::enable() };
        Self {
            _pin: pin,
            len: ring_len,
            last_index: 0,
            last_total: 0,
        }
    }

    /// Moves every queued mark into `out` as a monotonic X-ring byte count (total
    /// bytes received when the edge came); returns how many were written. Marks that
    /// do not fit stay queued.
    pub fn drain(&mut self, out: &mut [u32]) -> usize {
        let mut n = 0;
        let head = HEAD.load(Ordering::Acquire);
        let mut tail = TAIL.load(Ordering::Relaxed);
        for slot in out.iter_mut() {
            if tail == head {
                break;
            }
            let index = QUEUE[usize::from(tail)].load(Ordering::Relaxed);
            // Distance forward from the previous mark, modulo the ring.
            let len = u32::from(self.len);
            let step = (u32::from(index) + len - u32::from(self.last_index)) % len;
            self.last_total = self.last_total.wrapping_add(step);
            self.last_index = index;
            *slot = self.last_total;
            tail = tail.wrapping_add(1);
            n += 1;
        }
        TAIL.store(tail, Ordering::Release);
        n
    }

    /// Marks lost because the queue was full.
    pub fn dropped(&self) -> u32 {
        DROPPED.load(Ordering::Relaxed)
    }
}

impl Drop for SyncMarks<'_> {
    fn drop(&mut self) {
        EXTI4::disable();
        RING_LEN.store(0, Ordering::Release);
    }
}
