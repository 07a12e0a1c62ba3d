//! The XY2-100 controller of the end-to-end tests ([`super::source::BsrrSource`]
//! with `shared::xy2::tx` words), and the watch on the laser gate and the STATUS
//! level towards that controller (pairings with the level form).

#[cfg(any(bridge_pairing = "xy2_to_xy3", bridge_pairing = "xy2_to_hans"))]
use {
    super::checks::laser_gate_high,
    core::cell::Cell,
    embassy_stm32::pac,
    embassy_time::{Duration, Instant},
    shared::xy2::{Health, StatusLevel},
};

use shared::xy2;

/// Ticks per frame and tick rate of the XY2-100 source: 100 kHz frames at a 2 MHz
/// clock, as a controller sends them.
pub(super) const SRC_TPF: usize = 40;
pub(super) const SRC_TICK_HZ: u32 = 4_000_000;
/// Frames per half of the source's ring (0.5 ms).
pub(super) const SRC_FRAMES: usize = 50;

/// The source's port-E pins, in `OutPinMap` order: CLK PE2, SYNC PE3, X PE4, Y PE9,
/// Z PE10.
pub(super) const SRC_PINS: xy2::tx::OutPinMap = xy2::tx::OutPinMap {
    clk: 2,
    sync: 3,
    x: 4,
    y: 9,
    z: Some(10),
};

/// The laser gate (PF13 pad) and the XY2-100 STATUS level towards the controller
/// (PA0), sampled every 100 us through an end-to-end run: violations counted per
/// phase. (Not for a STATUS word: the XY2-100 word pairing checks the words.)
#[cfg(any(bridge_pairing = "xy2_to_xy3", bridge_pairing = "xy2_to_hans"))]
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

#[cfg(any(bridge_pairing = "xy2_to_xy3", bridge_pairing = "xy2_to_hans"))]
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
        let status = || level.health(pac::GPIOA.idr().read().idr(0) == pac::gpio::vals::Idr::HIGH);
        loop {
            let (g, ok) = (laser_gate_high(), status() == Health::Ok);
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
