//! Which block of input continues the signal a [`HansRx`] decoded last, and what
//! the receiver is told when one does not: the one rule of the firmware's two
//! HANS-100 decoders (controller input, `tasks/hans_in.rs`; head STATUS,
//! `tasks/status.rs`), kept here so that both follow it and the host tests it.
//!
//! The input arrives in blocks (DMA halves) numbered by their first word within
//! a **session**: a stretch in which the sampling ran without a break, so word
//! counts of one session are one continuous signal. A block is then
//! - [`Step::Push`]: the one after the last decoded; it is pushed as it is;
//! - [`Step::Skip`]: later in the same session, blocks in between never decoded
//!   (lost on a full queue, dropped by the load governor, or not passed on at
//!   all, as the head STATUS input passes on only every second half beside a
//!   HANS-100 controller): the receiver is told how many words are missing
//!   ([`HansRx::skip`]), so a settled lock **coasts** across them (the sender's
//!   clock ran on) instead of hunting and running the young fit again;
//! - [`Step::Fresh`]: a new session (the sampling restarted: the words missing
//!   are not known), a gap beyond [`HansRx::max_gap_words`] (it would not coast
//!   anyway) or a block from before the last one (a gap that wraps reads as
//!   huge): a new receiver starts on it;
//! - [`Step::First`]: the first block: a new receiver too, but nothing was lost.
//!
//! Whether a lock coasts is the receiver's decision ([`super::rx::gap`]): a young
//! one does not, it is dropped and the hunt starts after the gap. A caller that
//! decodes only every second block must therefore see contiguous blocks until its
//! lock has left the young fit; [`HansRx::coasts`] says when, and
//! [`status_passes`] is that rule for the head's STATUS input (the firmware's
//! input task and the host pipeline both ask it).

use super::rx::{ConfigError, HansRx, RxEvent};

/// What to do with a block before pushing it (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Step {
    /// The first block: start a new receiver; nothing is known lost.
    First,
    /// Contiguous with the last decoded block.
    Push,
    /// Same session, this many words per channel missing since the last decoded
    /// block, within [`HansRx::max_gap_words`]: skip them, then push.
    Skip(u32),
    /// A new session, a longer gap, or an older block: start a new receiver.
    Fresh,
}

impl Step {
    /// True when input between the last decoded block and this one was lost (the
    /// firmware reports it as a `Dropped` fault).
    pub fn lost(self) -> bool {
        matches!(self, Step::Skip(_) | Step::Fresh)
    }
}

/// Where a receiver's input stands (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Follow {
    /// The session of the last block and the first word the next one must have
    /// to continue it; `None` before the first block.
    next: Option<(u32, u32)>,
}

impl Follow {
    /// Nothing decoded yet.
    pub const fn new() -> Follow {
        Follow { next: None }
    }

    /// The step for a block of `words` words per channel starting at word
    /// `first_word` of `session`, when a gap of up to `max_gap` words may be
    /// skipped; the block is then taken as the last decoded one. Private: callers
    /// go through [`Follow::apply`], which also carries the step out.
    fn step(&mut self, session: u32, first_word: u32, words: u32, max_gap: u32) -> Step {
        let step = match self.next {
            None => Step::First,
            Some((s, next)) if s == session => match first_word.wrapping_sub(next) {
                0 => Step::Push,
                gap if gap <= max_gap => Step::Skip(gap),
                _ => Step::Fresh,
            },
            Some(_) => Step::Fresh,
        };
        self.next = Some((session, first_word.wrapping_add(words)));
        step
    }

    /// The step for the block of `words` words per channel from `first_word` of
    /// `session`, at `rx`'s [`HansRx::max_gap_words`], carried out: a skip goes
    /// to `rx` (its events, those of a dropped lock, to `sink`), a new receiver
    /// comes from `fresh`, the constructor the caller built its first receiver
    /// with (so the caller reports a refused configuration once, at start-up,
    /// and the construction lives in one place). Should `fresh` refuse anyway,
    /// `rx` is told of a gap no lock coasts across: it drops any lock and clears
    /// its rings as a new one would start. The block itself is for the caller to
    /// push.
    pub fn apply(
        &mut self,
        rx: &mut HansRx,
        session: u32,
        first_word: u32,
        words: u32,
        fresh: impl FnOnce() -> Result<HansRx, ConfigError>,
        sink: &mut impl FnMut(RxEvent),
    ) -> Step {
        let step = self.step(session, first_word, words, rx.max_gap_words());
        match step {
            Step::Push => {}
            Step::Skip(gap) => rx.skip(gap, sink),
            Step::First | Step::Fresh => match fresh() {
                Ok(new) => *rx = new,
                Err(_) => rx.skip(u32::MAX, sink),
            },
        }
        step
    }
}

/// Every how many DMA halves (SPI6 in the firmware) of the head's HANS-100 STATUS
/// input one goes to its decoder once the lock can coast ([`status_passes`]), by
/// what else the firmware's decode executor carries. The receiver costs ~1 950
/// instructions per frame on one channel as the firmware feeds it (QEMU, README
/// "Measured figures"): 41 % of the 4 800 cycles of a 10 us frame at one
/// instruction a cycle.
/// * Without a HANS-100 controller: **every half** (1). The decoder is then the
///   decode executor's only work; the line executor (an XY2-100 or XY3-100 receiver,
///   the bridge, the HANS-100 slot updates: ~1 450 a frame, 30 %) preempts it, so it
///   is busy ~58 % of the time, under the governor's 90 % (`SHARE_PERMILLE` in
///   `firmware/tasks/governor.rs`). Consecutive halves are contiguous signal, so
///   one receiver runs on and every frame is decoded.
/// * With a HANS-100 controller (HANS-100 -> HANS-100): **every second half** (2).
///   Its input decoder takes 41 % in normal mode and the line executor ~17 %
///   (bridge, slot updates, HANS STATUS out); the STATUS decoder adds ~22 %: the
///   decode executor is busy ~75 % of the time, under the 90 %. Every half (81 % +
///   17 %, busy ~98 %) would not fit. One receiver follows the signal across the
///   halves in between ([`Follow`], [`HansRx::skip`]): its settled lock
///   coasts over each skipped half and publishes from the second frame wholly in
///   the next one, so the head's status is at most two halves (410 us) plus a
///   decode old. The ~22 % is a half after a skipped one: 43 369 instructions
///   (QEMU bench row "hans rx: STATUS half, after a skipped half": the settled
///   cost and two re-centring frames at the young fit's) per 410 us. Before, each
///   half decoded was a new receiver, a hunt and then young-fit frames only (a
///   half is 20.5 frames, the young fit 32), the receiver's most expensive state:
///   99 773 ("new receiver"), ~51 %, which did not fit beside the input decoder.
///   A lock that cannot coast yet (a new receiver, or one that lost its lock) gets
///   every half ([`status_passes`], the firmware's `HANS_STATUS_CONTIGUOUS`;
///   about two halves per acquisition, over the share while they last: a half the governor drops then costs the
///   young lock, which hunts again on the next, as before). With vote3 (~65 %)
///   the two together are over the share, and vote5 / super alone: the governor
///   drops STATUS halves first (optional work) but decodes one at least every
///   1.6 ms (a gap of up to ~5.8 halves is coasted across, a longer one starts a
///   new receiver).
///
/// Below ~1 700 instructions per frame (busy ~85 %), 1 fits both pairings.
pub const fn status_every(hans_controller: bool) -> u32 {
    if hans_controller {
        2
    } else {
        1
    }
}

/// Whether the head's STATUS input passes half number `half` (counted from 1,
/// wrapping) on to the decoder: every `every`-th ([`status_due`]), and every one
/// while `contiguous`, which the decoder sets after each half to
/// `!`[`HansRx::coasts`]: a young lock is dropped at a skip, so an acquisition
/// (about two halves) must see contiguous halves or it would hunt again on every
/// one.
pub fn status_passes(half: u32, every: u32, contiguous: bool) -> bool {
    contiguous || status_due(half, every)
}

/// Whether half number `half` is one of every `every`-th ([`status_every`]; 0
/// reads as 1): the halves [`status_passes`] passes on whatever the lock does.
/// The others pass only while the decoder asks for contiguous halves.
pub fn status_due(half: u32, every: u32) -> bool {
    half.is_multiple_of(every.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hans::rx::Mode;

    const MAX: u32 = 2_970;
    const HALF: u32 = 512;

    #[test]
    fn contiguous_blocks_are_pushed() {
        let mut f = Follow::new();
        assert_eq!(f.step(0, 0, HALF, MAX), Step::First);
        assert_eq!(f.step(0, HALF, HALF, MAX), Step::Push);
        assert_eq!(f.step(0, 2 * HALF, HALF, MAX), Step::Push);
        assert!(!Step::Push.lost() && !Step::First.lost());
    }

    #[test]
    fn a_gap_within_the_limit_is_skipped() {
        let mut f = Follow::new();
        f.step(3, 0, HALF, MAX);
        // Every second half: one half missing each time.
        assert_eq!(f.step(3, 2 * HALF, HALF, MAX), Step::Skip(HALF));
        assert_eq!(f.step(3, 4 * HALF, HALF, MAX), Step::Skip(HALF));
        // Exactly the limit still skips; the word count wraps like the input's.
        let mut f = Follow::new();
        f.step(3, u32::MAX - 99, HALF, MAX);
        assert_eq!(
            f.step(3, 412u32.wrapping_add(MAX), HALF, MAX),
            Step::Skip(MAX)
        );
        assert!(Step::Skip(1).lost());
    }

    #[test]
    fn a_gap_beyond_the_limit_starts_fresh() {
        let mut f = Follow::new();
        f.step(0, 0, HALF, MAX);
        assert_eq!(f.step(0, HALF + MAX + 1, HALF, MAX), Step::Fresh);
        // And from there on the new block is the one followed.
        assert_eq!(f.step(0, 2 * HALF + MAX + 1, HALF, MAX), Step::Push);
        // A block from before the last one is a gap of nearly 2^32 words.
        assert_eq!(f.step(0, 0, HALF, MAX), Step::Fresh);
        assert!(Step::Fresh.lost());
    }

    #[test]
    fn a_new_session_starts_fresh() {
        let mut f = Follow::new();
        f.step(0, 0, HALF, MAX);
        // Even where the word count would continue: the sampling restarted.
        assert_eq!(f.step(1, HALF, HALF, MAX), Step::Fresh);
        assert_eq!(f.step(1, 2 * HALF, HALF, MAX), Step::Push);
        assert_eq!(f.step(2, 0, HALF, MAX), Step::Fresh);
    }

    fn new_rx() -> Result<HansRx, ConfigError> {
        HansRx::new(40_000_000, Mode::Normal { channel: 1 })
    }

    fn rx() -> HansRx {
        new_rx().unwrap()
    }

    /// A receiver that has seen input (its word count moved on).
    fn used() -> HansRx {
        let mut rx = rx();
        rx.push(&[&[0xFFFF; 300]], &mut |_| {});
        rx
    }

    #[test]
    fn apply_carries_the_step_out() {
        let mut f = Follow::new();
        let mut r = used();
        assert_eq!(
            f.apply(&mut r, 0, 0, HALF, new_rx, &mut |_| {}),
            Step::First
        );
        assert_eq!(r, rx(), "first: a new receiver");
        r = used();
        assert_eq!(
            f.apply(&mut r, 0, HALF, HALF, || panic!(), &mut |_| {}),
            Step::Push
        );
        assert_eq!(r, used(), "push: untouched");
        let step = f.apply(&mut r, 0, 3 * HALF, HALF, || panic!(), &mut |_| {});
        assert_eq!(step, Step::Skip(HALF));
        let mut skipped = used();
        skipped.skip(HALF, &mut |_| {});
        assert_eq!(r, skipped, "skip: told of the gap");
        let step = f.apply(&mut r, 1, 4 * HALF, HALF, new_rx, &mut |_| {});
        assert_eq!(step, Step::Fresh);
        assert_eq!(r, rx(), "fresh: a new receiver");
    }

    #[test]
    fn without_a_new_receiver_the_old_one_forgets() {
        let mut f = Follow::new();
        let mut r = used();
        let refused = || HansRx::new(1, Mode::Normal { channel: 1 });
        assert_eq!(
            refused(),
            Err(ConfigError::SampleRate { hz: 1 }),
            "the constructor refuses"
        );
        f.apply(&mut r, 0, 0, HALF, refused, &mut |_| {});
        let mut forgot = used();
        forgot.skip(u32::MAX, &mut |_| {});
        assert_eq!(r, forgot);
        assert_ne!(r, used(), "the old receiver was told of the gap");
    }

    #[test]
    fn status_halves_pass_every_second_beside_a_hans_controller() {
        assert_eq!(status_every(false), 1);
        assert_eq!(status_every(true), 2);
        let passed = |every: u32, contiguous: bool| -> [bool; 6] {
            core::array::from_fn(|i| status_passes(i as u32 + 1, every, contiguous))
        };
        // Settled: every half alone; every second one (the even numbers) beside a
        // HANS-100 controller.
        assert_eq!(passed(1, false), [true; 6]);
        assert_eq!(passed(2, false), [false, true, false, true, false, true]);
        // While the lock cannot coast: every half, whatever the pairing.
        assert_eq!(passed(2, true), [true; 6]);
        assert_eq!(passed(1, true), [true; 6]);
        // 0 is read as 1 (never a division by zero); the count wraps.
        assert_eq!(passed(0, false), [true; 6]);
        assert!(status_passes(0, 2, false) && !status_passes(u32::MAX, 2, false));
        // The every-n part alone is `status_due`, whatever `contiguous` says.
        for (every, contiguous) in [(1, false), (2, false), (2, true), (0, true)] {
            for half in [0, 1, 2, 3, 4, u32::MAX] {
                assert_eq!(
                    status_passes(half, every, contiguous),
                    contiguous || status_due(half, every),
                    "{half} {every} {contiguous}"
                );
            }
        }
        assert!(status_due(4, 2) && !status_due(3, 2) && status_due(3, 0));
    }

    /// The rule as the firmware runs it: halves pass while the receiver's lock
    /// cannot coast, then every second one, and the receiver follows the signal
    /// across the half in between without losing its lock.
    #[test]
    fn a_status_decoder_asks_for_every_half_until_it_can_coast() {
        use crate::hans::{Frame, FRAME_BITS};
        // Frames back to back at 12.5 Mbit/s sampled at 40 MHz (3.2 samples a
        // bit): each 16-bit word packs 16 samples, MSB first.
        let frames: Vec<Frame> = (0..256u32)
            .map(|k| Frame::new(k * 37 % 0x10_0000, k, 0xF_0000 - k).unwrap())
            .collect();
        let mut bits = [0u8; 256 * FRAME_BITS / 8];
        for (k, f) in frames.iter().enumerate() {
            f.write_at(&mut bits, k * FRAME_BITS).unwrap();
        }
        let level = |sample: usize| {
            let bit = sample * 5 / 16; // 12.5 / 40
            bits.get(bit / 8)
                .is_some_and(|b| b & (0x80 >> (bit % 8)) != 0)
        };
        let words = |half: u32| -> [u16; HALF as usize] {
            core::array::from_fn(|w| {
                let at = ((half - 1) * HALF) as usize + w;
                (0..16).fold(0u16, |acc, s| acc << 1 | u16::from(level(at * 16 + s)))
            })
        };
        let mut f = Follow::new();
        let mut r = rx();
        let (mut contiguous, mut decoded, mut asked) = (true, 0u32, 0u32);
        let (mut published, mut last) = (0u32, None);
        for half in 1..=12u32 {
            if !status_passes(half, status_every(true), contiguous) {
                continue;
            }
            decoded += 1;
            asked += u32::from(contiguous && half % 2 == 1);
            let mut lost = false;
            let block = words(half);
            let mut sink = |ev: RxEvent| match ev {
                RxEvent::Frame(fr) => {
                    // In order and sent: the frame's index follows the last one.
                    let from = last.map_or(0, |k: usize| k + 1);
                    let k = frames[from..].iter().position(|s| *s == fr).unwrap() + from;
                    last = Some(k);
                    published += 1;
                }
                RxEvent::Fault { kind, .. } => {
                    lost |= matches!(
                        kind,
                        crate::model::FaultKind::Resync | crate::model::FaultKind::Missing
                    )
                }
            };
            f.apply(&mut r, 0, half * HALF, HALF, new_rx, &mut sink);
            r.push(&[&block], &mut sink);
            assert!(contiguous || !lost, "half {half}: a settled lock was lost");
            contiguous = !r.coasts();
        }
        // The acquisition asked for an odd half at least once, then only every
        // second half passed: 12 halves, 6 of them even.
        assert!((1..=3).contains(&asked), "{asked} halves asked for");
        assert_eq!(decoded, 6 + asked);
        // A half is 20.5 frame periods: the settled halves publish most of theirs
        // (measured: 122 of the 7 halves' ~143).
        assert!(published >= 100, "{published} frames published");
    }
}
