//! End-to-end tests through the firmware's own tasks. One image carries one baked
//! pairing (`config::BAKED_ROLES`), so each test is compiled only into the image of
//! the pairing it is written for: `build.rs` sets the cfg `bridge_pairing` from the
//! baked configuration (README "Hardware-in-the-loop self-tests").

// The shared checks serve the pairings that have an end-to-end test (an image of
// another pairing, e.g. XY3-100 -> HANS-100, carries none of them).
#[cfg(any(
    bridge_pairing = "hans_to_hans",
    bridge_pairing = "hans_to_xy2",
    bridge_pairing = "xy2_to_hans",
    bridge_pairing = "xy2_to_xy2",
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "xy3_to_xy2"
))]
mod checks;
#[cfg(any(bridge_pairing = "hans_to_xy2", bridge_pairing = "hans_to_hans"))]
mod hans_source;
#[cfg(bridge_pairing = "hans_to_hans")]
mod hans_to_hans;
#[cfg(bridge_pairing = "hans_to_xy2")]
mod hans_to_xy2;
#[cfg(bridge_pairing = "xy3_to_xy2")]
mod sck_gate;
#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "xy2_to_hans",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
mod source;
#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "xy2_to_hans",
    bridge_pairing = "xy2_to_xy2"
))]
mod xy2_source;
#[cfg(bridge_pairing = "xy2_to_hans")]
mod xy2_to_hans;
#[cfg(bridge_pairing = "xy2_to_xy2")]
mod xy2_to_xy2;
#[cfg(bridge_pairing = "xy2_to_xy3")]
mod xy2_to_xy3;
#[cfg(bridge_pairing = "xy3_to_xy2")]
mod xy3_to_xy2;
