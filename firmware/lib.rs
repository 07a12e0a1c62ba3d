//! The reusable part of the firmware: the board bring-up and the peripheral drivers.
//! It is a library so that the firmware binary (`firmware/main.rs`) and the
//! hardware-in-the-loop test binary (`firmware/hil/main.rs`) run the same code.
#![no_std]

pub mod board;
pub mod drivers;
mod ring;
pub mod tcm;
