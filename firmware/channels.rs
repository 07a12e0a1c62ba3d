//! Inter-task communication: every `Channel` / `Signal` / `Watch` static of the firmware
//! lives here, so the data flow between tasks can be read in one place.
//!
//! Conventions:
//! * `Watch` for state that has a current value many tasks may look at (health, link
//!   state, configuration); late readers get the latest value.
//! * `Signal` for "something happened, latest wins" wake-ups from interrupt context
//!   (DMA half/complete) to one task.
//! * `Channel` for queues where every item matters (decoded frames, log events).
//!
//! All use `CriticalSectionRawMutex`, because senders include interrupt handlers and the
//! high-priority `InterruptExecutor` tasks that will run the decoders.
//!
//! Current flow:
//! ```text
//! supervisor --HEALTH--> leds
//! ```

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::watch::Watch;

/// Overall state shown on the LEDs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Health {
    /// Valid input frames are arriving (the laser gate may open). Set by the bridge
    /// task once input decoding runs (issue 6); false until then.
    pub input_valid: bool,
    /// A fault is latched (watchdog reset at boot, link fault): red LED.
    pub fault: bool,
}

/// Subscribed receivers of [`HEALTH`]. The LED task polls through an anonymous
/// receiver, which needs no slot; one slot is left for a task that awaits changes.
const HEALTH_RECEIVERS: usize = 1;

/// Current [`Health`], published by the supervisor.
pub static HEALTH: Watch<CriticalSectionRawMutex, Health, HEALTH_RECEIVERS> = Watch::new();
