//! The bridge engine (sans-IO): configuration, forward translation, link
//! supervision and fail-safe, counters and status back-translation, between the
//! line-level receivers' [`LineEvent`](crate::model::LineEvent)s and the head-side
//! transmitters. It never awaits and never touches hardware; the caller supplies
//! the time (`now_ns`, any monotonic nanosecond clock) with every call.
//!
//! # Use
//! ```text
//! let mut bridge = Bridge::new(&config)?;          // Config::validate() inside
//! bridge.on_line_event(now, event);                // every receiver event
//! let out = bridge.tick(now);                      // every output slot
//! bridge.head_status_mut() + bridge.status_seen(now) // head-side status receivers
//! bridge.xy2_status_frame() / hans_status_frame() / xy3_back_poll(now, buf)
//! ```
//!
//! # Forward path
//! A valid input frame is translated at once ([`Bridge::on_line_event`]): positions
//! resized to the head's width (exact widening, rounded and saturated narrowing,
//! [`Position::resized`](crate::model::Position::resized)), then the axis map (swap
//! X/Y, invert, offset in head LSBs, clamped), Z from its source. Commands reach the
//! head only where its protocol carries them (XY3-100 commands to an XY3-100 head;
//! XY2-100 enhanced commands to a 16-bit XY2-100 head with `enhanced_commands`);
//! HANS-100 laser control only to a HANS-100 head with `laser.forward`. Everything
//! else is counted (`commands_not_carried`, `laser_not_carried`); HANS-100 code 3
//! also drives the bridge's power output and, with `laser.gate = "hans_mo_pa"`, the
//! gate. An XY3-100 backchannel-rate command also switches the bridge's own
//! controller-side backchannel (reported in [`Output::controller_back_rate`]).
//!
//! Timing: **free-running** — [`Bridge::tick`] once per output slot sends the newest
//! input frame; if none arrived since the last slot the last positions are repeated
//! (`repeated`), if several arrived all but the newest are skipped (`skipped`), their
//! one-off command / laser control riding on the newest frame when it has none.
//! **Slaved** — each forwarded input frame is output at once from
//! [`Bridge::on_line_event`]; `tick` at the configured rate only clocks the
//! fail-safe frames. One-offs (commands, laser control) are never repeated.
//!
//! # Supervision state machine
//! `T` = `failsafe.input_timeout_us` (default 1 ms), `H` = `failsafe.hold_us`,
//! `N` = `failsafe.recovery_frames`. A *valid frame* is `LineEvent::Frame`; a
//! *fault* is a `LineEvent::Fault` that stands for a frame period the receiver
//! could not publish: any fault on an XY2-100 / XY3-100 line (`Axis`, `Framing`),
//! and on a HANS-100 controller the period faults on `Framing` (in the vote and
//! super modes the receiver ends every decoded period in a frame or one such
//! fault, and reports a lost timing there). Faults on a `HansChannel` (check failed,
//! resync, minority, missing) are counted only in the vote and super modes (in
//! normal mode the one channel's faults are the period's), as are the head-side
//! `Status` / `Backchannel`: a noisy or dead backup channel must not hold the
//! recovery run at zero while the decode mode still publishes verified frames.
//! Time is applied before each event.
//!
//! | state | event | action / next state |
//! |---|---|---|
//! | (power-up) | — | `Safe`, `INPUT_LOST`, no position to hold |
//! | `Running` | valid frame | forward it; stay |
//! | `Running` | fault | count; never forwarded; stay (output repeats) |
//! | `Running` | no valid frame for `>= T` | `Holding` from `last_valid + T`; `INPUT_LOST`, gate off, pending frame dropped, MO/PA gate memory cleared; a HANS-100 head that got laser control gets [`LASER_OFF`] in the first fail-safe frame |
//! | `Holding` | time reaches `last_valid + T + H` | `Safe` (`H = 0`: at once) |
//! | `Holding` | — (each slot) | send the last valid positions, no commands / laser control |
//! | `Safe` | — (each slot) | `after_hold = "park"`: send the park position; `"stop"`: send nothing |
//! | `Holding` / `Safe` | valid frame, run < `N` | count run, not forwarded (`not_forwarded`) |
//! | `Holding` / `Safe` | `N`-th consecutive valid frame | `Running`, forward this frame, clear `INPUT_LOST` |
//! | `Holding` / `Safe` | fault, or gap `>= T` | run := 0 |
//! | (power-up) | `failsafe.status_timeout_us != 0` | head status not known: gate off with `off_on_head_alarm`, no alarm |
//! | any | no head status for `failsafe.status_timeout_us` | `STATUS_LOST`, status not known (gate off with `off_on_head_alarm`) |
//! | any | [`Bridge::status_seen`] | clear `STATUS_LOST`, status known |
//!
//! Laser gate = `Running` and not (`off_on_head_alarm` and (any head alarm or the
//! head's status not known)) and (`gate = "link_ok"` or the latest HANS-100 MO and
//! PA on). The status is known from the first [`Bridge::status_seen`] until a
//! `STATUS_LOST`; with `status_timeout_us = 0` (no status supervised) always. So a
//! head that reports an alarm from power-up never gets the gate, however short
//! `recovery_frames` is. The wait before the first status is not reported to the
//! controller: a head's first status normally arrives within milliseconds, and an
//! alarm raised and cleared at every start-up would only be noise; if none comes,
//! `STATUS_LOST` follows after the timeout as before.
//!
//! # Cost
//! One input frame plus one output slot cost about 285-295 instructions on the
//! Cortex-M7 (`cargo xtask qemu`, free-running, with and without the axis map;
//! frame, event and summing in the workload included). The per-frame path
//! avoids moving frames around: a valid frame is translated straight into the
//! pending slot, the output slot completes it there and moves it straight into the
//! output; the axis map is resolved at construction into per-axis masks and steps
//! applied to the MSB-aligned value (rounding is one saturating add); the translation and completion inline into the engine; and
//! while running with fresh input and status the supervisor's time check is one
//! 64-bit compare against the earliest deadline, made at the call site, which a
//! valid frame does not re-arm (see `supervision`); the full rules, the clean-up
//! after a loss and a frame superseding a still pending one are calls.
//!
//! # Status
//! See [`status`] and `STATUS_MAP.md`.

mod config;
mod counters;
mod engine;
pub mod head_out;
pub mod pacing;
pub mod ring_guard;
#[cfg(feature = "serde")]
pub mod serde_impl;
pub mod slot_guard;
pub mod status;
mod supervision;
mod translate;
mod validate;

pub use config::{
    AfterHold, AxisMap, Config, ControllerSide, FailSafe, GateSource, HansController, HansDecode,
    HeadSide, LaserConfig, OutputConfig, Protocol, StatusForm, Timing, Xy2Controller, Xy2Head,
    Xy3Controller, Xy3Head, Xy3Select, ZConfig, ZSource, CENTRE20, HANS_RATE_HZ, MAX20,
    MAX_RATE_HZ, MIN_RATE_HZ,
};
pub use counters::{Counters, LineCounters};
pub use engine::{Bridge, LaserOutputs, Output, LASER_OFF};
pub use supervision::LinkState;
pub use validate::ConfigError;

#[cfg(test)]
mod tests;
