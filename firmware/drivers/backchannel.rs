//! XY3-100 backchannel UARTs (RS-485, `layouts.md` §6; XY3-100 §6): DMA transmit
//! with a hardware-timed driver enable towards the controller, ring-buffered DMA
//! receive from the head, runtime baud change on each.
//!
//! embassy-stm32 0.6 covers all of it, so this file only fixes the configuration and
//! documents the choices (no register code of our own):
//! * `Uart::new_with_de` puts the USART's DE function on the DE pin: the USART itself
//!   raises DE before the start bit and drops it after the last stop bit
//!   (CR3.DEM = 1, CR1.DEAT / DEDT, RM0433 §48.4, "RS232 hardware flow control and
//!   RS485 driver enable"), so no software timing is involved.
//! * `UartRx::into_ring_buffered` runs the receive DMA stream circularly into our ring
//!   (embassy's `RingBufferedUartRx`): bytes are never lost between reads.
//! * `set_baudrate` rewrites USART_BRR (§48.7) at run time (XY3-100 §6 lets the
//!   controller change the backchannel rate by command).
//!
//! Board (README.md, section "Firmware"): one UART per side, so each side runs at its
//! own rate. UART7 TX + DE drive the controller-side pair-6 RS-485 driver (the
//! controller only listens on pair 6, so UART7's receiver is not wired; embassy has
//! no transmit-only constructor with DE, so it is built duplex and its receiver
//! dropped). USART2 RX listens to the head-side pair-6 receiver (the head only
//! talks; its TX pin serves the HIL loop-back test only).
//!
//! embassy 0.6 quirk found while reading it: `configure` writes CR1.DEDT from
//! `de_assertion_time` (not `de_deassertion_time`); we set both to the same value so the
//! result is what we asked for either way.

use embassy_stm32::mode::Async;
use embassy_stm32::usart::{Config, RingBufferedUartRx, Uart, UartRx, UartTx};

/// Driver-enable lead and tail time in 1/16 bit: the transceiver needs its enable a
/// moment before the start bit, and must not cut off the last stop bit.
const DE_TIME_SIXTEENTHS: u8 = 8;

/// The UART configuration for a baud rate (8N1, XY3-100 §6).
pub fn config(baud: u32) -> Config {
    let mut c = Config::default();
    c.baudrate = baud;
    c.de_assertion_time = DE_TIME_SIXTEENTHS;
    c.de_deassertion_time = DE_TIME_SIXTEENTHS;
    c
}

/// The controller-side transmitter of a UART built with `Uart::new_with_de` (its
/// receiver is dropped: nothing is wired to it).
pub fn controller_tx(uart: Uart<'_, Async>) -> UartTx<'_, Async> {
    let (tx, _rx) = uart.split();
    tx
}

/// The head-side receiver, receiving into `ring` from now on.
pub fn head_rx<'d>(rx: UartRx<'d, Async>, ring: &'d mut [u8]) -> RingBufferedUartRx<'d> {
    let mut rx = rx.into_ring_buffered(ring);
    rx.start_uart();
    rx
}
