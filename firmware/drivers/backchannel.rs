//! XY3-100 backchannel UART (RS-485, `layouts.md` §6; XY3-100 §6): DMA transmit with a
//! hardware-timed driver enable, ring-buffered DMA receive, runtime baud change.
//!
//! embassy-stm32 0.6 covers all of it, so this file only fixes the configuration and
//! documents the choices (no register code of our own):
//! * `Uart::new_with_de` puts the USART's DE function on the DE pin: the USART itself
//!   raises DE before the start bit and drops it after the last stop bit
//!   (CR3.DEM = 1, CR1.DEAT / DEDT, RM0433 §53.5.20 "RS232 hardware flow control and
//!   RS485 driver enable"), so no software timing is involved.
//! * `UartRx::into_ring_buffered` runs the receive DMA stream circularly into our ring
//!   (embassy's `RingBufferedUartRx`): bytes are never lost between reads.
//! * `set_baudrate` rewrites USART_BRR (§53.5.7) at run time (XY3-100 §6 lets the
//!   controller change the backchannel rate by command).
//!
//! Board: one UART7 serves both sides (README.md (section "Firmware")): TX + DE drive the
//! controller-side pair-6 RS-485 driver, RX listens to the head-side pair-6 receiver.
//! Both directions therefore share one baud rate.
//!
//! embassy 0.6 quirk found while reading it: `configure` writes CR1.DEDT from
//! `de_assertion_time` (not `de_deassertion_time`); we set both to the same value so the
//! result is what we asked for either way.

use embassy_stm32::mode::Async;
use embassy_stm32::usart::{Config, ConfigError, RingBufferedUartRx, Uart, UartRx, UartTx};

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

/// Transmit and receive halves of the running backchannel; a side that does not
/// speak XY3-100 leaves its half out.
pub struct Backchannel<'d> {
    /// DMA transmitter (DE handled by hardware): controller side is XY3-100.
    pub tx: Option<UartTx<'d, Async>>,
    /// Ring-buffered DMA receiver: head side is XY3-100.
    pub rx: Option<RingBufferedUartRx<'d>>,
}

impl<'d> Backchannel<'d> {
    /// Splits a UART built with `Uart::new_with_de`; with `receive`, starts ring
    /// reception into `ring`, else drops the receiver (the head-side pair 6 then
    /// carries another protocol's STATUS).
    pub fn duplex(uart: Uart<'d, Async>, ring: &'d mut [u8], receive: bool) -> Self {
        let (tx, rx) = uart.split();
        Self {
            tx: Some(tx),
            rx: receive.then(|| start(rx.into_ring_buffered(ring))),
        }
    }

    /// Receiver only (controller side is not XY3-100, so the DE pin is not the
    /// UART's and TX stays unused).
    pub fn receive_only(rx: UartRx<'d, Async>, ring: &'d mut [u8]) -> Self {
        Self {
            tx: None,
            rx: Some(start(rx.into_ring_buffered(ring))),
        }
    }

    /// Changes the baud rate of both directions (they share USART_BRR).
    pub fn set_baud(&mut self, baud: u32) -> Result<(), ConfigError> {
        match (&self.rx, &self.tx) {
            (Some(rx), _) => rx.set_baudrate(baud),
            (None, Some(tx)) => tx.set_baudrate(baud),
            (None, None) => Ok(()),
        }
    }
}

fn start(mut rx: RingBufferedUartRx<'_>) -> RingBufferedUartRx<'_> {
    rx.start_uart();
    rx
}
