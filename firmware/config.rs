//! Which protocol each side of the board speaks, fixed at build time.
//!
//! Set with environment variables when building, e.g.
//! `XY_CONTROLLER=xy3 XY_HEAD=hans cargo build --release`; defaults: an XY2-100
//! controller driving an XY3-100 head (the typical retrofit). A value the firmware
//! cannot run stops the build (const evaluation), with the message below.
//!
//! The full bridge configuration file (axis map, scaling, supervision limits) replaces
//! this once the bridge's configuration type is on main (issue 6, "configuration baked
//! in at build time").

/// Protocol on the controller side (inputs from the marking card). HANS-100 input
/// needs the oversampling receivers of issue 4 and is not offered yet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Controller {
    /// XY2-100: TIM1-clocked port sampling, STATUS level out.
    Xy2,
    /// XY3-100: SPI slaves with SYNC marks, backchannel out.
    Xy3,
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

/// The roles this image was built for.
pub const ROLES: Roles = Roles {
    controller: controller(option_env!("XY_CONTROLLER")),
    head: head(option_env!("XY_HEAD")),
};

const fn eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

const fn controller(v: Option<&str>) -> Controller {
    match v {
        None => Controller::Xy2,
        Some(s) if eq(s, "xy2") => Controller::Xy2,
        Some(s) if eq(s, "xy3") => Controller::Xy3,
        Some(_) => panic!("XY_CONTROLLER must be xy2 or xy3 (hans input: issue 4)"),
    }
}

const fn head(v: Option<&str>) -> Head {
    match v {
        None => Head::Xy3,
        Some(s) if eq(s, "xy2") => Head::Xy2,
        Some(s) if eq(s, "xy3") => Head::Xy3,
        Some(s) if eq(s, "hans") => Head::Hans,
        Some(_) => panic!("XY_HEAD must be xy2, xy3 or hans"),
    }
}
