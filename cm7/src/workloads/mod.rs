//! Bench workloads: one per per-frame job the firmware does. Each workload prepares
//! its own input (outside the measured window), then runs [`FRAMES`] frames' worth of
//! work inside [`Window::measure`], and returns a checksum of its results so nothing
//! is optimised away. One file per protocol; each exports `WORKLOADS`, listed in
//! [`GROUPS`].

pub mod bridge;
pub mod hans;
pub mod model;
pub mod worst;
pub mod xy2;
pub mod xy3;

/// Frames per measured window (the count per frame is an average over varied data).
pub const FRAMES: usize = 64;

/// One measured job.
pub struct Workload {
    /// Name printed in the table.
    pub name: &'static str,
    /// Frames the window processes (0: the empty calibration window).
    pub frames: u32,
    /// Prepares input, measures the work with [`Window::measure`] exactly once, and
    /// returns a checksum of the results.
    pub run: fn(&mut Window) -> u32,
}

/// Brackets the measured part of a workload with the `bench_start` / `bench_end`
/// markers the counting plugin watches.
pub struct Window {
    start: extern "C" fn(),
    end: extern "C" fn(),
}

impl Window {
    /// A window calling `start` and `end` around the measured work.
    pub const fn new(start: extern "C" fn(), end: extern "C" fn()) -> Self {
        Self { start, end }
    }

    /// Runs `work` between the markers.
    pub fn measure<R>(&mut self, work: impl FnOnce() -> R) -> R {
        (self.start)();
        let out = work();
        (self.end)();
        out
    }
}

/// Every workload group, in the order they run. The first workload of the first group
/// must stay the empty calibration window.
pub const GROUPS: &[&[Workload]] = &[
    model::WORKLOADS,
    xy2::WORKLOADS,
    xy3::WORKLOADS,
    hans::WORKLOADS,
    bridge::WORKLOADS,
    worst::WORKLOADS,
];
