//! The bridge configuration, baked in at build time (issue 6).
//!
//! `build.rs` parses `bridge.toml` (or the file named by `XY_BRIDGE_CONFIG`) into
//! [`shared::bridge::Config`], validates it with `Config::validate()` and writes it
//! postcard-encoded to `OUT_DIR/bridge_config.bin`; a bad file stops the build there.
//! [`load`] decodes it at boot (no heap) and validates it again, so an image can never
//! run a configuration the bridge engine would refuse. If that ever fails, `main` keeps
//! the safe state (outputs idle, laser gate off) and logs why.

use shared::bridge::{Config, ConfigError, Protocol};

/// The postcard bytes `build.rs` wrote.
static BAKED: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/bridge_config.bin"));

/// Why the baked configuration cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum LoadError {
    /// The bytes do not decode (an image built with a different `Config` layout).
    Decode,
    /// The configuration decodes but fails `Config::validate()`.
    Invalid(ConfigError),
}

/// The protocols of the baked configuration, as a constant: `build.rs` writes them
/// from the same file as [`BAKED`], so they equal `Roles::of(&load()?)`. The bridge
/// loops build only these roles' receiver and encoder (a test against this constant
/// folds away), which leaves the other roles' code out of the image, and out of ITCM
/// (README "Memory placement").
pub const BAKED_ROLES: Roles = include!(concat!(env!("OUT_DIR"), "/bridge_roles.rs"));

/// Decodes and re-validates the baked configuration.
pub fn load() -> Result<Config, LoadError> {
    let config: Config = postcard::from_bytes(BAKED).map_err(|_| LoadError::Decode)?;
    config.validate().map_err(LoadError::Invalid)?;
    Ok(config)
}

/// Protocol on the controller side (inputs from the marking card) that this board has
/// input drivers for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Controller {
    /// XY2-100: TIM1-clocked port sampling, STATUS level out.
    Xy2,
    /// XY3-100: SPI slaves with SYNC marks, backchannel out.
    Xy3,
    /// HANS-100: SPI slaves oversampling at fs, HANS STATUS out on SAI2.
    Hans,
}

/// Protocol on the head side (outputs to the scan head).
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Head {
    /// XY2-100: BSRR waveform out, STATUS level and word in.
    Xy2,
    /// XY3-100: BSRR waveform out, backchannel in.
    Xy3,
    /// HANS-100: SAI serial out, STATUS in on SPI6.
    Hans,
}

/// Both sides.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub struct Roles {
    /// Controller side.
    pub controller: Controller,
    /// Head side.
    pub head: Head,
}

impl Roles {
    /// The roles of a configuration (the board has drivers for every protocol on
    /// either side).
    pub fn of(config: &Config) -> Roles {
        let controller = match config.controller.protocol {
            Protocol::Xy2 => Controller::Xy2,
            Protocol::Xy3 => Controller::Xy3,
            Protocol::Hans => Controller::Hans,
        };
        let head = match config.head.protocol {
            Protocol::Xy2 => Head::Xy2,
            Protocol::Xy3 => Head::Xy3,
            Protocol::Hans => Head::Hans,
        };
        Roles { controller, head }
    }
}
