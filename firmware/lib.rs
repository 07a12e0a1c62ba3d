//! The firmware: board bring-up, peripheral drivers, the tasks, their channels, the
//! baked configuration and the start-up that spawns them ([`app`]). It is a library so
//! that the firmware binary (`firmware/main.rs`, a thin spawner) and the
//! hardware-in-the-loop test binary (`firmware/hil/`) run the same code, the
//! bridge tasks included.
#![no_std]

pub mod app;
pub mod board;
// Public for the hardware-in-the-loop tests, which read what the firmware's own
// tasks publish (e.g. the bridge's counters through its statistics snapshot).
pub mod channels;
pub mod config;
pub mod drivers;
mod ring;
pub mod tasks;
pub mod tcm;
