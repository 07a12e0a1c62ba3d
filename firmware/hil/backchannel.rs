//! The XY3-100 backchannel UARTs and the RS-485 driver enable timing.

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use crate::WAIT;
    use embassy_stm32::gpio::{AfType, Flex, Pull};
    use embassy_stm32::mode::Async;
    use embassy_stm32::pac::timer::vals::FilterValue;
    use embassy_stm32::timer::low_level::{InputCaptureMode, InputTISelection, Timer};
    use embassy_stm32::timer::{self, Ch1, Ch4, Channel as TimChannel, TimerPin};
    use embassy_stm32::usart::{RingBufferedUartRx, Uart, UartTx};
    use embassy_stm32::{dma, pac, peripherals, Peri};
    use embassy_time::{with_timeout, Duration};
    use shared::xy3::back::{Event, Packet, Parser, Sender, SEND_BUF_LEN};
    use xy_bridge::board::{self, Board};
    use xy_bridge::dma_ring;
    use xy_bridge::drivers::backchannel;
    use xy_bridge::tasks::Irqs;

    #[init]
    fn init() -> Board {
        board::init()
    }

    /// Sends `packet` with `shared`'s sender on `tx` and waits until `rx` parses it
    /// back (other bytes, e.g. a resync after a rate change, are skipped).
    async fn packet_crosses(
        tx: &mut UartTx<'static, Async>,
        rx: &mut RingBufferedUartRx<'static>,
        sender: &mut Sender,
        packet: &Packet,
    ) {
        let mut parser = Parser::default();
        let mut out = [0u8; SEND_BUF_LEN];
        let n = sender.send(0, packet, &mut out).unwrap();
        tx.write(&out[..n]).await.unwrap();
        let mut buf = [0u8; 64];
        loop {
            let n = with_timeout(WAIT, rx.read(&mut buf))
                .await
                .unwrap()
                .unwrap();
            for &byte in &buf[..n] {
                if let Some(Event::Packet(raw)) = parser.push(byte) {
                    if Packet::decode(raw.ty, raw.payload).as_ref() == Ok(packet) {
                        return;
                    }
                }
            }
        }
    }

    /// UART7 duplex (TX + DE as the firmware builds it), its TX and ring RX.
    fn uart7(
        b: board::BackRes,
        baud: u32,
    ) -> (UartTx<'static, Async>, RingBufferedUartRx<'static>) {
        let uart = Uart::new_with_de(
            b.uart,
            b.rx,
            b.tx,
            b.de,
            b.tx_dma,
            b.rx_dma,
            Irqs,
            backchannel::config(baud),
        )
        .unwrap();
        let (tx, rx) = uart.split();
        (tx, backchannel::head_rx(rx, dma_ring!(".sram3", u8, 256)))
    }

    /// Backchannel towards the controller: UART7 TX -> RX. Jumper: PE8 -> PA8.
    /// Packets sent with `shared`'s sender must be parsed back, before and after a
    /// baud change.
    #[test]
    async fn backchannel_loopback(board: Board) {
        let (mut tx, mut rx) = uart7(board.res.back, 115_200);
        let mut sender = Sender::default();
        for (round, baud) in [115_200u32, 921_600].into_iter().enumerate() {
            if round > 0 {
                tx.set_baudrate(baud).unwrap();
                sender.note_rate_change();
            }
            let packet = Packet::FrameErrorCount([1, 2, 3, 4, baud]);
            packet_crosses(&mut tx, &mut rx, &mut sender, &packet).await;
        }
    }

    /// The head's backchannel UART (USART2, its own rate) against UART7. Jumpers:
    /// PD5 (USART2 TX) -> PA8 (UART7 RX) and PE8 (UART7 TX) -> PD6 (USART2 RX, the
    /// head-side pair-6 input). Packets cross both ways at 115200 baud; then each
    /// UART is switched through its own handle (`set_baudrate` on one must not be
    /// needed for the other's rate: separate BRRs) to 921600 and they cross again;
    /// at last only USART2 goes back to 115200 and a packet from UART7 (still at
    /// 921600) must not be parsed, the proof that the two rates are independent.
    #[test]
    async fn head_backchannel_loopback(board: Board) {
        let (mut ctrl_tx, mut ctrl_rx) = uart7(board.res.back, 115_200);
        let h = board.res.head_back;
        let head = Uart::new(
            h.uart,
            h.rx,
            h.tx,
            h.tx_dma,
            h.rx_dma,
            Irqs,
            backchannel::config(115_200),
        )
        .unwrap();
        let (mut head_tx, head_rx) = head.split();
        let mut head_rx = backchannel::head_rx(head_rx, dma_ring!(".sram3", u8, 256));
        let mut sender = Sender::default();
        for (round, baud) in [115_200u32, 921_600].into_iter().enumerate() {
            if round > 0 {
                head_rx.set_baudrate(baud).unwrap();
                ctrl_tx.set_baudrate(baud).unwrap();
                sender.note_rate_change();
            }
            let to_head = Packet::FrameErrorCount([round as u32, 0, 0, 0, baud]);
            packet_crosses(&mut ctrl_tx, &mut head_rx, &mut sender, &to_head).await;
            let from_head = Packet::FrameErrorCount([0, round as u32, 0, 0, baud]);
            packet_crosses(&mut head_tx, &mut ctrl_rx, &mut sender, &from_head).await;
        }
        // Rates apart: USART2 back at 115200, UART7 still at 921600.
        head_rx.set_baudrate(115_200).unwrap();
        let mut out = [0u8; SEND_BUF_LEN];
        let packet = Packet::FrameErrorCount([7, 7, 7, 7, 7]);
        let n = sender.send(0, &packet, &mut out).unwrap();
        ctrl_tx.write(&out[..n]).await.unwrap();
        ctrl_tx.flush().await.unwrap();
        let mut parser = Parser::default();
        let mut buf = [0u8; 64];
        // Whatever arrives (framing errors are allowed) never parses as the packet;
        // bounded, in case the receiver reports an error on every read.
        for _ in 0..64 {
            let n = match with_timeout(Duration::from_millis(20), head_rx.read(&mut buf)).await {
                Err(_) => break,
                Ok(r) => r.unwrap_or(0),
            };
            for &byte in &buf[..n] {
                if let Some(Event::Packet(raw)) = parser.push(byte) {
                    assert_ne!(Packet::decode(raw.ty, raw.payload).as_ref(), Ok(&packet));
                }
            }
        }
    }

    /// TIM5 as a 32-bit edge stamper for two pins: CH1 (PA0) and CH4 (PA3) capture
    /// the counter on both edges, and one DMA stream per channel copies each capture
    /// into a buffer (register sequence: RM0433, chapter "General-purpose timers
    /// (TIM2/TIM3/TIM4/TIM5)", input capture mode; TIMx_CCMR1/2, TIMx_CCER,
    /// TIMx_DIER.CCxDE). TIM5 counts the 240 MHz timer clock (200 MHz on revision Y)
    /// undivided, so a capture never wraps (17.9 s).
    struct EdgeCapture {
        timer: Timer<'static, peripherals::TIM5>,
        /// CH1 and CH4 inputs, kept configured.
        pins: [Flex<'static>; 2],
        dma: [dma::Channel<'static>; 2],
        request: [dma::Request; 2],
    }

    /// What one [`EdgeCapture::run`] captured: per channel the level before the
    /// first edge and the number of edges in its buffer.
    struct Captured {
        initial_high: [bool; 2],
        edges: [usize; 2],
    }

    impl EdgeCapture {
        /// The two capture channels in `EdgeCapture`'s order.
        const CHANNELS: [TimChannel; 2] = [TimChannel::Ch1, TimChannel::Ch4];

        fn new(
            tim: Peri<'static, peripherals::TIM5>,
            ch1: Peri<'static, impl TimerPin<peripherals::TIM5, Ch1>>,
            ch4: Peri<'static, impl TimerPin<peripherals::TIM5, Ch4>>,
            ch1_dma: Peri<'static, peripherals::DMA2_CH0>,
            ch4_dma: Peri<'static, peripherals::DMA2_CH7>,
            irq: Irqs,
        ) -> Self {
            // Pulls give a missing jumper a defined level: TX idles high, DE low.
            let (af1, af4) = (ch1.af_num(), ch4.af_num());
            let mut p1 = Flex::new(ch1);
            p1.set_as_af_unchecked(af1, AfType::input(Pull::Up));
            let mut p4 = Flex::new(ch4);
            p4.set_as_af_unchecked(af4, AfType::input(Pull::Down));
            // DMAMUX1 inputs TIM5_CH1 / TIM5_CH4 (RM0433 §17.3.2), from embassy's table.
            let request = [
                <peripherals::DMA2_CH0 as timer::Dma<peripherals::TIM5, Ch1>>::request(&ch1_dma),
                <peripherals::DMA2_CH7 as timer::Dma<peripherals::TIM5, Ch4>>::request(&ch4_dma),
            ];
            let dma = [
                dma::Channel::new(ch1_dma, irq),
                dma::Channel::new(ch4_dma, irq),
            ];
            let timer = Timer::new(tim);
            timer.regs_gp32().psc().write_value(0);
            timer.regs_gp32().arr().write_value(u32::MAX);
            for ch in Self::CHANNELS {
                // CCxS = TIx, a filter of 8 timer clocks (both channels alike, so it
                // delays both the same), no prescaler, both edges (CCxP = CCxNP = 1).
                timer.set_input_ti_selection(ch, InputTISelection::Normal);
                timer.set_input_capture_filter(ch, FilterValue::FCK_INT_N8);
                timer.set_input_capture_prescaler(ch, 0);
                timer.set_input_capture_mode(ch, InputCaptureMode::BothEdges);
            }
            Self {
                timer,
                pins: [p1, p4],
                dma,
                request,
            }
        }

        /// Capture ticks per second.
        fn hz(&self) -> u32 {
            self.timer.get_clock_frequency().0
        }

        /// Captures both pins from counter 0 while `activity` runs: CH1's edge times
        /// into `ch1`, CH4's into `ch4`. A full buffer fails the test (edges lost).
        async fn run(
            &mut self,
            ch1: &mut [u32],
            ch4: &mut [u32],
            activity: impl core::future::Future<Output = ()>,
        ) -> Captured {
            let t = &self.timer;
            t.stop();
            t.reset();
            let lens = [ch1.len(), ch4.len()];
            let [dma1, dma4] = &mut self.dma;
            // Direct mode (the default options): every capture lands in memory at once,
            // so a stopped stream has written all it counted.
            let options = dma::TransferOptions::default();
            // SAFETY: CCR1 / CCR4 are readable 32-bit registers of TIM5, which this
            // struct owns; the buffers outlive the transfers (dropped below).
            let mut transfers = unsafe {
                [
                    dma1.read(self.request[0], t.regs_gp32().ccr(0).as_ptr(), ch1, options),
                    dma4.read(self.request[1], t.regs_gp32().ccr(3).as_ptr(), ch4, options),
                ]
            };
            for ch in Self::CHANNELS {
                t.clear_input_interrupt(ch);
                t.set_cc_dma_enable_state(ch, true);
                t.enable_channel(ch, true);
            }
            let initial_high = [self.pins[0].is_high(), self.pins[1].is_high()];
            t.start();
            activity.await;
            for ch in Self::CHANNELS {
                t.enable_channel(ch, false);
                t.set_cc_dma_enable_state(ch, false);
            }
            t.stop();
            let mut edges = [0; 2];
            for (i, tr) in transfers.iter_mut().enumerate() {
                tr.request_pause();
                while tr.is_running() {}
                let left = tr.get_remaining_transfers() as usize;
                assert!(left > 0, "capture buffer {} full: edges lost", i);
                edges[i] = lens[i] - left;
            }
            Captured {
                initial_high,
                edges,
            }
        }
    }

    /// UART7's DE timing as its registers hold it (RM0433 §48.4 and §48.7, CR1.DEAT / DEDT in
    /// sample times; BRR, PRESC and CR1.OVER8 give the bit time), checked
    /// against what `backchannel::config(baud)` asked for. The register values, not
    /// the request, are what the capture is judged by.
    fn uart7_de_setup(baud: u32, capture_hz: u32) -> shared::rs485::Setup {
        const PRESC_DIV: [u32; 12] = [1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128, 256];
        let u = pac::UART7;
        let cr1 = u.cr1().read();
        let over8 = cr1.over8() == pac::usart::vals::Over8::OVERSAMPLING8;
        let brr = u32::from(u.brr().read().brr());
        // With 8x oversampling BRR[2:0] holds USARTDIV[3:1] (USARTDIV[0] is 0).
        let usartdiv = if over8 {
            (brr & !0xF) | ((brr & 0x7) << 1)
        } else {
            brr
        };
        let presc = PRESC_DIV[usize::from(u.presc().read().prescaler().to_bits())];
        let kernel_hz = embassy_stm32::rcc::frequency::<peripherals::UART7>().0;
        let asked = backchannel::config(baud);
        // embassy halves the times for 8x oversampling (its unit is 1/16 bit).
        let unit = |t: u8| if over8 { t / 2 } else { t };
        assert_eq!(
            cr1.deat(),
            unit(asked.de_assertion_time),
            "DEAT at {}",
            baud
        );
        assert_eq!(
            cr1.dedt(),
            unit(asked.de_deassertion_time),
            "DEDT at {}",
            baud
        );
        let setup = shared::rs485::Setup {
            kernel_hz,
            kernel_clocks_per_bit: usartdiv * presc,
            samples_per_bit: if over8 { 8 } else { 16 },
            lead_samples: u32::from(cr1.deat()),
            tail_samples: u32::from(cr1.dedt()),
            capture_hz,
            // Four UART kernel clocks: the input synchronisers and the skew between
            // the DE and TX outputs.
            tolerance_ns: 40,
        };
        // The bit time is the one asked for, within 0.5 %: embassy picks 16x
        // oversampling for 921600 too, so BRR = 109 clocks (-0.45 %; 8x would give
        // 217 half-clocks, 0.01 %).
        let actual = kernel_hz / setup.kernel_clocks_per_bit;
        assert!(
            actual.abs_diff(baud) * 200 < baud,
            "{} baud for {}",
            actual,
            baud
        );
        setup
    }

    /// RS-485 driver enable of the backchannel towards the controller: UART7 as the
    /// firmware builds it (`Uart::new_with_de`, `backchannel::config`: DE active high,
    /// CR1.DEAT = DEDT = 8 sample times at 16x oversampling, i.e. half a bit: 4.34 us
    /// at 115200 baud, 545 ns at 921600). Jumpers: PE8 (UART7_TX) -> PA0 (TIM5_CH1),
    /// PF8 (UART7_DE) -> PA3 (TIM5_CH4), PD5 (USART2_TX) -> PA8 (UART7_RX). TIM5
    /// stamps every TX and DE edge ([`EdgeCapture`]) while, at 115200 and then (after
    /// `set_baudrate`, as the firmware switches rates) 921600 baud: the line idles,
    /// UART7 sends two packets from `shared`'s sender (the second holds 0x00 and 0xFF
    /// bytes) 300 us apart, and USART2 sends a packet that UART7 must receive.
    /// `shared::rs485::check` then requires, against UART7's registers read back:
    /// TX decodes to exactly the bytes sent, each packet back to back; DE is low at
    /// the start and has exactly one pulse per packet, so it is low while idle and
    /// while receiving; each pulse rises the configured lead before the first start
    /// edge and falls the configured tail after the end of the last stop bit (so it
    /// covers every stop bit), each within [configured - 40 ns, configured + one
    /// sample + 40 ns] (the USART switches DE on its 1/16-bit sample clock).
    #[test]
    async fn backchannel_de_timing(board: Board) {
        let r = board.res;
        let (mut tx, mut rx) = uart7(r.back, 115_200);
        let h = r.head_back;
        let mut head_tx =
            UartTx::new(h.uart, h.tx, h.tx_dma, Irqs, backchannel::config(115_200)).unwrap();
        // SAFETY: neither TIM5 nor PA3 is taken by `board` or any driver (README
        // "Peripheral allocation": TIM5 spare); only this test uses them.
        let (tim5, pa3) = unsafe { (peripherals::TIM5::steal(), peripherals::PA3::steal()) };
        let x = r.xy2_in;
        let mut capture = EdgeCapture::new(tim5, r.ctrl_status, pa3, x.dma, x.status_dma, Irqs);
        let tx_edges = dma_ring!(".sram2", u32, 1024);
        let de_edges = dma_ring!(".sram2", u32, 64);
        let mut sender = Sender::default();
        let mut head_sender = Sender::default();
        for (round, baud) in [115_200u32, 921_600].into_iter().enumerate() {
            if round > 0 {
                tx.set_baudrate(baud).unwrap();
                head_tx.set_baudrate(baud).unwrap();
                sender.note_rate_change();
                head_sender.note_rate_change();
            }
            // Re-enabled, a USART may send an idle frame: let it pass uncaptured.
            embassy_time::Timer::after_millis(1).await;
            let setup = uart7_de_setup(baud, capture.hz());
            let mut first = [0u8; SEND_BUF_LEN];
            let packet = Packet::FrameErrorCount([1, 2, 3, 4, baud]);
            let n_first = sender.send(0, &packet, &mut first).unwrap();
            let mut second = [0u8; SEND_BUF_LEN];
            let packet = Packet::FrameErrorCount([u32::MAX, 0, 0x5555_5555, 0xAAAA_AAAA, baud]);
            let n_second = sender.send(0, &packet, &mut second).unwrap();
            let messages: [&[u8]; 2] = [&first[..n_first], &second[..n_second]];
            let from_head = Packet::FrameErrorCount([9, 9, 9, round as u32, baud]);
            let activity = async {
                embassy_time::Timer::after_micros(100).await;
                for m in messages {
                    tx.write(m).await.unwrap();
                    tx.flush().await.unwrap();
                    embassy_time::Timer::after_micros(300).await;
                }
                packet_crosses(&mut head_tx, &mut rx, &mut head_sender, &from_head).await;
                embassy_time::Timer::after_micros(100).await;
            };
            let got = capture
                .run(&mut tx_edges[..], &mut de_edges[..], activity)
                .await;
            let tx_line = shared::rs485::Edges {
                initial_high: got.initial_high[0],
                times: &tx_edges[..got.edges[0]],
            };
            let de_line = shared::rs485::Edges {
                initial_high: got.initial_high[1],
                times: &de_edges[..got.edges[1]],
            };
            let measured = shared::rs485::check(&setup, tx_line, de_line, &messages);
            match measured {
                Ok(m) => defmt::info!("{} baud: {}", baud, m),
                Err(e) => panic!("{} baud: {}", baud, e),
            }
        }
    }
}
