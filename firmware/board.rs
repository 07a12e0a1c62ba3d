//! The reference board: NUCLEO-H743ZI2 (STM32H743ZI) plus RS-422/RS-485 transceivers and
//! two DB25 connectors (controller side, head side). Everything that ties the firmware
//! to this particular board lives here: power supply, clock tree, the early fail-safe
//! state of the laser gate, the pin map and the boot diagnostics.
//!
//! # Pin map
//! The full signal / DB25 / transceiver / pin / peripheral / DMA table is in
//! `README.md (section "Firmware")`. One DB25 pair feeds every MCU pin one of its roles
//! needs (receiver outputs fan out to several inputs; outputs that several roles share
//! go through a 2:1 mux or share one pin with different alternate functions), so the
//! protocol per side is configuration, not a rebuild. Pins taken here:
//! * `PF13` laser gate (interlock): high = laser may fire. External pull-down, so it is
//!   off in reset; [`init`] drives it low before anything else ([`LASER_GATE_PIN`]).
//! * `PF11` head-side line-driver enable (pulled down, off until an output runs);
//!   `PF14` SCK-bus buffer enable (XY3 CLK from pair 2); `PF15` head-driver source
//!   select (GPIO waveform / HANS serial) -- taken by the output drivers (issue 6).
//! * NUCLEO LEDs: `PB0` LD1 green = link OK (blinking: no link), `PE1` LD2 yellow =
//!   activity (frames to the head), `PB14` LD3 red = fault (latched after a watchdog
//!   reset); `tasks::leds` in the firmware binary.
//!
//! # Clock tree (RM0433 §8 "Reset and clock control")
//! ```text
//! HSE 8 MHz, bypass: the NUCLEO's ST-LINK drives its MCO into PH0 (no crystal fitted)
//!   every PLL: DIVM = 4 -> 2 MHz reference (PLL input range 2..4 MHz)
//!   PLL1  x480 -> VCO 960 MHz (wide range)   P /2 -> 480 MHz = sys_ck     (rev V, VOS0)
//!         x400 -> VCO 800 MHz                P /2 -> 400 MHz = sys_ck     (rev Y, VOS1)
//!   PLL2  x300 -> VCO 600 MHz (wide range)   P /6 -> 100 MHz  SPI1/2/3 + SAI1/2/3 kernel
//!                                            Q /6 -> 100 MHz  SPI4/5/6 + all U(S)ART kernel
//! sys_ck 480 -> D1CPRE /1 -> CPU 480 MHz
//!            -> HPRE /2   -> AHB1..4 (hclk) 240 MHz (max 240 in VOS0)
//!            -> D2PPRE1 /2 -> APB1 120 MHz; timers on APB1 (TIM2..7, 12..14) 240 MHz
//!            -> D2PPRE2 /2 -> APB2 120 MHz; timers on APB2 (TIM1, 8, 15..17)  240 MHz
//!            -> D1PPRE /2  -> APB3 120 MHz;  D3PPRE /2 -> APB4 120 MHz
//! (rev Y: CPU 400, AHB 200, APBx 100, timers 200 MHz.)
//! ```
//! Why PLL2 feeds every serial kernel clock: the protocol timing must not depend on the
//! silicon revision (480 or 400 MHz core), and 100 MHz divides to every rate we need
//! exactly:
//! * HANS-100 out, 12.5 MHz: SAI/SPI master bit clock 100 MHz / 8.
//! * HANS-100 in oversampling clock fs (layouts.md §3): TIM3 CH1 (controller side) and
//!   CH2 (head-side STATUS) as PWM from the 240 MHz timer clock, 240 / 6 = **40.000 MHz** (rev Y: 200 / 5 = 40.000 MHz), ratio
//!   fs / 12.5 MHz = 3.2. Alternatives, if a head needs another rate: 50 MHz (ratio 4)
//!   = an SPI master clocked from PLL2_P 100 MHz with MBR /2; 37.5 MHz (ratio 3) = PLL2_Q
//!   changed to /8 (75 MHz) and an SPI4/5 master with MBR /2. All exact: the decoder
//!   gets the exact ratio.
//! * Backchannel UART (115200 .. 921600 baud): USART kernel 100 MHz. embassy-stm32 0.6
//!   keeps 16x oversampling whenever BRR fits (RM0433 "USART baud rate generation",
//!   §48.4, beside the driver-enable part the driver cites), so 115200 is
//!   100e6 / 868 = 115 207 baud (+0.006 %) and 921600 is 100e6 / 109 = 917 431 baud
//!   (-0.45 %): well inside an 8N1 link's ~±2 % between both ends, and measured on
//!   the board by the HIL test `backchannel_de_timing` (it accepts up to 0.5 %).
//!
//! PLL3 stays off (nothing needs it yet; PLL3_Q /10 of a 480 MHz VCO would give USB's
//! 48 MHz if a USB console is added).
//!
//! # Power (RM0433 §6 "Power control")
//! The STM32H743 (RM0433 family) has no SMPS: VCORE comes from the internal LDO (the
//! NUCLEO-H743ZI2 wiring) or from an external supply with the LDO bypassed. embassy-stm32
//! writes PWR_CR3 = LDO for this family (and exposes no `SupplyConfig` here). PWR_CR3's
//! supply bits are write-once per power-on: a mismatch with the board hangs at
//! ACTVOSRDY. See README.md (section "Firmware") "Troubleshooting" for recovery.

use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
use embassy_stm32::pac;
use embassy_stm32::peripherals::*;
use embassy_stm32::rcc::{
    AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllDiv, PllMul, PllPreDiv, PllSource, Sysclk,
    VoltageScale,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::{Peri, PeripheralType};

#[cfg(feature = "board-custom-smps")]
compile_error!(
    "board-custom-smps: the STM32H743 has no SMPS (RM0433 §6; LDO or LDO bypass only). \
     An SMPS board needs an SMPS part (e.g. STM32H725/735/747/7A3): change the chip feature \
     of embassy-stm32 and set `config.rcc.supply_config` in board.rs to match the board."
);

/// Laser gate: port F bit 13 (`PF13`); `init` takes `p.PF13` for the same pin.
pub const LASER_GATE_PIN: usize = 13;

/// Silicon revision, from DBGMCU_IDC.REV_ID (RM0433, debug support chapter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Silicon {
    /// Revision V (REV_ID 0x2003): VOS0 allowed, 480 MHz.
    RevV,
    /// Any other REV_ID (revision Y is 0x1003): limited to VOS1, 400 MHz.
    Other(u16),
}

/// Why the chip last reset, from RCC_RSR (RM0433 §8, reset status register). Several
/// flags can be set at once (a power-on also sets the pin and BOR flags); the most
/// specific one wins.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum ResetCause {
    /// The independent watchdog expired: the firmware stalled.
    IndependentWatchdog,
    /// The window watchdog fired.
    WindowWatchdog,
    /// Software reset (SYSRESETREQ, e.g. from the debugger or a panic handler).
    Software,
    /// Power-on / power-down reset.
    PowerOn,
    /// Brown-out reset.
    BrownOut,
    /// NRST pin (reset button, probe).
    Pin,
    /// Illegal low-power entry, or no flag set.
    Other(u32),
}

impl ResetCause {
    /// True if the last reset shows the firmware itself failed.
    pub fn is_fault(self) -> bool {
        matches!(self, Self::IndependentWatchdog | Self::WindowWatchdog)
    }
}

/// What [`init`] hands to `main`.
pub struct Board {
    /// Laser gate output, driven low (off).
    pub laser_gate: Output<'static>,
    /// LD1 green.
    pub led_green: Output<'static>,
    /// LD2 yellow.
    pub led_yellow: Output<'static>,
    /// LD3 red.
    pub led_red: Output<'static>,
    /// The independent watchdog, for the supervisor task.
    pub iwdg: Peri<'static, IWDG1>,
    /// Reset cause read before the flags were cleared.
    pub reset_cause: ResetCause,
    /// Silicon revision and the core clock chosen for it.
    pub silicon: Silicon,
    /// Core clock in Hz.
    pub core_hz: u32,
    /// Everything the protocol drivers take, grouped by function.
    pub res: Resources,
}

/// The HANS-100 oversampling clock fs made by TIM3 (240 MHz / 6 on revision V,
/// 200 MHz / 5 on revision Y: exact on both; README clock tree), 3.2 times the
/// 12.5 MHz bit rate.
pub const HANS_FS_HZ: u32 = 40_000_000;

/// Controller-side XY2-100 input (README.md (section "Firmware") allocation table).
pub struct Xy2InRes {
    /// TIM1, counting CLK on ETR.
    pub tim: Peri<'static, TIM1>,
    /// Pair 1 (XY2 CLK) on TIM1_ETR.
    pub clk: Peri<'static, PE7>,
    /// Trigger DMA stream.
    pub dma: Peri<'static, DMA2_CH0>,
    /// COM DMA stream on the same CLK edges: the STATUS word towards the controller
    /// (`drivers::status_word_out`, PA0 BSRR).
    pub status_dma: Peri<'static, DMA2_CH7>,
    /// The data lines the samples carry.
    pub data: Xy2DataPins,
}

/// The XY2-100 data lines on port G that the TIM1 samples (GPIOG IDR) carry: pairs
/// 2..5.
pub struct Xy2DataPins {
    /// Pair 2, SYNC.
    pub sync: Peri<'static, PG0>,
    /// Pair 3, X.
    pub x: Peri<'static, PG1>,
    /// Pair 4, Y.
    pub y: Peri<'static, PG2>,
    /// Pair 5, Z.
    pub z: Peri<'static, PG3>,
}

impl Xy2DataPins {
    /// The four pins as inputs (the receivers drive them). GPIO pins leave reset in
    /// analog mode, where the input stage is off and the input data register reads 0
    /// (RM0433 §11.3.12): without this every sample would be 0. The inputs must be
    /// kept while sampling (dropping one turns its pin back into an unconnected
    /// pin).
    pub fn inputs(self) -> [Input<'static>; 4] {
        [
            Input::new(self.sync, Pull::None),
            Input::new(self.x, Pull::None),
            Input::new(self.y, Pull::None),
            Input::new(self.z, Pull::None),
        ]
    }
}

/// One XY3-100 data line's receive-only SPI slave: the SPI, its SCK (from the shared
/// SCK bus), MOSI (the line's pair), NSS (SYNC, pair 1) and RX DMA stream.
pub struct SpiLineRes<S, K, M, N, D>
where
    S: PeripheralType + 'static,
    K: PeripheralType + 'static,
    M: PeripheralType + 'static,
    N: PeripheralType + 'static,
    D: PeripheralType + 'static,
{
    /// The SPI.
    pub spi: Peri<'static, S>,
    /// SCK.
    pub sck: Peri<'static, K>,
    /// MOSI.
    pub mosi: Peri<'static, M>,
    /// NSS.
    pub nss: Peri<'static, N>,
    /// RX DMA stream.
    pub dma: Peri<'static, D>,
}

/// Controller-side XY3-100 data lines + SYNC marks.
pub struct Xy3InRes {
    /// X: SPI3 (SCK PC10, MOSI PC12 = pair 3, NSS PA15; AF6) on DMA1 stream 0 (the
    /// SYNC-mark ISR reads its counter).
    pub x: SpiLineRes<SPI3, PC10, PC12, PA15, DMA1_CH0>,
    /// Y: SPI4 (SCK PE12, MOSI PE14 = pair 4, NSS PE11; AF5) on DMA1 stream 1.
    pub y: SpiLineRes<SPI4, PE12, PE14, PE11, DMA1_CH1>,
    /// Z: SPI5 (SCK PF7, MOSI PF9 = pair 5, NSS PF6; AF5) on DMA1 stream 2.
    pub z: SpiLineRes<SPI5, PF7, PF9, PF6, DMA1_CH2>,
    /// U: SPI1 (SCK PA5, MOSI PB5 = pair 7, NSS PG10; AF5) on DMA1 stream 3. NSS is
    /// PG10, not SPI1's other NSS pin PA4: PA4 is the SYNC EXTI input below.
    pub u: SpiLineRes<SPI1, PA5, PB5, PG10, DMA1_CH3>,
    /// W: SPI2 (SCK PB10, MOSI PB15 = pair 8, NSS PB12; AF5) on DMA1 stream 4.
    pub w: SpiLineRes<SPI2, PB10, PB15, PB12, DMA1_CH4>,
    /// SYNC again, as an EXTI input (EXTI4).
    pub sync: Peri<'static, PA4>,
    /// EXTI line 4.
    pub exti: Peri<'static, EXTI4>,
    /// SCK-bus buffer OE# (low = pair 2 drives the SCK bus).
    pub sck_buffer_oe: Peri<'static, PF14>,
}

/// Head-side GPIO waveform output (XY2 / XY3) and XY2 STATUS sampling.
pub struct WaveRes {
    /// TIM8: tick timer.
    pub tim: Peri<'static, TIM8>,
    /// Update DMA stream (BSRR writes).
    pub dma: Peri<'static, DMA2_CH1>,
    /// CC1 DMA stream (STATUS word samples).
    pub status_dma: Peri<'static, DMA2_CH2>,
    /// Pairs 1, 2, 3, 4, 5, 7, 8 drivers (port D bits 0, 1, 2, 3, 10, 14, 15).
    pub pins: WavePins,
}

/// The port-D pins of the waveform output.
pub struct WavePins {
    /// Pair 1.
    pub p1: Peri<'static, PD0>,
    /// Pair 2.
    pub p2: Peri<'static, PD1>,
    /// Pair 3.
    pub p3: Peri<'static, PD2>,
    /// Pair 4.
    pub p4: Peri<'static, PD3>,
    /// Pair 5.
    pub p5: Peri<'static, PD10>,
    /// Pair 7.
    pub p7: Peri<'static, PD14>,
    /// Pair 8.
    pub p8: Peri<'static, PD15>,
}

/// Head-side HANS-100 serial output.
pub struct HansOutRes {
    /// SAI1 (block A).
    pub sai: Peri<'static, SAI1>,
    /// SAI1_SD_A.
    pub sd: Peri<'static, PE6>,
    /// DMA stream.
    pub dma: Peri<'static, DMA2_CH3>,
    /// TIM7 (basic timer, no pin): the slot ring guard's slot timer
    /// (`drivers::serial_tx`, "The slot timer").
    pub tick: Peri<'static, TIM7>,
}

/// Head-side HANS-100 STATUS input: SPI6 slave clocked by the TIM3 fs clock
/// ([`FsRes`], channel 2).
pub struct HansStatusInRes {
    /// SPI6 (BDMA, ring in SRAM4).
    pub spi: Peri<'static, SPI6>,
    /// SPI6_SCK (AF8), wired to the fs clock output.
    pub sck: Peri<'static, PB3>,
    /// SPI6_MOSI (AF5) from the pair-6 receiver.
    pub mosi: Peri<'static, PG14>,
    /// BDMA channel 0.
    pub dma: Peri<'static, BDMA_CH0>,
}

/// The HANS-100 oversampling clock fs: TIM3, one timer for both HANS inputs, so
/// both sample at the same exact rate ([`HANS_FS_HZ`]).
pub struct FsRes {
    /// TIM3.
    pub tim: Peri<'static, TIM3>,
    /// TIM3_CH1 (AF2): fs onto the controller-side SCK bus (HANS-100 controller
    /// input, SPI1..5 SCK). Only a HANS-100 controller may drive it: for XY3-100
    /// the pair-2 buffer drives that bus.
    pub ctrl: Peri<'static, PC6>,
    /// TIM3_CH2 (AF2): fs to SPI6 SCK (PB3, HANS STATUS input from the head).
    pub status: Peri<'static, PC7>,
}

/// Controller-side HANS-100 input: the channel pins the XY3-100 lines do not share.
/// CH3, CH4, CH5 arrive on the X, Y, Z MOSI pins of [`Xy3InRes`] (pairs 3..5), and
/// all five SPIs, their SCK pins on the shared bus and their DMA streams are
/// [`Xy3InRes`]'s too (one controller protocol runs at a time).
pub struct HansInRes {
    /// CH1 (pair 1) on SPI1_MOSI (AF5).
    pub ch1: Peri<'static, PD7>,
    /// CH2 (pair 2) on SPI2_MOSI (AF5). SPI2's MOSI can only be PB15 (pair 8, XY3
    /// W), PC1 or PC3, and PC3 is the analog-only pad PC3_C on this package, so PC1:
    /// the NUCLEO routes it to the Ethernet PHY's MDC *input* as well (the PHY never
    /// drives it; without an MDIO frame it ignores the clocking).
    pub ch2: Peri<'static, PC1>,
}

/// Controller-side HANS STATUS out: SAI2 block B, serial data on the pair-6 driver
/// input (PA0, `Resources::ctrl_status`, AF10).
pub struct HansStatusOutRes {
    /// SAI2 (block B).
    pub sai: Peri<'static, SAI2>,
    /// DMA stream.
    pub dma: Peri<'static, DMA2_CH4>,
}

/// UART7: XY3 backchannel towards the controller, TX + DE to the controller-side
/// pair-6 driver. Its RX pin is not wired on the board (embassy builds a DE UART
/// duplex only); the HIL tests loop other TX pins into it.
pub struct BackRes {
    /// UART7.
    pub uart: Peri<'static, UART7>,
    /// UART7_RX (AF11): not wired (HIL loop-back input).
    pub rx: Peri<'static, PA8>,
    /// UART7_TX (AF7) to the controller side.
    pub tx: Peri<'static, PE8>,
    /// UART7_DE (AF7): controller-side pair-6 driver enable.
    pub de: Peri<'static, PF8>,
    /// TX DMA stream.
    pub tx_dma: Peri<'static, DMA2_CH5>,
    /// RX DMA stream.
    pub rx_dma: Peri<'static, DMA2_CH6>,
}

/// USART2: XY3 backchannel from the head, RX from the head-side pair-6 receiver; a
/// UART of its own so the head side runs at its own rate (the bridge switches it
/// when it forwards a BACK_RATE command to the head, the controller side when the
/// bytes queued at the old rate are out).
pub struct HeadBackRes {
    /// USART2.
    pub uart: Peri<'static, USART2>,
    /// USART2_RX (AF7) from the head-side pair-6 receiver.
    pub rx: Peri<'static, PD6>,
    /// USART2_TX (AF7): not wired on the board (HIL loop-back output).
    pub tx: Peri<'static, PD5>,
    /// RX DMA stream.
    pub rx_dma: Peri<'static, DMA1_CH5>,
    /// TX DMA stream (HIL only).
    pub tx_dma: Peri<'static, DMA1_CH6>,
}

/// All protocol resources.
pub struct Resources {
    /// Controller XY2 in.
    pub xy2_in: Xy2InRes,
    /// Controller XY3 in.
    pub xy3_in: Xy3InRes,
    /// Controller-side pair 6 driver input: GPIO (XY2 STATUS level out, or the
    /// word by BSRR DMA) or SAI2_SD_B (HANS STATUS out).
    pub ctrl_status: Peri<'static, PA0>,
    /// Head waveform out.
    pub wave: WaveRes,
    /// Head-side pair 6 receiver as GPIO (XY2 STATUS level; the CC1 sampler reads it
    /// as port G bit 9).
    pub head_status: Peri<'static, PG9>,
    /// Head HANS out.
    pub hans_out: HansOutRes,
    /// Head HANS STATUS in.
    pub hans_status_in: HansStatusInRes,
    /// HANS-100 oversampling clock (both HANS inputs).
    pub fs: FsRes,
    /// Controller HANS-100 input (channel pins not shared with `xy3_in`).
    pub hans_in: HansInRes,
    /// Controller HANS STATUS out (its pin is `ctrl_status`).
    pub hans_status_out: HansStatusOutRes,
    /// Backchannel UART towards the controller.
    pub back: BackRes,
    /// Backchannel UART from the head.
    pub head_back: HeadBackRes,
    /// Head-side line-driver enable (high = drivers on).
    pub head_enable: Peri<'static, PF11>,
    /// Head-driver source select (low = GPIO waveform, high = HANS serial).
    pub head_mux: Peri<'static, PF15>,
}

/// Brings the board up. Order matters:
/// 1. laser gate off (before anything that can take time or fail),
/// 2. reset cause captured and cleared,
/// 3. power, clocks (embassy), SRAM1..3 clocks, I-cache, debug freeze of the watchdog.
pub fn init() -> Board {
    laser_gate_off_early();
    let reset_cause = take_reset_cause();
    let silicon = match pac::DBGMCU.idc().read().rev_id() {
        0x2003 => Silicon::RevV,
        other => Silicon::Other(other),
    };
    let p = embassy_stm32::init(clock_config(silicon));

    // SRAM1..3 (D2 domain) hold the DMA1/DMA2 rings; their clocks are off after reset
    // and embassy-stm32 does not enable them (RM0433 §8, RCC_AHB2ENR).
    pac::RCC.ahb2enr().modify(|w| {
        w.set_sram1en(true);
        w.set_sram2en(true);
        w.set_sram3en(true);
    });
    // Halted at a breakpoint the watchdog would reset the chip under the debugger.
    pac::DBGMCU.apb4fzr1().modify(|w| w.set_iwdg1(true));
    enable_icache();

    Board {
        // `Output::new` writes the level before switching the mode: no glitch high.
        laser_gate: Output::new(p.PF13, Level::Low, Speed::Low),
        led_green: Output::new(p.PB0, Level::Low, Speed::Low),
        led_yellow: Output::new(p.PE1, Level::Low, Speed::Low),
        led_red: Output::new(p.PB14, Level::Low, Speed::Low),
        iwdg: p.IWDG1,
        reset_cause,
        silicon,
        core_hz: core_hz(silicon),
        res: Resources {
            xy2_in: Xy2InRes {
                tim: p.TIM1,
                clk: p.PE7,
                dma: p.DMA2_CH0,
                status_dma: p.DMA2_CH7,
                data: Xy2DataPins {
                    sync: p.PG0,
                    x: p.PG1,
                    y: p.PG2,
                    z: p.PG3,
                },
            },
            xy3_in: Xy3InRes {
                x: SpiLineRes {
                    spi: p.SPI3,
                    sck: p.PC10,
                    mosi: p.PC12,
                    nss: p.PA15,
                    dma: p.DMA1_CH0,
                },
                y: SpiLineRes {
                    spi: p.SPI4,
                    sck: p.PE12,
                    mosi: p.PE14,
                    nss: p.PE11,
                    dma: p.DMA1_CH1,
                },
                z: SpiLineRes {
                    spi: p.SPI5,
                    sck: p.PF7,
                    mosi: p.PF9,
                    nss: p.PF6,
                    dma: p.DMA1_CH2,
                },
                u: SpiLineRes {
                    spi: p.SPI1,
                    sck: p.PA5,
                    mosi: p.PB5,
                    nss: p.PG10,
                    dma: p.DMA1_CH3,
                },
                w: SpiLineRes {
                    spi: p.SPI2,
                    sck: p.PB10,
                    mosi: p.PB15,
                    nss: p.PB12,
                    dma: p.DMA1_CH4,
                },
                sync: p.PA4,
                exti: p.EXTI4,
                sck_buffer_oe: p.PF14,
            },
            ctrl_status: p.PA0,
            wave: WaveRes {
                tim: p.TIM8,
                dma: p.DMA2_CH1,
                status_dma: p.DMA2_CH2,
                pins: WavePins {
                    p1: p.PD0,
                    p2: p.PD1,
                    p3: p.PD2,
                    p4: p.PD3,
                    p5: p.PD10,
                    p7: p.PD14,
                    p8: p.PD15,
                },
            },
            head_status: p.PG9,
            hans_out: HansOutRes {
                sai: p.SAI1,
                sd: p.PE6,
                dma: p.DMA2_CH3,
                tick: p.TIM7,
            },
            hans_status_in: HansStatusInRes {
                spi: p.SPI6,
                sck: p.PB3,
                mosi: p.PG14,
                dma: p.BDMA_CH0,
            },
            fs: FsRes {
                tim: p.TIM3,
                ctrl: p.PC6,
                status: p.PC7,
            },
            hans_in: HansInRes {
                ch1: p.PD7,
                ch2: p.PC1,
            },
            hans_status_out: HansStatusOutRes {
                sai: p.SAI2,
                dma: p.DMA2_CH4,
            },
            back: BackRes {
                uart: p.UART7,
                rx: p.PA8,
                tx: p.PE8,
                de: p.PF8,
                tx_dma: p.DMA2_CH5,
                rx_dma: p.DMA2_CH6,
            },
            head_back: HeadBackRes {
                uart: p.USART2,
                rx: p.PD6,
                tx: p.PD5,
                rx_dma: p.DMA1_CH5,
                tx_dma: p.DMA1_CH6,
            },
            head_enable: p.PF11,
            head_mux: p.PF15,
        },
    }
}

/// Drives the laser gate low with raw register writes, before clocks are set up. At
/// reset the pin is a floating input held off by the board's pull-down; this makes it
/// an actively driven low from the first microseconds (RM0433 §11: GPIO_BSRR first, then
/// GPIO_MODER, so the pin never drives high).
fn laser_gate_off_early() {
    pac::RCC.ahb4enr().modify(|w| w.set_gpiofen(true));
    // Read back so the clock enable has taken effect before the port is written
    // (RM0433 §8: a short delay is needed after enabling a peripheral clock).
    let _ = pac::RCC.ahb4enr().read();
    pac::GPIOF.bsrr().write(|w| w.set_br(LASER_GATE_PIN, true));
    pac::GPIOF
        .moder()
        .modify(|w| w.set_moder(LASER_GATE_PIN, pac::gpio::vals::Moder::OUTPUT));
}

/// Reads RCC_RSR and clears it (RMVF) so the next boot sees only its own cause.
fn take_reset_cause() -> ResetCause {
    let rsr = pac::RCC.rsr().read();
    pac::RCC.rsr().modify(|w| w.set_rmvf(true));
    if rsr.iwdg1rstf() {
        ResetCause::IndependentWatchdog
    } else if rsr.wwdg1rstf() {
        ResetCause::WindowWatchdog
    } else if rsr.sftrstf() {
        ResetCause::Software
    } else if rsr.porrstf() {
        ResetCause::PowerOn
    } else if rsr.borrstf() {
        ResetCause::BrownOut
    } else if rsr.pinrstf() {
        ResetCause::Pin
    } else {
        ResetCause::Other(rsr.0)
    }
}

/// Core clock for a silicon revision: 480 MHz needs VOS0, which only revision V allows
/// (DS12110 / errata ES0392); everything else runs at 400 MHz in VOS1.
fn core_hz(silicon: Silicon) -> u32 {
    match silicon {
        Silicon::RevV => 480_000_000,
        Silicon::Other(_) => 400_000_000,
    }
}

/// The clock tree described in the module docs.
fn clock_config(silicon: Silicon) -> embassy_stm32::Config {
    let mut config = embassy_stm32::Config::default();
    let rcc = &mut config.rcc;
    rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Bypass,
    });
    // HSI stays on: it clocks the PLL setup and is the fallback if HSE fails.
    rcc.sys = Sysclk::PLL1_P;
    let (mul, scale) = match silicon {
        Silicon::RevV => (PllMul::MUL480, VoltageScale::Scale0),
        Silicon::Other(_) => (PllMul::MUL400, VoltageScale::Scale1),
    };
    rcc.voltage_scale = scale;
    rcc.pll1 = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV4,
        mul,
        fracn: None,
        divp: Some(PllDiv::DIV2),
        divq: None,
        divr: None,
    });
    rcc.pll2 = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL300,
        fracn: None,
        divp: Some(PllDiv::DIV6),
        divq: Some(PllDiv::DIV6),
        divr: None,
    });
    rcc.d1c_pre = AHBPrescaler::DIV1;
    rcc.ahb_pre = AHBPrescaler::DIV2;
    rcc.apb1_pre = APBPrescaler::DIV2;
    rcc.apb2_pre = APBPrescaler::DIV2;
    rcc.apb3_pre = APBPrescaler::DIV2;
    rcc.apb4_pre = APBPrescaler::DIV2;

    use embassy_stm32::rcc::mux;
    rcc.mux.spi123sel = mux::Saisel::PLL2_P;
    rcc.mux.sai1sel = mux::Saisel::PLL2_P;
    rcc.mux.sai23sel = mux::Saisel::PLL2_P;
    rcc.mux.spi45sel = mux::Spi45sel::PLL2_Q;
    rcc.mux.spi6sel = mux::Spi6sel::PLL2_Q;
    rcc.mux.usart16910sel = mux::Usart16910sel::PLL2_Q;
    rcc.mux.usart234578sel = mux::Usart234578sel::PLL2_Q;
    config
}

/// Enables the Cortex-M7 instruction cache. The data cache stays off on purpose: DMA
/// rings in SRAM1..4 then need no clean/invalidate maintenance, and the per-frame hot
/// state lives in DTCM, which is zero-wait-state and never cached anyway.
fn enable_icache() {
    // SAFETY: nothing else owns SCB at this point (embassy does not take the core
    // peripherals); the I-cache enable sequence (invalidate, enable, barriers) is done
    // by `enable_icache`.
    let mut cp = unsafe { cortex_m::Peripherals::steal() };
    cp.SCB.enable_icache();
}
