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
//! lock has left the young fit; [`HansRx::coasts`] says when.

use super::rx::{HansRx, RxEvent};

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
    /// skipped; the block is then taken as the last decoded one.
    pub fn step(&mut self, session: u32, first_word: u32, words: u32, max_gap: u32) -> Step {
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

    /// [`Follow::step`] for the block of `words` words per channel from
    /// `first_word` of `session`, at `rx`'s [`HansRx::max_gap_words`], carried
    /// out: a skip
    /// goes to `rx` (its events, those of a dropped lock, to `sink`), a new
    /// receiver comes from `fresh`. Should `fresh` give none (it is made as the
    /// first one was, so that cannot happen), `rx` is told of a gap no lock
    /// coasts across: it drops any lock and clears its rings as a new one would
    /// start. The block itself is for the caller to push.
    pub fn apply(
        &mut self,
        rx: &mut HansRx,
        session: u32,
        first_word: u32,
        words: u32,
        fresh: impl FnOnce() -> Option<HansRx>,
        sink: &mut impl FnMut(RxEvent),
    ) -> Step {
        let step = self.step(session, first_word, words, rx.max_gap_words());
        match step {
            Step::Push => {}
            Step::Skip(gap) => rx.skip(gap, sink),
            Step::First | Step::Fresh => match fresh() {
                Some(new) => *rx = new,
                None => rx.skip(u32::MAX, sink),
            },
        }
        step
    }
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

    fn rx() -> HansRx {
        HansRx::new(40_000_000, Mode::Normal { channel: 1 }).unwrap()
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
            f.apply(&mut r, 0, 0, HALF, || Some(rx()), &mut |_| {}),
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
        let step = f.apply(&mut r, 1, 4 * HALF, HALF, || Some(rx()), &mut |_| {});
        assert_eq!(step, Step::Fresh);
        assert_eq!(r, rx(), "fresh: a new receiver");
    }

    #[test]
    fn without_a_new_receiver_the_old_one_forgets() {
        let mut f = Follow::new();
        let mut r = used();
        f.apply(&mut r, 0, 0, HALF, || None, &mut |_| {});
        let mut forgot = used();
        forgot.skip(u32::MAX, &mut |_| {});
        assert_eq!(r, forgot);
    }
}
