//! Verdicts the end-to-end tests share, as plain functions and structs over what a
//! test recorded: the baked settings every pairing's expectations rest on, and the
//! order of the frame numbers a head received (README "Hardware-in-the-loop
//! self-tests"). Each item is compiled only for the pairings whose test uses it,
//! so no image carries one it does not call.

use shared::bridge::{Config, ZSource};

/// Checks the baked settings every end-to-end test's expectations rest on: the
/// axis map is the identity (no swap, no inversion, no offsets) and Z comes from
/// the input, so a frame reaches the head as it was sent (up to the protocols'
/// bit widths).
pub fn assert_identity_axes(config: &Config) {
    let a = config.axes;
    assert!(
        !a.swap_xy && !a.invert_x && !a.invert_y && !a.invert_z,
        "axis map"
    );
    assert_eq!((a.offset_x, a.offset_y, a.offset_z), (0, 0, 0), "offsets");
    assert_eq!(config.z.source, ZSource::Input);
}

/// The frame numbers a free-running head received, in the order it received them,
/// and its park periods: what the waveform tests (one frame number per head
/// period) judge with [`FrameSeq::check`].
#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
#[derive(Default, Debug, defmt::Format)]
pub struct FrameSeq {
    /// First frame number seen, and the highest one so far.
    pub first: Option<u32>,
    pub last: Option<u32>,
    /// Frames seen for the first time, repeats of the last one, steps back; the
    /// largest step between two distinct frames.
    pub distinct: u32,
    pub repeats: u32,
    pub backwards: u32,
    pub max_step: u32,
    /// The frame with the flipped parity bit was seen.
    pub bad_seen: bool,
    /// Park periods; of them before the first frame; frames after a park.
    pub park: u32,
    pub park_before_first: u32,
    pub frames_after_park: u32,
}

#[cfg(any(
    bridge_pairing = "xy2_to_xy3",
    bridge_pairing = "xy3_to_xy2",
    bridge_pairing = "xy2_to_xy2"
))]
impl FrameSeq {
    /// Records one period at the park position.
    pub fn park(&mut self) {
        self.park += 1;
        self.park_before_first += u32::from(self.first.is_none());
    }

    /// Records one period carrying frame `k` (a frame sent); `bad` when it is the
    /// one sent with a flipped parity bit.
    pub fn frame(&mut self, k: u32, bad: bool) {
        self.frames_after_park += u32::from(self.park > 0);
        self.bad_seen |= bad;
        self.first.get_or_insert(k);
        match self.last {
            Some(last) if k == last => self.repeats += 1,
            Some(last) if k < last => self.backwards += 1,
            Some(last) => {
                self.distinct += 1;
                self.max_step = self.max_step.max(k - last);
            }
            None => self.distinct += 1,
        }
        self.last = Some(self.last.map_or(k, |l| l.max(k)));
    }

    /// The verdict for a source of `n` frames whose first `recovery` frames the
    /// bridge's recovery run (`failsafe.recovery_frames`) holds back: the flipped
    /// frame never; frames never go back; park only after the last frame; the
    /// first frame at the end of the recovery run, the last within 4 of the last
    /// one sent; steps of at most 4 and at least 60 % of the frames after the
    /// recovery run distinct (free-running at the input's rate, a batch of 20
    /// slots that drains a half of 25 frames skips 5: ~80 % expected, README
    /// "Added latency"); at least 1000 park periods at the end.
    pub fn check(&self, n: u32, recovery: u32) {
        assert!(
            !self.bad_seen,
            "the frame with a flipped parity bit reached the head"
        );
        assert_eq!(self.backwards, 0, "frames out of order");
        assert_eq!(self.park_before_first, 0, "park before the first frame");
        assert_eq!(self.frames_after_park, 0, "frames after the park");
        let first = self.first.expect("no frame reached the head");
        assert!(
            (recovery - 1..recovery + 10).contains(&first),
            "first frame {}",
            first
        );
        assert!(
            self.last.is_some_and(|l| l + 4 >= n - 1),
            "last frame {:?}",
            self.last
        );
        assert!(self.max_step <= 4, "a step of {} frames", self.max_step);
        assert!(
            self.distinct >= (n - recovery) * 6 / 10,
            "{} distinct frames",
            self.distinct
        );
        assert!(self.park >= 1000, "{} park periods", self.park);
    }
}
