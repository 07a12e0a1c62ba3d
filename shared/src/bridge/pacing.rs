//! Pacing input events onto output slots, for a bridge loop that works in batches:
//! the firmware's waveform loop computes a whole DMA half of output slots at a time
//! from the input halves that arrived since the last batch (README "Tasks and
//! executors", "The bridge loop").
//!
//! Two decisions live here, so the firmware and the host pipeline make them alike:
//!
//! - [`batch_slot`]: the output slot of the batch an input event belongs to, from its
//!   *position* in the input the batch drained (samples, bytes or words consumed
//!   when the receiver decided it: `xy2::rx::Receiver::feed_at`,
//!   `xy3::rx::Period::end`, `hans::rx::HansRx::push_at`). A frame goes where its
//!   bits were on the line, however many fault events came before it. Spreading by
//!   event count instead let faulted periods (which can report up to three faults
//!   each) push the following frames together, two into one slot, and the
//!   free-running output skipped one of them.
//! - [`SlotQueue`]: the events waiting for their slot, handed out slot by slot.
//!   Free-running: every event due (the engine keeps the newest frame). Slaved: every
//!   fault due and at most one frame, so each input frame gets an output slot of its
//!   own; frames the slots could not take yet wait for the next slots (also of the
//!   next batch). At most `max_frames` frames wait: that bounds the latency the queue
//!   adds when the input runs faster than the slots; a frame beyond it is refused and
//!   the caller reports it (the firmware: a `Dropped` fault to the bridge).

use heapless::Deque;

use crate::model::LineEvent;

/// The slot (`0..slots`) of a batch of `slots` output slots for an input event at
/// `position` (units consumed when it was decided, `0..=units`) in the `units` input
/// units the batch drained. Unit `u` (position `u + 1`) falls in slot
/// `u * slots / units`, so evenly spaced frames fill the slots evenly; position 0
/// (decided before any unit, e.g. a fault about the whole chunk) is slot 0. Returns
/// 0 for an empty batch or no input.
pub fn batch_slot(position: u32, units: u32, slots: usize) -> usize {
    if units == 0 || slots == 0 {
        return 0;
    }
    let unit = u128::from(position.min(units).saturating_sub(1));
    // unit < units, so the quotient is below `slots`: no clamp needed, but free.
    let slot = unit * slots as u128 / u128::from(units);
    usize::try_from(slot).map_or(slots - 1, |s| s.min(slots - 1))
}

/// Why [`SlotQueue::push`] refused an event (it is handed back).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Refused {
    /// A frame while `max_frames` frames already wait (slaved output behind its
    /// input): the frame is lost and must be reported as such.
    Backlog(LineEvent),
    /// The queue is full.
    Full(LineEvent),
}

/// Input events waiting for their output slot (module docs). `N` bounds the events
/// (frames and faults) held.
#[derive(Clone, Debug)]
pub struct SlotQueue<const N: usize> {
    queue: Deque<(u64, LineEvent), N>,
    frames: usize,
    max_frames: usize,
}

impl<const N: usize> SlotQueue<N> {
    /// An empty queue holding at most `max_frames` frames (and `N` events).
    pub const fn new(max_frames: usize) -> Self {
        SlotQueue {
            queue: Deque::new(),
            frames: 0,
            max_frames,
        }
    }

    /// Queues `event` for output slot `due` (any slot numbering that only grows).
    /// Events are handed out in the order pushed.
    pub fn push(&mut self, due: u64, event: LineEvent) -> Result<(), Refused> {
        let frame = matches!(event, LineEvent::Frame(_));
        if frame && self.frames >= self.max_frames {
            return Err(Refused::Backlog(event));
        }
        self.queue
            .push_back((due, event))
            .map_err(|(_, e)| Refused::Full(e))?;
        if frame {
            self.frames += 1;
        }
        Ok(())
    }

    /// Frames waiting.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Events waiting (frames and faults).
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// Nothing waits.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// The events for output slot `slot`, in order: every event due at or before
    /// it, except that with `one_frame` (slaved timing) the slot ends after its
    /// first frame and the rest wait for the next slot.
    pub fn take(&mut self, slot: u64, one_frame: bool) -> Due<'_, N> {
        Due {
            queue: self,
            slot,
            one_frame,
            frame_taken: false,
        }
    }
}

/// The events of one slot ([`SlotQueue::take`]); what is not iterated stays queued.
pub struct Due<'a, const N: usize> {
    queue: &'a mut SlotQueue<N>,
    slot: u64,
    one_frame: bool,
    frame_taken: bool,
}

impl<const N: usize> Iterator for Due<'_, N> {
    type Item = LineEvent;

    fn next(&mut self) -> Option<LineEvent> {
        if self.one_frame && self.frame_taken {
            return None;
        }
        let (due, _) = self.queue.queue.front()?;
        if *due > self.slot {
            return None;
        }
        let (_, event) = self.queue.queue.pop_front()?;
        if matches!(event, LineEvent::Frame(_)) {
            self.queue.frames = self.queue.frames.saturating_sub(1);
            self.frame_taken = true;
        }
        Some(event)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{FaultKind, ForwardFrame, Line, Position};
    use proptest::prelude::*;

    fn frame(n: u32) -> LineEvent {
        let mut f = ForwardFrame::default();
        f.axes[0] = Position::from_raw(n, 20).ok();
        LineEvent::Frame(f)
    }

    fn fault() -> LineEvent {
        LineEvent::Fault {
            line: Line::Framing,
            kind: FaultKind::CheckFailed,
        }
    }

    #[test]
    fn batch_slot_places_frames_where_their_bits_were() {
        // 25 XY2 frames of 20 samples in a 500-sample half over 25 slots: frame k
        // (position 20k + 20) in slot k, whatever happened between them.
        for k in 0..25u32 {
            assert_eq!(batch_slot(20 * k + 20, 500, 25), k as usize);
        }
        // A 512-sample half (25.6 frame periods): still in order, never past the end.
        let slots: Vec<usize> = (0..25).map(|k| batch_slot(20 * k + 20, 512, 25)).collect();
        assert!(slots.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(slots.last(), Some(&24));
        // Two halves drained into one batch: two frames per slot.
        assert_eq!(batch_slot(40, 1000, 25), 0);
        assert_eq!(batch_slot(80, 1000, 25), 1);
        // Edge cases never panic and stay in range.
        assert_eq!(batch_slot(0, 500, 25), 0);
        assert_eq!(batch_slot(9_999, 500, 25), 24);
        assert_eq!(batch_slot(5, 0, 25), 0);
        assert_eq!(batch_slot(5, 10, 0), 0);
        assert!(batch_slot(u32::MAX, u32::MAX, usize::MAX) < usize::MAX);
        assert_eq!(batch_slot(u32::MAX, u32::MAX, 7), 6);
    }

    /// The regression: a period with three faults before each frame. Spreading by
    /// event count (the old rule) puts two frames into some slots; by position,
    /// every frame has a slot of its own.
    #[test]
    fn faults_take_no_slot() {
        let slots = 25;
        let mut events = Vec::new();
        for k in 0..25u32 {
            let pos = 20 * k + 20;
            if k % 3 == 0 {
                events.extend([(pos, fault()), (pos, fault()), (pos, fault())]);
            } else {
                events.push((pos, frame(k)));
            }
        }
        let per_slot = |slot_of: &dyn Fn(usize, u32) -> usize| {
            let mut n = vec![0; slots];
            for (i, (pos, e)) in events.iter().enumerate() {
                if matches!(e, LineEvent::Frame(_)) {
                    n[slot_of(i, *pos)] += 1;
                }
            }
            n
        };
        let by_position = per_slot(&|_, pos| batch_slot(pos, 500, slots));
        assert!(by_position.iter().all(|&n| n <= 1), "{by_position:?}");
        let count = events.len();
        let by_count = per_slot(&|i, _| i * slots / count);
        assert!(by_count.iter().any(|&n| n > 1), "{by_count:?}");
    }

    #[test]
    fn free_running_takes_everything_due() {
        let mut q: SlotQueue<8> = SlotQueue::new(8);
        q.push(3, frame(1)).unwrap();
        q.push(3, fault()).unwrap();
        q.push(3, frame(2)).unwrap();
        q.push(4, frame(3)).unwrap();
        assert_eq!(q.take(2, false).count(), 0);
        assert_eq!(
            q.take(3, false).collect::<Vec<_>>(),
            [frame(1), fault(), frame(2)]
        );
        assert_eq!(q.frames(), 1);
        assert_eq!(q.take(9, false).collect::<Vec<_>>(), [frame(3)]);
        assert!(q.is_empty());
    }

    #[test]
    fn slaved_takes_one_frame_per_slot_and_carries_the_rest() {
        let mut q: SlotQueue<8> = SlotQueue::new(8);
        q.push(0, fault()).unwrap();
        q.push(0, frame(1)).unwrap();
        q.push(0, frame(2)).unwrap();
        q.push(0, fault()).unwrap();
        q.push(5, frame(3)).unwrap();
        assert_eq!(q.take(0, true).collect::<Vec<_>>(), [fault(), frame(1)]);
        assert_eq!(q.take(1, true).collect::<Vec<_>>(), [frame(2)]);
        // A fault due after the frame waits for the next slot, then goes alone.
        assert_eq!(q.take(2, true).collect::<Vec<_>>(), [fault()]);
        assert_eq!(q.take(3, true).count(), 0);
        assert_eq!(q.take(5, true).collect::<Vec<_>>(), [frame(3)]);
        assert!(q.is_empty() && q.frames() == 0);
    }

    #[test]
    fn backlog_and_capacity_refuse_and_hand_back() {
        let mut q: SlotQueue<4> = SlotQueue::new(2);
        q.push(0, frame(1)).unwrap();
        q.push(0, frame(2)).unwrap();
        assert_eq!(q.push(0, frame(3)), Err(Refused::Backlog(frame(3))));
        // Faults still fit up to the capacity.
        q.push(0, fault()).unwrap();
        q.push(0, fault()).unwrap();
        assert_eq!(q.push(0, fault()), Err(Refused::Full(fault())));
        assert_eq!(q.len(), 4);
        // An iterator dropped early leaves the rest queued.
        assert_eq!(q.take(0, false).next(), Some(frame(1)));
        assert_eq!(q.frames(), 1);
        q.push(1, frame(4)).unwrap();
        assert_eq!(q.frames(), 2);
    }

    /// The firmware's slaved batch loop (`firmware/tasks/bridge.rs`, `bridge_core`)
    /// on the engine, at the unit level: batches of 25 slots of 10 us, fed with
    /// DMA halves of 512 samples (20 per frame period) that arrived before each
    /// batch, a third of the periods faulted (three fault events each).
    struct SlavedLoop {
        bridge: crate::bridge::Bridge,
        queue: SlotQueue<192>,
        slot: u64,
        /// Per slot: the X position sent (raw 20-bit), and the link state.
        sent: Vec<(Option<u32>, crate::bridge::LinkState)>,
        /// Due slots of the queued frames, in order.
        dues: std::collections::VecDeque<u64>,
        /// Per frame taken from the queue: slots after its due slot.
        lag: Vec<u64>,
    }

    const SLOTS: usize = 25;
    const HALF: u32 = 512;

    impl SlavedLoop {
        fn new() -> Self {
            use crate::bridge::{Config, Protocol, Timing};
            let mut c = Config::default();
            c.controller.protocol = Protocol::Xy2;
            // 20-bit positions end to end, so X reads back exactly.
            c.head.protocol = Protocol::Xy3;
            c.output.timing = Timing::Slaved;
            c.failsafe.recovery_frames = 1;
            SlavedLoop {
                bridge: crate::bridge::Bridge::new(&c).unwrap(),
                queue: SlotQueue::new(2 * SLOTS),
                slot: 0,
                sent: Vec::new(),
                dues: std::collections::VecDeque::new(),
                lag: Vec::new(),
            }
        }

        /// One batch: `halves` (events with their positions in the half) queued by
        /// position, then 25 slots.
        fn batch(&mut self, halves: &[Vec<(u32, LineEvent)>]) {
            let units = HALF * halves.len() as u32;
            let base = self.slot;
            for (h, half) in halves.iter().enumerate() {
                for (at, e) in half {
                    let due = base + batch_slot(h as u32 * HALF + at, units, SLOTS) as u64;
                    match self.queue.push(due, *e) {
                        Ok(()) => {
                            if matches!(e, LineEvent::Frame(_)) {
                                self.dues.push_back(due);
                            }
                        }
                        Err(Refused::Backlog(_)) => {
                            let drop = LineEvent::Fault {
                                line: Line::Framing,
                                kind: FaultKind::Dropped,
                            };
                            self.queue.push(due, drop).unwrap();
                        }
                        Err(Refused::Full(e)) => panic!("queue full: {e:?}"),
                    }
                }
            }
            for _ in 0..SLOTS {
                let t = self.slot * 10_000;
                let mut slaved = None;
                for e in self.queue.take(self.slot, true) {
                    if matches!(e, LineEvent::Frame(_)) {
                        let due = self.dues.pop_front().unwrap();
                        self.lag.push(self.slot - due);
                    }
                    if let Some(o) = self.bridge.on_line_event(t, e) {
                        slaved = o.frame.or(slaved);
                    }
                }
                let o = self.bridge.tick(t);
                let frame = slaved.or(o.frame);
                let x = frame.and_then(|f| f.axes[0]).map(|p| p.to_raw(20));
                self.sent.push((x, o.state));
                self.slot += 1;
            }
        }
    }

    /// Input halves: frame period `k` (20 units) carries X = `k`; with `faults`
    /// every third period is faulted (three fault events, no frame).
    fn halves(periods: u32, faults: bool) -> Vec<Vec<(u32, LineEvent)>> {
        let period_units = 20;
        let mut out: Vec<Vec<(u32, LineEvent)>> = Vec::new();
        for k in 0..periods {
            let end = (k + 1) * period_units;
            let h = ((end - 1) / HALF) as usize;
            if out.len() <= h {
                out.resize(h + 1, Vec::new());
            }
            let at = end - h as u32 * HALF;
            if faults && k % 3 == 2 {
                out[h].extend([(at, fault()), (at, fault()), (at, fault())]);
            } else {
                out[h].push((at, frame(k)));
            }
        }
        out
    }

    /// Runs batches every 250 us, each draining the halves complete by then (a
    /// half of `HALF` units lasts `half_ns`), then `idle` batches without input.
    fn run(halves: &[Vec<(u32, LineEvent)>], half_ns: u64, idle: usize) -> SlavedLoop {
        let mut l = SlavedLoop::new();
        let mut next = 0;
        let mut b = 1u64;
        while next < halves.len() {
            let done = ((b * 250_000 / half_ns) as usize).min(halves.len());
            l.batch(halves.get(next..done).unwrap_or_default());
            next = done.max(next);
            b += 1;
        }
        for _ in 0..idle {
            l.batch(&[]);
        }
        l
    }

    #[test]
    fn slaved_loop_sends_every_input_frame_once_then_holds_and_parks() {
        use crate::bridge::LinkState;
        let periods = 3_000;
        let l = run(&halves(periods, true), 256_000, 80);
        let frames: Vec<u32> = (0..periods).filter(|k| k % 3 != 2).collect();
        // While running, exactly the input frames, in order, one per slot at most;
        // the other running slots idle (nothing sent).
        let running: Vec<u32> = l
            .sent
            .iter()
            .filter(|(_, s)| *s == LinkState::Running)
            .filter_map(|(x, _)| *x)
            .collect();
        assert_eq!(running, frames);
        // Equal rates: a frame waits at most about a batch beyond its slot.
        assert!(
            l.lag.iter().all(|&d| d <= SLOTS as u64 + 1),
            "{:?}",
            l.lag.iter().max()
        );
        let c = l.bridge.counters();
        assert_eq!(c.line(Line::Framing).dropped, 0);
        assert_eq!((c.skipped, c.repeated), (0, 0));
        // Input stopped: idle slots for the 1 ms timeout, then the last position
        // held at the slot rate for 10 ms, then the park position at the slot rate.
        let last = l
            .sent
            .iter()
            .rposition(|(x, s)| *s == LinkState::Running && x.is_some());
        let after = &l.sent[last.unwrap() + 1..];
        let idle = after
            .iter()
            .take_while(|(x, s)| x.is_none() && *s == LinkState::Running);
        assert!((95..=100).contains(&idle.count()));
        let holding: Vec<_> = after
            .iter()
            .filter(|(_, s)| *s == LinkState::Holding)
            .collect();
        assert_eq!(holding.len(), 1_000);
        let last_x = *frames.last().unwrap();
        assert!(holding.iter().all(|(x, _)| *x == Some(last_x)));
        let safe: Vec<_> = after
            .iter()
            .filter(|(_, s)| *s == LinkState::Safe)
            .collect();
        assert!(safe.len() > 500);
        assert!(safe
            .iter()
            .all(|(x, _)| *x == Some(crate::bridge::CENTRE20)));
    }

    /// Input 4 % faster than the slots, no faults: the backlog fills to its bound, the frames
    /// beyond it are dropped and counted (`Dropped` on the framing line), every
    /// other frame still goes out once and in order, and the lag stays bounded.
    #[test]
    fn slaved_loop_bounds_the_lag_of_a_fast_input() {
        use crate::bridge::LinkState;
        let periods = 30_000;
        let l = run(&halves(periods, false), 246_000, 0);
        let sent: Vec<u32> = l
            .sent
            .iter()
            .filter(|(_, s)| *s == LinkState::Running)
            .filter_map(|(x, _)| *x)
            .collect();
        assert!(sent.windows(2).all(|w| w[0] < w[1]));
        let valid = u64::from(periods);
        let dropped = l.bridge.counters().line(Line::Framing).dropped;
        assert!(dropped > 0);
        assert!(sent.len() as u64 + dropped + l.queue.frames() as u64 >= valid);
        assert!(
            l.lag.iter().all(|&d| d <= 3 * SLOTS as u64),
            "{:?}",
            l.lag.iter().max()
        );
    }

    proptest! {
        /// Slaved: every frame pushed comes out exactly once, in order, at most one
        /// per slot and never before its due slot; faults keep their order too.
        #[test]
        fn slaved_is_one_frame_per_slot_in_order(
            dues in proptest::collection::vec((0u64..4, any::<bool>()), 0..60)
        ) {
            let mut q: SlotQueue<64> = SlotQueue::new(64);
            let mut due = 0;
            let mut pushed = Vec::new();
            for (n, (step, is_frame)) in dues.iter().enumerate() {
                due += step;
                let e = if *is_frame { frame(n as u32) } else { fault() };
                q.push(due, e).unwrap();
                pushed.push((due, e));
            }
            let mut out = Vec::new();
            let mut slot = 0;
            while !q.is_empty() {
                let got: Vec<_> = q.take(slot, true).collect();
                prop_assert!(got.iter().filter(|e| matches!(e, LineEvent::Frame(_))).count() <= 1);
                out.extend(got.into_iter().map(|e| (slot, e)));
                slot += 1;
                prop_assert!(slot < 1_000);
            }
            prop_assert_eq!(out.len(), pushed.len());
            for ((at, e), (due, p)) in out.iter().zip(&pushed) {
                prop_assert_eq!(e, p);
                prop_assert!(at >= due);
            }
        }
    }
}
